#pragma once
// The zone plan: how many points a segment takes and into how many zones (strips) it
// is cut, from the windows' share of the memory ledger (pipeline/memory_budget.hpp).
#include "core/error.hpp"
#include "pipeline/window/point_index.hpp"
#include "pipeline/sort/point_sort.hpp"
#include "pipeline/window/zone_triangulator.hpp"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

// The segment size and the zones per segment for the budget.
//
// Model (points spread evenly over the bounding box; spacing w0 = cbrt(volume / n),
// buffer width w = buffer_spacings w0). A segment of S labels is a slab across the sort
// axis; its window adds the two axis buffers, B = 2 w n / E_axis points for the whole
// cross-section. Cut into k zones (strips along strip_axis, of width E_strip / k),
// each zone's window is the share 1/k + 2 w / E_strip of the segment's window:
//   window(k) = (S + B) min(1, 1/k + 2w/E_strip [k > 1]),   zone Z = S / k.
// Memory: `threads` zones in flight, each window at kWindowBytesPerPoint, and the
// output of one segment plus threads - 1 zones at kOutputBytesPerPoint:
//   threads window(k) 480 + (k + threads - 1) Z 125 <= available,
// available = the windows' share of the ledger (MemoryBudget::plan_triangulate: 75% of
// what the runtime reserve and the writer leave of the budget, less the point indexes
// and the hull's points). The other 25% holds the mapped pages of the sorted file that
// the queries read (SortedView::query_regions) and the allocator's slack.
// That is linear in Z; for each k the largest Z follows, and the k with the smallest
// redundancy (window / Z - 1) wins: thin slabs waste their buffers, narrow strips
// theirs, and the best zone is about as wide as its slab is thick. --segment-points
// fixes S (tests force many segments) and --zones fixes k.
struct ZonePlan {
  std::uint64_t segment_points = 0;
  int zones = 1;
  double buffer_width = 0;
  double window_bytes = 0;     // the model's memory for this plan (at most the windows' share)
  double available = 0;        // the windows' share of the ledger the plan was made for
  double buffer_spacings = 0;  // buffer_width in spacings (--buffer)
  bool fixed = false;          // the segment size or the zones came from the options
};

// What the plan reads of the job's options (pipeline/run/run.hpp, RunOptions; the job
// fills it with plan_options()): the budget, the buffers' thickness in spacings, and the
// segment size and zone count when the options fix them (0: from the budget).
struct PlanOptions {
  std::uint64_t memory_bytes = 0;
  double buffer_spacings = 0;
  std::uint64_t segment_points = 0;
  int zones = 0;
  // A refusal names the user's --memory: `stated_bytes` (0: memory_bytes), when the
  // job's caller gave it less (a periodic job keeps its tables beside the padded job),
  // and suggests what the job needs plus `reserved_bytes`, what that caller holds.
  std::uint64_t stated_bytes = 0, reserved_bytes = 0;
  // The user's points among the job's (0: all of them; a periodic job's padded job
  // adds their images), so that the refusal counts what the user gave.
  std::uint64_t stated_points = 0;
  // The output's frames (RunOptions::frame_tets), for the writer's share; 0: the budget's.
  std::size_t frame_tets = 0;
};

// What the plan is made from: the sorted view and its index once they exist, or,
// before the sort, the first pass's count and bounding box with the index's size
// estimated (pipeline/memory_budget.hpp) and the mean spacing for the buffers.
struct PlanInputs {
  std::uint64_t points = 0;
  double extent[3] = {0, 0, 0};
  int axis = 0, strip_axis = 1;
  double leaf_spacing = 0;  // 0: unknown (the bounding box's mean spacing is used)
  std::uint64_t index_bytes = 0;
};

// The inputs of the plan once the sorted view and its index exist.
PlanInputs plan_inputs(const SortedView& view, const PointIndex& index);

// The plan for o.memory_bytes; when it cannot hold a window, a UsageError that names
// the smallest budget that can (to a mebibyte, found by bisection: the plan is cheap).
ZonePlan plan_for_budget(const PlanInputs& in, const PlanOptions& o, int threads);

// The segments of the labels from `first_label` on, cut into their zones, with
// their windows measured rather than modelled: the model assumes points spread
// evenly, and in clusters a window's buffers hold several times the points it
// expects. So each zone's
// window is counted from a sample of its segment's window labels, and while the
// largest run of `threads` consecutive windows (the zones run in order, `threads` at
// once) and a segment's output take more than the plan's share: first each segment's buffers become as many spacings as
// the plan's but of its own points' (median) spacing when that is smaller (a slab through a dense cluster); then the
// segments shrink, as long as that helps (a plan fixed by --segment-points or --zones is kept). `window_bytes` is the
// measured need of the plan returned.
struct SegmentCut {
  std::vector<SegmentPlan> plans;
  double window_bytes = 0;
  std::uint64_t largest_window = 0;  // points, estimated
};
// The segments of labels [first_label, end_label) (a rank's range under MPI; by default
// to the last label) and their zones.
SegmentCut cut_segments(const SortedView& view, const ZonePlan& plan, std::uint64_t first_label, int threads,
                        std::uint64_t end_label = ~std::uint64_t(0));

// The order in which the zones of one segment of `zones` strips start: every other
// strip, then the strips between them (0, 2, 4, ..., 1, 3, ...). Zones that run at the
// same time cannot use each other's rims (docs/certificate.md, Lemma 7: a zone hands
// its rim on when it ends), so two neighbouring strips running side by side each
// prove the rim between them; in this order a strip between two others starts after
// both. On `hills`, 10^6 points, the same plan of 9 x 5 zones: 3.30 M queries on one
// thread, 3.75 M on two in plan order.
std::vector<std::size_t> zone_start_order(std::size_t zones);

// A budget refused before the sort: nothing worth keeping was done.
class BudgetTooSmall : public UsageError {
 public:
  using UsageError::UsageError;
};

// After the first pass (count and bounding box, nothing written): throws
// BudgetTooSmall when the budget cannot hold this many points even with buffers of
// width 0 and the index's smallest size, i.e. when no plan after the sort could work
// either. A budget that passes may still be refused after the sort, by the exact
// plan, with the sort's work kept for a --resume.
void refuse_budget_before_sort(const SortProgress& p, const PlanOptions& o, int threads);

}  // namespace tetstream::pipeline
