#pragma once
// What the stages of `run` share: their lifecycle, the job's state they read and
// record, and how a stage runs on the thread count it was given.
//
// The stages (docs/architecture.md, "The job"): sort (stage_sort.hpp), index and hull
// (stage_index.hpp), triangulate (stage_triangulate.hpp) and write (stage_write.hpp).
// Each goes through the same steps, as PDAL's stages do (prepare, execute, done):
//
//   prepare   reads the stage's own record of the checkpoint state, i.e. what an
//             earlier process of the same job finished, and decides what is left;
//   run       does what is left, within the memory share and on the thread count
//             its constructor was given (never the process's OpenMP default);
//   commit    writes the stage's record into the state and saves it, so that a
//             resumed job's prepare finds the stage's work done.
//
// A stage owns its record (a key of state.json: "sort" and "sorted" are the sort's,
// "header_memory" and "output" the writer's) and the files that record names; no
// other stage reads or writes them. A stage with nothing worth keeping across a crash
// (the index, rebuilt from the sorted file in one pass) has no record and no commit.
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/util/disk_meter.hpp"
#include "pipeline/run/run.hpp"

#include <nlohmann/json.hpp>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <string>

namespace tetstream::pipeline {

using StageClock = std::chrono::steady_clock;
inline double seconds_since(StageClock::time_point t0) {
  return std::chrono::duration<double>(StageClock::now() - t0).count();
}

// The job as its stages see it. The state is kept even when the job is not
// resumable (no checkpoint): a stage reads and records it the same way, and only
// save() is skipped.
struct StageContext {
  const RunOptions& options;
  std::string dir;            // the job's working files: the checkpoint's directory, or a TempDir
  Checkpoint* checkpoint;     // null: the job is not resumable
  nlohmann::json& state;      // what the checkpoint holds
  DiskMeter* disk = nullptr;  // sampled at every save (pipeline/disk_meter.hpp)
  void save() const {
    if (checkpoint) checkpoint->save(state);
    if (disk) disk->sample();
  }
};

// Runs the OpenMP regions that a stage's library code opens without a num_threads
// clause (the sort's run sorting, the index's blocks) on `threads` threads until the
// end of the scope. It sets the calling thread's own setting and restores it, so a
// stage's thread count is the one it was handed, whatever the process's default.
class ScopedThreads {
 public:
  explicit ScopedThreads(int threads) : saved_(omp_get_max_threads()) { omp_set_num_threads(std::max(1, threads)); }
  ~ScopedThreads() { omp_set_num_threads(saved_); }
  ScopedThreads(const ScopedThreads&) = delete;
  ScopedThreads& operator=(const ScopedThreads&) = delete;

 private:
  int saved_;
};

}  // namespace tetstream::pipeline
