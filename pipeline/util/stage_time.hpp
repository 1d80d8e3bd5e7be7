#pragma once
// A stage's wall time and busy thread-seconds (the process's CPU time, user and
// system, of all its threads, over the same interval), so that a stage running on one
// thread shows itself: busy / wall is the cores it kept busy (issue 38, `--json`).
//
//   StageMeter meter;  ... the stage ...  StageTime t = meter.elapsed();
//
// The CPU time is the whole process's: work of another stage overlapping this one (the
// writer's encoders during the triangulation) counts in both intervals it spans.
#include <chrono>

namespace tetstream::pipeline {

// The process's CPU seconds so far, all threads, user + system (getrusage).
double process_cpu_seconds();

struct StageTime {
  double wall = 0;  // seconds
  double busy = 0;  // thread-seconds of CPU
  double parallelism() const { return wall > 0 ? busy / wall : 0; }
  StageTime& operator+=(const StageTime& o) {
    wall += o.wall, busy += o.busy;
    return *this;
  }
};

class StageMeter {
 public:
  StageMeter() { restart(); }
  void restart() {
    wall0_ = std::chrono::steady_clock::now();
    cpu0_ = process_cpu_seconds();
  }
  StageTime elapsed() const {
    return {std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0_).count(),
            process_cpu_seconds() - cpu0_};
  }

 private:
  std::chrono::steady_clock::time_point wall0_;
  double cpu0_ = 0;
};

}  // namespace tetstream::pipeline
