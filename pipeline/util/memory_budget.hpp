#pragma once
// The job's memory ledger: the one place that splits `--memory` into shares.
//
// `--memory` is a ceiling, not an allocation. Each share is what this input needs,
// capped by its part of the ceiling, so a generous budget costs nothing: 1,000 points
// at --memory 1T take what 1,000 points take.
//
// A job holds memory in two phases that never overlap:
//   sort         the run buffer (56 bytes a point: the record and a coordinate copy
//                for the hull candidates), the hull pieces' kernels (~320 bytes a
//                point, `threads` pieces at once) and the merge's blocks;
//   triangulate  the point indexes (measured once built), the writer's frames and
//                encoders, the windows with their kernels and held output, and the
//                pages of the sorted file that the queries map;
// and in both a runtime reserve. A periodic job (docs/periodic.md) has a third, after
// its padded job: keep (its label map, its frames and the kept tets' sort);
// and in every phase a runtime reserve: the process, the allocator's slack, the page-cache
// folios that sequential scans map before handing them back (ReleaseBehind).
//
// Invariant (checked as the shares are made, and by tests/unit/memory_budget_test.cpp):
// the shares of a phase, with the reserve, sum to at most the ceiling.
#include <cstdint>
#include <cstddef>
#include <string>
#include <vector>

namespace tetstream::pipeline {

// The least the point index takes in memory (a leaf's 4-byte entry per point), for
// refusals before the sort, which must never refuse a job that would fit; an index on
// disk takes its share instead (below), so the bound is the smaller of the two.
inline constexpr double kIndexBytesLowerBound = 4;
// The point index in memory, about (PointIndex: a 4-byte entry and a 2-byte cell a
// point, a 36-byte node for every ~24 points).
inline constexpr double kIndexBytesPerPoint = 7.5;
// The point index on disk (IndexStage::run_on_disk, `run --index`): the share of its
// file's pages held resident, a sixteenth of the budget and at least 32 MiB (a window's
// queries read the blocks of its label range and of its neighbours, three 2 MiB regions
// a block). It goes to disk, unless told otherwise, when in memory it would take more
// than an eighth of the budget: at 10^9 points, 7.5 GB, which left 8G no room for the
// windows. Not when the index is smaller than that share (budgets under 512M): its
// pages would all stay resident, the same memory with a file beside it.
inline constexpr std::uint64_t kIndexDiskShareFloor = std::uint64_t(32) << 20;
inline std::uint64_t index_disk_share(std::uint64_t memory_bytes) {
  return memory_bytes / 16 > kIndexDiskShareFloor ? memory_bytes / 16 : kIndexDiskShareFloor;
}
inline bool index_crowds_budget(std::uint64_t points, std::uint64_t memory_bytes) {
  const double in_memory = kIndexBytesPerPoint * double(points);
  return in_memory > double(memory_bytes) / 8 && in_memory > double(index_disk_share(memory_bytes));
}

// Tets per frame, about: a frame is cut at the first change of minimum label after
// this many tets (pipeline/frame_cutter.hpp). The segments emit their tets grouped by
// minimum label and the zones follow each other in label order, so the job's whole
// stream is ordered by minimum label, and the frames (each a set, stored canonically
// by the codec) are the same for any segment plan or thread count. The size is the
// largest below, and smaller for small budgets (MemoryBudget::frame_tets_for): it
// depends on the budget the output's header names, which a resumed job keeps.
inline constexpr std::size_t kFrameTets = std::size_t(1) << 18;
inline constexpr std::size_t kSmallestFrameTets = std::size_t(1) << 12;

struct SortShares {
  std::size_t run_points = 0;         // points per sorted run
  std::size_t hull_piece_points = 0;  // points per hull-candidate piece (one kernel each)
  int hull_threads = 1;               // pieces computed at once
  std::size_t merge_bytes = 0;        // the external sorter's budget (merge blocks)
};

struct TriangulateShares {
  int encoders = 1;                    // the writer stage's compression threads
  std::uint64_t writer_bytes = 0;      // frames in flight, the encoders' scratch, the file buffer
  std::size_t file_buffer_bytes = 0;   // the output file's write buffer (part of writer_bytes)
  std::uint64_t query_page_bytes = 0;  // mapped pages of the sorted file the queries read
  std::uint64_t index_bytes = 0;       // the point index and the hull's (as measured)
  double window_bytes = 0;             // the windows: kernels, coordinates, held output (the plan's "available")
  std::uint64_t shared_rim_bytes = 0;  // the finished zones' rim tets for the running ones (SharedRim)
};

struct KeepShares {
  std::uint64_t map_bytes = 0;    // the periodic labels, offsets and coordinates of the padded points
  std::uint64_t frame_bytes = 0;  // the frames the threads decode and the writer encodes
  std::uint64_t sort_bytes = 0;   // the kept tets' external sort (it spills beyond)
};

class MemoryBudget {
 public:
  struct Share {
    std::string phase, name;
    std::uint64_t bytes = 0;
  };

