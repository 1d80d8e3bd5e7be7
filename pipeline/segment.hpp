#pragma once
// Stages 2-4 of `run`: the segment windows over the sorted point file, their
// triangulation with the kernel, the exactness check of DESIGN.md section 3, and the
// minimum vertex filter.
//
// Segment s owns the labels [zone_begin, zone_end) (its insertion zone). Its window
// holds those points, buffer points on each side along the sort axis, and the global
// convex hull's vertices (so the window's hull is the global hull). A zone vertex is
// *final* when every tet of its star is Delaunay with respect to all points:
//   (a) range test: the tet's circumball, clipped to the global bounding box in the
//       other two axes, lies strictly between the last missing point on the left and
//       the first on the right along the axis (with rigorous error margins), or
//   (b) emptiness query: no missing point is in conflict with the tet under the
//       kernel's own exact, perturbed predicates.
// A query that finds points inserts the deepest one into the window, and the zone's
// unfinished vertices are checked again (a final vertex stays final: its tets have
// empty balls, so no insertion touches them). Then each finite tet of a zone vertex's
// star whose minimum label is that vertex is emitted: every tet exactly once overall.
#include "core/delaunay.hpp"
#include "pipeline/point_index.hpp"
#include "pipeline/point_sort.hpp"

#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

namespace tetstream::pipeline {

// The sorted, duplicate-free points, read-only, addressed by label.
struct SortedView {
  const SortedPoint* points = nullptr;
  std::uint64_t count = 0;
  int axis = 0;
  double bbox_min[3], bbox_max[3];
  std::vector<std::uint64_t> hull_labels;  // sorted
  const PointIndex* index = nullptr;       // over points[0, count)
  // When `points` is a read-only file mapping: the mapped bytes a worker's emptiness
  // queries may keep resident before handing them back (0: never hand them back;
  // anonymous memory must not be, MADV_DONTNEED would zero it).
  std::uint64_t query_page_bytes = 0;

  double key(std::uint64_t label) const { return points[label].xyz[axis]; }
  // First label whose axis coordinate is >= x (count when none).
  std::uint64_t lower_bound(double x) const;
  // First label whose axis coordinate is > x.
  std::uint64_t upper_bound(double x) const;
};

// One zone of a segment, for parallel zonal insertion (the paper's section 3): the
// segment's zone points whose coordinate along `axis` lies in [lo, hi). It is
// triangulated alone, in a window of the segment's window points whose coordinate lies
// in [window_lo, window_hi] (the strip and a buffer on each side), plus the hull. Its
// boundary is made exact as a segment's is (DESIGN.md section 3): the points of the
// segment's label range outside the strip's window count as missing, for the range
// test and the emptiness query alike. axis < 0: the whole segment, no strip.
struct ZoneStrip {
  int axis = -1;
  double lo = 0, hi = 0;
  double window_lo = 0, window_hi = 0;
};

struct SegmentPlan {
  std::uint64_t zone_begin = 0, zone_end = 0;      // labels this segment owns
  std::uint64_t window_begin = 0, window_end = 0;  // labels in its window (zone + buffers)
  double buffer_width = 0;                         // of the buffers (and of its zones')
  // The segment's zones, in increasing strip order; one ZoneStrip{} (the whole
  // segment) unless split_into_zones cut it.
  std::vector<ZoneStrip> zones{ZoneStrip{}};
};

// Splits [first_label, count) into segments of about `zone_points` labels and gives
// each a window extended by `buffer_width` along the axis on each side. (A resumed job
// plans the labels it has not written yet; the output does not depend on the plan.)
std::vector<SegmentPlan> plan_segments(const SortedView& view, std::uint64_t zone_points, double buffer_width,
                                       std::uint64_t first_label = 0);

// The axis zones are cut along: the longer of the two other than the sort axis.
int strip_axis(const SortedView& view);

// Cuts the segment into `zones` strips along strip_axis, at quantiles of (a sample of)
// its zone points, so that each holds about the same number; fewer when the segment
// has too few points (at least 256 a zone) or too few distinct coordinates.
void split_into_zones(const SortedView& view, SegmentPlan& plan, int zones);

struct SegmentStats {
  std::uint64_t window_points = 0;  // zone + buffers + hull vertices, before repairs
  std::uint64_t repair_points = 0;  // inserted by the emptiness queries
  std::uint64_t range_failures = 0; // star tets the range test could not clear
  std::uint64_t queries = 0;        // emptiness queries run
  std::uint64_t query_points = 0;   // points the queries examined
  std::uint64_t rounds = 0;         // check/repair rounds
  std::uint64_t tets = 0;           // tets emitted
  std::uint64_t kernel_bytes = 0;   // the kernel's arrays at the end
  double seconds_build = 0, seconds_check = 0;  // check includes repairs and emission

  // Sums another worker's counters into these (rounds: the larger).
  SegmentStats& operator+=(const SegmentStats& o) {
    window_points += o.window_points, repair_points += o.repair_points, range_failures += o.range_failures;
    queries += o.queries, query_points += o.query_points, rounds = std::max(rounds, o.rounds), tets += o.tets;
    kernel_bytes += o.kernel_bytes, seconds_build += o.seconds_build, seconds_check += o.seconds_check;
    return *this;
  }
};

// Triangulates one zone of a segment (the whole segment for ZoneStrip{}) and appends
// the tets whose minimum label is one of its points (4 labels each, positively
// oriented) to `out`, grouped by minimum label in increasing order. Every label of the
// segment belongs to exactly one of its zones, so the zones' outputs together are the
// segment's tets, each once. Throws InputError when the window has fewer than 4
// affinely independent points (only possible when the whole input has).
SegmentStats triangulate_zone(const SortedView& view, const SegmentPlan& plan, const ZoneStrip& zone,
                              std::vector<std::uint64_t>& out);

// The smallest of a tet's 4 labels: the label that owns it under the minimum vertex
// rule, by which the output stream is grouped.
inline std::uint64_t tet_min_label(const std::uint64_t* q) {
  return std::min(std::min(q[0], q[1]), std::min(q[2], q[3]));
}

// Merges the outputs of a segment's zones into one stream grouped by minimum label in
// increasing order: calls sink(tets, count) with runs of whole groups.
template <class Sink>
void merge_by_min_label(const std::vector<std::vector<std::uint64_t>>& parts, Sink&& sink) {
  constexpr std::uint64_t kDone = ~std::uint64_t(0);
  std::vector<std::size_t> at(parts.size(), 0);  // next tet of each part
  auto next_label = [&](std::size_t p) { return 4 * at[p] < parts[p].size() ? tet_min_label(&parts[p][4 * at[p]]) : kDone; };
  for (;;) {
    // The part with the smallest next label, and the smallest next label of the others.
    std::size_t best = 0;
    std::uint64_t best_label = kDone, limit = kDone;
    for (std::size_t p = 0; p < parts.size(); ++p) {
      const std::uint64_t l = next_label(p);
      if (l < best_label) limit = best_label, best_label = l, best = p;
      else limit = std::min(limit, l);
    }
    if (best_label == kDone) return;
    // That part's run of groups below every other part's next label.
    std::size_t end = at[best];
    while (4 * end < parts[best].size() && tet_min_label(&parts[best][4 * end]) < limit) ++end;
    sink(parts[best].data() + 4 * at[best], end - at[best]);
    at[best] = end;
  }
}

}  // namespace tetstream::pipeline
