#include "pipeline/util/fault.hpp"

#include "core/error.hpp"
#include "pipeline/util/interrupt.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <thread>

namespace tetstream::pipeline {

namespace {

// An environment variable's value, read once: the environment does not change during
// a job.
struct Spec {
  std::string value;
  explicit Spec(const char* name) {
    const char* v = std::getenv(name);
    value = v ? v : "";
  }
  // Whether the comma-separated list names `want` ("SITE:N").
  bool names(const std::string& want) const {
    std::string_view rest = value;
    while (!rest.empty()) {
      const std::size_t comma = rest.find(',');
      if (rest.substr(0, comma) == want) return true;
      if (comma == std::string_view::npos) break;
      rest.remove_prefix(comma + 1);
    }
    return false;
  }
};

}  // namespace

void maybe_inject_fault(const char* site, std::uint64_t index) {
  static const Spec fault("TETSTREAM_FAULT"), stall("TETSTREAM_STALL");
  if (fault.value.empty() && stall.value.empty()) return;
  const std::string want = std::string(site) + ":" + std::to_string(index);
  if (fault.names(want))
    throw IoError(std::string("injected failure at ") + want + " (TETSTREAM_FAULT): No space left on device");
  if (stall.names(want)) {
    // Announced on stderr (whatever the log level) for the test that waits for it to
    // kill the process here; then never returns.
    std::fprintf(stderr, "tetstream: stalled at %s (TETSTREAM_STALL)\n", want.c_str());
    std::fflush(stderr);
    // A SIGTERM or Ctrl-C here ends the job as a signal arriving at this passage would
    // (the interrupt tests); SIGKILL ends it where it stands (the resume tests).
    for (;;) {
      check_interrupted();
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
}

}  // namespace tetstream::pipeline
