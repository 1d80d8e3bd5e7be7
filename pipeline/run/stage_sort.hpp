#pragma once
// The sort stage of `run`: the external sort (pipeline/point_sort.hpp) as a stage with a
// lifecycle (pipeline/stage.hpp).
//
// Its records in the checkpoint state: "sort", how far the sort got (pass 1's count
// and bounding box, the finished runs and their hull candidates), replaced after each
// step; and "sorted", the sorted file and the hull's labels (the file hull.labels)
// once the runs are merged, when "sort" and the run files go. A file that a record
// names and that fails its checksum is made again, never trusted.
#include "io/output_file.hpp"
#include "io/tet_container.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/sort/point_sort.hpp"
#include "pipeline/run/stage.hpp"

#include <cstdint>
#include <functional>
#include <optional>

namespace tetstream::pipeline {

class SortStage {
 public:
  // The sort takes its shares from `budget` once pass 1 has counted the points (the
  // run buffer, the hull pieces on `threads` threads, the merge's blocks), and sorts
  // its runs on `threads` threads.
  // `claim`: the output, when it is a regular file (null for standard output): the
  // merge then writes the sorted points into its points section
  // (pipeline/points_in_output.hpp) instead of a file of the sort's own.
  SortStage(const StageContext& context, MemoryBudget& budget, int threads, const io::OutputClaim* claim = nullptr)
      : context_(context), budget_(budget), threads_(threads), claim_(claim) {}

  // Reads "sorted" (a finished sort whose files pass their checksums: run does
  // nothing) or "sort" (the steps to skip).
  void prepare();
  // The sorted points: sorted now, or as the checkpoint kept them. A sorted file made
  // again after a checksum failure must come to the recorded checksum (the output
  // written so far uses its labels): DamagedCheckpoint otherwise. A budget that cannot
  // hold the job is refused after pass 1, before any run is written (BudgetTooSmall).
  const SortedPoints& run();
  // Records "sorted" (with hull.labels) in place of "sort", and removes the run files
  // that no state names any more. Nothing when the sort was already recorded or the
  // job keeps no checkpoint.
  void commit();

  const SortedPoints& result() const { return sorted_; }

  // Whether prepare() found the sort recorded and intact (run() then does nothing).
  bool recorded() const { return done_; }
  // The container header the points section is written with, for given sorted points
  // (the budget it names: the writer's record when it started, else this process's).
  std::function<io::TetFileHeader(const SortedPoints&)> points_header() const;
  // In place of run(): the sorted points that the ranks of a distributed job wrote
  // into the claimed output's points section (pipeline/point_sort_distributed.hpp),
  // with run()'s check of a sort made again after a checksum failure.
  const SortedPoints& adopt(SortedPoints sorted);

 private:
  void renew_header_budget();
  void check_sorted_again() const;  // DamagedCheckpoint when a sort made again differs
  StageContext context_;
  MemoryBudget& budget_;
  const int threads_;
  const io::OutputClaim* claim_;
  bool done_ = false;                          // prepare found the sort recorded
  std::optional<std::uint32_t> expected_crc_;  // of a recorded sorted file that failed its checksum
  SortProgress progress_;                      // the steps done (in: an earlier process's; out: all)
  SortedPoints sorted_;
};

}  // namespace tetstream::pipeline
