#include "pipeline/util/resident_memory.hpp"

#include <sys/resource.h>

namespace tetstream::pipeline {

std::uint64_t peak_resident_bytes() {
  rusage usage{};
  if (getrusage(RUSAGE_SELF, &usage) != 0) return 0;
  return std::uint64_t(usage.ru_maxrss) * 1024;  // Linux: kilobytes, the kernel's VmHWM
}

}  // namespace tetstream::pipeline
