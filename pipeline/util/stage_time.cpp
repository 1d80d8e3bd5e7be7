#include "pipeline/util/stage_time.hpp"

#include <sys/resource.h>

namespace tetstream::pipeline {

double process_cpu_seconds() {
  rusage ru{};
  if (::getrusage(RUSAGE_SELF, &ru) != 0) return 0;
  auto seconds = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
  return seconds(ru.ru_utime) + seconds(ru.ru_stime);
}

}  // namespace tetstream::pipeline
