#include "pipeline/util/interrupt.hpp"

#include <atomic>
#include <csignal>
#include <string>

namespace tetstream::pipeline {

namespace {
std::atomic<int> g_signal{0};

extern "C" void on_signal(int sig) {
  if (g_signal.exchange(sig) != 0) {
    // Second signal: the user means it.
    std::signal(sig, SIG_DFL);
    std::raise(sig);
  }
}
}  // namespace

Interrupted::Interrupted(int signal)
    : Error(ExitCode::kInterrupted,
            std::string("interrupted by signal ") + std::to_string(signal) + "; no output written") {}

void install_interrupt_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  // A closed terminal (ssh dropped) ends the job like Ctrl-C: checkpoint kept, nothing
  // under the final name. (`nohup` or a terminal multiplexer keeps a job running.)
  sigaction(SIGHUP, &sa, nullptr);
  // Past a file-size limit (ulimit -f), write() then fails with EFBIG and the job
  // reports it like any write failure (and keeps its checkpoint), instead of being
  // killed by SIGXFSZ half-way through a write.
  std::signal(SIGXFSZ, SIG_IGN);
  // A reader that closes the pipe (`run -o - | head`): write() fails with EPIPE and the
  // job ends through its cleanup, instead of being killed with its work files left.
  std::signal(SIGPIPE, SIG_IGN);
}

void request_interrupt(int signal) { g_signal.store(signal, std::memory_order_relaxed); }

void clear_interrupt() { g_signal.store(0, std::memory_order_relaxed); }

void check_interrupted() {
  if (const int sig = g_signal.load(std::memory_order_relaxed)) throw Interrupted(sig);
}

}  // namespace tetstream::pipeline