  // ceiling: --memory; points: the input's count (an upper bound of the sorted
  // points); threads: the worker threads; cores: the machine's (the writer's encoders).
  MemoryBudget(std::uint64_t ceiling, std::uint64_t points, int threads, int cores);

  std::uint64_t ceiling() const { return ceiling_; }
  std::uint64_t points() const { return points_; }
  // The count once it is known (stdin: after the first pass).
  void set_points(std::uint64_t points) { points_ = points; }
  // The reserve for the process and the allocator, in both phases.
  std::uint64_t runtime_bytes() const { return runtime_; }
  // The part of it `verify` takes out of its --memory before it plans: the
  // process's own pages (the code and the shared libraries: 13 MiB
  // resident for `tetstream`), the threads' stacks and the allocator's slack, a quarter
  // of the budget between 20 and 64 MiB (at most the budget's 5/8).
  static std::uint64_t process_reserve(std::uint64_t ceiling);

  // The sort's shares, recorded in the ledger.
  SortShares plan_sort();
  // The triangulation's shares once the indexes are built (index_bytes measured, or
  // bounded from kIndexBytesLowerBound before the sort), recorded. window_bytes <= 0:
  // the budget cannot hold the fixed shares and the indexes.
  // windows_planned: what the chosen zone plan's windows take (recorded as the
  // windows' share when smaller than what the budget leaves them).
  TriangulateShares plan_triangulate(std::uint64_t index_bytes, double windows_planned = -1);

  // The writer's encoders and its frames' bytes for a budget and an output of about
  // `tets` tets (frames of frame_tets: fewer frames in flight when the output is small).
  static int encoders_for(std::uint64_t ceiling, int cores);
  // The frame size for a budget: a power of two, a 1024th of the budget in tets (the
  // writer's frames in flight then take ~14% of it), between kSmallestFrameTets and
  // kFrameTets, so budgets from 256M up keep the largest frames. Smaller frames
  // compress less well: each starts its codec afresh (scripts/bench-format).
  static std::size_t frame_tets_for(std::uint64_t ceiling);
  // The frames of this job: frame_tets_for(ceiling) unless the output was started
  // with another budget (a resumed job), whose frames it goes on with.
  std::size_t frame_tets() const { return frame_tets_; }
  void set_frame_tets(std::size_t tets) { frame_tets_ = tets; }
  // What the writer holds besides its frames: with --labels bricks, a brick of tets and
  // the label order's kept bricks (pipeline/write/brick_reorder.hpp). Part of the
  // writer's share of the triangulation.
  void set_label_order_bytes(std::uint64_t bytes) { label_order_bytes_ = bytes; }
  static std::uint64_t writer_bytes_for(int encoders, std::uint64_t tets, std::size_t frame_tets);

  // The keep step of a periodic job (pipeline/periodic/keep.hpp), recorded: its label
  // map and frames as they will be allocated, and the sort what is left, at most a
  // quarter of the ceiling (the padded container's pages, read as the frames are,
  // take the slack: scripts/bench-periodic's peak) and at least 4 MiB. UsageError
  // naming the --memory that would do when the map and frames do not fit.
  KeepShares plan_keep(std::uint64_t map_bytes, std::uint64_t frame_bytes);

  const std::vector<Share>& shares() const { return shares_; }
  // Sum of the recorded shares of a phase ("sort", "triangulate"), the reserve included.
  std::uint64_t phase_total(const std::string& phase) const;

 private:
  void record(const std::string& phase, const std::string& name, std::uint64_t bytes);

  std::uint64_t ceiling_, points_;
  int threads_, cores_;
  std::uint64_t runtime_;
  std::size_t frame_tets_;
  std::uint64_t label_order_bytes_ = 0;
  std::vector<Share> shares_;
};

}  // namespace tetstream::pipeline
