#pragma once
// The triangulate stage of `run`: the segments and their zones (pipeline/window/zone_triangulator.hpp), triangulated
// `threads` at a time, each segment's tets handed to the write stage in segment order.
//
// No checkpoint record of its own: its progress is the label below which every tet
// is written, which the write stage records with the bytes that hold those tets
// (pipeline/stage_write.hpp). prepare plans the labels from there on.
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/run/run.hpp"
#include "pipeline/window/shared_rim.hpp"
#include "pipeline/window/zone_triangulator.hpp"
#include "pipeline/run/stage_index.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/window/zone_plan.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>
#include <vector>

namespace tetstream::pipeline {

// Where the triangulation hands its segments, in segment order: the write stage, or
// a test's collector. One call a segment (a batch of zones), never one a tet.
class SegmentSink {
 public:
  // A segment's zones' tets, in plan order (each grouped by minimum label), with
  // their work and the segment's point count; every tet of the labels below
  // `next_label` is now in.
  virtual void add_segment(const std::vector<ZoneTets>& parts, const SegmentStats& work, std::uint64_t points,
                           std::uint64_t next_label) = 0;
  // A zone's tets as it emitted them, on the thread that triangulated it (zones run
  // `threads` at a time), before they wait for their turn in add_segment: `unit` is the
  // zone's place in the plan order (counted from the first zone this process runs).
  // A sink may transform them here in parallel (a periodic job keeps and certifies its
  // tets: pipeline/periodic/keep_stage.hpp); the write stage does nothing.
  virtual void zone_done(std::size_t /*unit*/, ZoneTets& /*tets*/) {}

 protected:
  ~SegmentSink() = default;
};

// The triangulation's shares of the ledger: the zone plan (the windows' share) and
// the fixed shares (writer, query pages, the indexes as measured).
struct TriangulatePlan {
  ZonePlan zones;
  TriangulateShares shares;
};
// Plans the triangulation for the indexed points on `threads` threads and records
// its shares in `budget`. UsageError, naming the budget that would work, when the
// windows do not fit.
TriangulatePlan plan_triangulation(const IndexStage& indexed, const RunOptions& options, MemoryBudget& budget,
                                   int threads);

class TriangulateStage {
 public:
  // `plan`: the segment size, zones per segment and buffer width, sized for the
  // windows' share; `query_page_bytes`: the share of the sorted file's pages that the
  // zones' emptiness queries map (handed back past it). The view's query tracker is
  // this stage's for its lifetime.
  TriangulateStage(const RunOptions& options, IndexStage& indexed, const ZonePlan& plan, std::uint64_t query_page_bytes,
                   std::uint64_t shared_rim_bytes, int threads);
  ~TriangulateStage();
  TriangulateStage(const TriangulateStage&) = delete;
  TriangulateStage& operator=(const TriangulateStage&) = delete;

  // Plans the segments of the labels from `first_label` (the write stage's record:
  // the labels below are written, by `first_segment` segments; the output does not
  // depend on the plan) to `end_label` (a rank's range; by default the last) and cuts
  // each into its zones.
  void prepare(std::uint64_t first_label, std::uint64_t first_segment, std::uint64_t end_label = ~std::uint64_t(0));

  // Under mpirun (pipeline/progress.hpp, share_to / add_shared): this rank's count
  // shared through the file `own` (counted from label `base`), and the line that prints
  // (rank 0's) adding the files `peers` and counting `total` labels: one line for the job.
  struct SharedProgress {
    std::string own;
    std::uint64_t base = 0;
    std::vector<std::string> peers;
    std::uint64_t total = 0;
  };
  void share_progress(SharedProgress shared) { shared_progress_ = std::move(shared); }
  // Triangulates every zone and hands each segment's tets to `out` once its last zone
  // is done. The first failure stops the others and is rethrown after the join.
  void run(SegmentSink& out);

  std::uint64_t segments() const { return plans_.size(); }
  std::uint64_t zones() const { return units_.size(); }
  // The triangulation's wall time, less what it spent waiting on the write stage.
  double seconds() const { return seconds_; }
  std::uint64_t query_region_releases() const { return query_regions_.releases(); }
  // What the windows of the plan prepare made take, from their measured sizes.
  double window_bytes() const { return window_bytes_; }
  // The most the finished zones' shared rim tets took (SharedRim).
  std::uint64_t shared_rim_peak_bytes() const { return shared_rim_.peak_bytes(); }

 private:
  struct Unit {
    std::size_t segment;
    std::size_t zone;
  };
  void collect(const Unit& unit, ZoneTets&& tets, const SegmentStats& stats, SegmentSink& out);
  // The warning, once, that the resident set passed the budget (after `plan`'s zones).
  void warn_if_past_budget(const SegmentPlan& plan);
  bool warned_past_budget_ = false;

  const RunOptions& options_;
  IndexStage& indexed_;
  const ZonePlan plan_;
  const int threads_;
  MappedRegions query_regions_;
  std::uint64_t first_label_ = 0, first_segment_ = 0, end_label_ = 0;
  std::optional<SharedProgress> shared_progress_;
  std::vector<SegmentPlan> plans_;
  std::vector<Unit> units_;  // every zone of every segment, in plan order
  // The order the threads take units_ in (run_order): a permutation of its indices.
  std::vector<std::size_t> run_order_;
  // Filled by collect, by zone: the current segment's zones' tets (in plan order
  // once all are in) and work.
  std::vector<ZoneTets> parts_;
  std::size_t parts_in_ = 0;
  SegmentStats segment_work_;
  OutputPool output_pool_;
  // The rim tets of finished zones for the zones still running; a segment's are
  // forgotten once every zone that could hold them has finished (collect).
  SharedRim shared_rim_;
  double seconds_ = 0;
  double window_bytes_ = 0;
  double sink_seconds_ = 0;  // in the sink's add_segment (the write stage's share of the wall time)
};

}  // namespace tetstream::pipeline
