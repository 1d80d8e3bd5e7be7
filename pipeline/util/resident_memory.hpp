#pragma once
// The process's resident set as the kernel counts it (getrusage's ru_maxrss): what
// --memory promises to bound. The ledger plans the job from models; this says what it
// took (run --json's memory_peak_bytes, and the triangulation's warning when a
// segment's windows grew past what the plan sampled: docs/memory.md).
#include <cstdint>

namespace tetstream::pipeline {

// The most the resident set has been since the process started (on Linux the same as
// /proc/self/status's VmHWM); 0 when the kernel does not say.
std::uint64_t peak_resident_bytes();

}  // namespace tetstream::pipeline
