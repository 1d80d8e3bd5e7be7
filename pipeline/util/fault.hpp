#pragma once
// Fault injection for tests: TETSTREAM_FAULT="SITE:N[,SITE:N...]" makes the N-th
// (0-based) passage through SITE throw IoError, exactly as a real failure there would
// (a full disk, a failing device). Sites: "sort-run" (a finished sort run),
// "segment" (a worker triangulating segment N of the plan), "write" (the writer
// taking segment N's tets), "place" (a rank of a job under mpirun copying its frames
// into the output; N = 0), "merge" (an external sort's final merge of its spilled
// runs starting; N = 0). TETSTREAM_STALL="SITE:N[,...]" instead makes that passage
// print "tetstream: stalled at SITE:N" on stderr and sleep until the process is killed
// (the resume tests' kill -9 at a chosen moment, whatever the machine's speed) or
// signalled (SIGTERM, SIGINT: Interrupted is thrown there, as check_interrupted would). Unset,
// both cost one relaxed load per call.
#include <cstdint>

namespace tetstream::pipeline {

// Throws IoError when TETSTREAM_FAULT names SITE:index; stalls when TETSTREAM_STALL does.
void maybe_inject_fault(const char* site, std::uint64_t index);

}  // namespace tetstream::pipeline
