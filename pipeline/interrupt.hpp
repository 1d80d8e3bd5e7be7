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

}  // namespace tetstream::pipeline
