#pragma once
// Ctrl-C and SIGTERM: the first signal asks the job to stop; long loops poll
// check_interrupted() between batches (a read chunk, a segment), which throws, so the
// stack unwinds through the usual cleanup: temporary directories are removed and no
// output is left under its final name (a checkpointed `run` keeps its checkpoint and
// partial output for --resume). A second signal kills the process at once.
#include "core/error.hpp"

namespace tetstream::pipeline {

class Interrupted : public Error {
 public:
  explicit Interrupted(int signal);
};

void install_interrupt_handlers();
// Throws Interrupted when a signal has arrived since install_interrupt_handlers().
void check_interrupted();

// For embedders that keep their own signal handling (the Python module): ask the job
// running in this process to stop, as a signal would (the next check_interrupted()
// throws Interrupted(signal)), and forget such a request before the next job.
void request_interrupt(int signal);
void clear_interrupt();

}  // namespace tetstream::pipeline
