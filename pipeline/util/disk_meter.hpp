#pragma once
// The disk a job's own files take, measured: the largest sum, over the samples, of the
// blocks allocated to the regular files in the job's working directory and to its
// partial output (st_blocks, so the holes the merge punches in the sort's runs count
// as given back). Sampled where the footprint changes shape: at each stage boundary
// and at each checkpoint (pipeline/stage.hpp calls sample() on every save), so the
// peak between two samples (inside a merge, inside a segment) is not seen; the CLI
// test tests/cli/disk_peak_cli.sh samples every 20 ms from outside instead.
// Thread-safe: the writer's thread saves checkpoints too.
#include <cstdint>
#include <mutex>
#include <string>

namespace tetstream::pipeline {

class DiskMeter {
 public:
  // `dir`: the job's working directory; `output_partial`: OUT.partial (empty: stdout).
  DiskMeter(std::string dir, std::string output_partial)
      : dir_(std::move(dir)), output_partial_(std::move(output_partial)) {}
  // Measures now; returns the bytes measured. Never throws (a file that goes while it
  // is measured counts 0).
  std::uint64_t sample();
  std::uint64_t peak() const {
    std::lock_guard lock(mutex_);
    return peak_;
  }

 private:
  const std::string dir_, output_partial_;
  mutable std::mutex mutex_;
  std::uint64_t peak_ = 0;
};

}  // namespace tetstream::pipeline
