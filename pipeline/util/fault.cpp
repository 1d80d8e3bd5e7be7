#include "pipeline/util/fault.hpp"

#include "core/error.hpp"

#include <cstdlib>
#include <string>
#include <string_view>

namespace tetstream::pipeline {

void maybe_inject_fault(const char* site, std::uint64_t index) {
  // Read once: the environment does not change during a job.
  static const std::string spec = [] {
    const char* v = std::getenv("TETSTREAM_FAULT");
    return std::string(v ? v : "");
  }();
  if (spec.empty()) return;
  const std::string want = std::string(site) + ":" + std::to_string(index);
  std::string_view rest = spec;
  while (!rest.empty()) {
    const std::size_t comma = rest.find(',');
    if (rest.substr(0, comma) == want)
      throw IoError(std::string("injected failure at ") + want + " (TETSTREAM_FAULT): No space left on device");
    if (comma == std::string_view::npos) break;
    rest.remove_prefix(comma + 1);
  }
}

}  // namespace tetstream::pipeline
