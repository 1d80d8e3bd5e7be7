#pragma once
// Stages 2-4 of `run`: the segment windows over the sorted point file, their
// triangulation with the kernel, the exactness check of DESIGN.md section 3, and the
// minimum vertex filter.
//
// Segment s owns the labels [zone_begin, zone_end) (its insertion zone). Its window
// holds those points and buffer points on each side along the sort axis. A zone
// vertex is *final* when every tet of its star is Delaunay with respect to all points:
//   (a) range test: the tet's circumball, clipped to the global bounding box in the
//       other two axes, lies strictly between the last missing point on the left and
//       the first on the right along the axis (with rigorous error margins); for an
//       infinite tet (a hull facet of the window), the half-space beyond the facet
//       misses the parts of the bounding box where missing points lie; or
//   (b) emptiness query: no missing point is in conflict with the tet under the
//       kernel's own exact, perturbed predicates (for a hull facet, it suffices to
//       search the global hull's boundary points: see check_hull_facet).
// A query that finds points inserts the deepest one into the window, and the zone's
// unfinished vertices are checked again (a final vertex stays final: its tets have
// empty balls, so no insertion touches them). Then each finite tet of a zone vertex's
// star whose minimum label is that vertex is emitted: every tet exactly once overall.
#include "core/delaunay.hpp"
#include "pipeline/point_index.hpp"
#include "pipeline/point_record.hpp"
#include "pipeline/point_sort.hpp"
#include "pipeline/temp_files.hpp"

#include <algorithm>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

namespace tetstream::pipeline {

// The sorted, duplicate-free points, read-only, addressed by label.
struct SortedView {
  PointRecords points;  // the sorted file's records (pipeline/point_record.hpp)
  std::uint64_t count = 0;
  int axis = 0;
  double bbox_min[3], bbox_max[3];
  // Every point on the boundary of the convex hull (hull.hpp), by increasing label:
  // its coordinates, and its label in `original`, with a spatial index of their own.
  // A window's hull facet is a facet of the global hull exactly when none of these
  // points conflicts with it.
  std::vector<SortedPoint> hull_points;
  const PointIndex* hull_index = nullptr;  // over hull_points
  const PointIndex* index = nullptr;       // over points[0, count)
  // When `points` is a read-only file mapping: the tracker that keeps the regions the
  // workers' emptiness queries map within their share of the budget, and hands them
  // back. Null for points in memory (anonymous memory must never be handed back:
  // MADV_DONTNEED would zero it).
  MappedRegions* query_regions = nullptr;

  // The key of every kKeyStride-th label, so that lower_bound and upper_bound search
  // a small in-memory table and then one stride of the file, instead of probing the
  // mapped file all over (a cache and TLB miss each: a quarter of the check's time).
  static constexpr std::uint64_t kKeyStride = 128;
  std::vector<double> key_samples;
  // Fills key_samples. When `points` is a read-only file mapping, release_file_pages
  // hands the pages back as it goes (a sample every 4 KiB touches every page).
  void sample_keys(bool release_file_pages = false);

  double key(std::uint64_t label) const { return points.coord(label, axis); }
  // First label whose axis coordinate is >= x (count when none).
  std::uint64_t lower_bound(double x) const;
  // First label whose axis coordinate is > x.
  std::uint64_t upper_bound(double x) const;
  // The same from the key samples alone, without reading the points: a label at most
  // lower_bound(x), and one at least upper_bound(x), each within kKeyStride of it
  // (0 and count without samples).
  std::uint64_t lower_bound_below(double x) const;
  std::uint64_t upper_bound_above(double x) const;
  // Bounds on the keys of the labels [first, last) (first < last), from the samples
  // alone when there are any.
  KeyRange key_range(std::uint64_t first, std::uint64_t last) const;
};

// Hands back the pages of the sorted file behind a scan that reads labels in
// increasing order, 4 MiB of records at a time, so that the scan's pages never add
// up in the resident set (window loads, key samples, the hull gather). Does nothing
// when `enabled` is false (anonymous memory, which MADV_DONTNEED would zero).
class ReleaseBehind {
 public:
  ReleaseBehind(const PointRecords& points, std::uint64_t first, bool enabled)
      : points_(points), released_(first), enabled_(enabled) {}
  ~ReleaseBehind() { release_to(reached_); }
  // The scan is at `label`: every chunk wholly below it is handed back.
  void reached(std::uint64_t label) {
    reached_ = std::max(reached_, label + 1);
    if (label >= released_ + kChunk) release_to(label / kChunk * kChunk);
  }

 private:
  static constexpr std::uint64_t kChunk = std::uint64_t(1) << 17;
  void release_to(std::uint64_t end) {
    if (enabled_ && end > released_)
      release_mapped_pages(points_.record(released_), (end - released_) * points_.record_bytes());
    released_ = std::max(released_, end);
  }
  PointRecords points_;
  std::uint64_t released_, reached_ = 0;
  bool enabled_;
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

// Splits [first_label, min(end_label, count)) into segments of about `zone_points`
// labels and gives each a window extended by `buffer_width` along the axis on each
// side. (A resumed job plans the labels it has not written yet, a rank under MPI its
// own range; the output does not depend on the plan.)
std::vector<SegmentPlan> plan_segments(const SortedView& view, std::uint64_t zone_points, double buffer_width,
                                       std::uint64_t first_label = 0, std::uint64_t end_label = ~std::uint64_t(0));

// The axis zones are cut along: the longer of the two other than the sort axis.
int strip_axis(const SortedView& view);

// Cuts the segment into `zones` strips along strip_axis, near quantiles of (a sample
// of) its zone points, so that each holds about the same number (within a tenth of a
// zone's share: each cut at the emptiest place near its quantile); fewer when the
// segment has too few points (at least 256 a zone) or too few distinct coordinates.
void split_into_zones(const SortedView& view, SegmentPlan& plan, int zones);

struct SegmentStats {
  std::uint64_t window_points = 0;  // zone + buffers + hull vertices, before repairs
  // Where the window's points beyond the zone's own come from: the segment's buffers
  // along the sort axis (inside the zone's strip), the strip buffers that cutting the
  // segment into zones adds (everything outside the strip: the price of parallel
  // zones), and the hull's vertices from elsewhere.
  std::uint64_t segment_buffer_points = 0, zone_buffer_points = 0, hull_points = 0;
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
    segment_buffer_points += o.segment_buffer_points, zone_buffer_points += o.zone_buffer_points;
    hull_points += o.hull_points;
    queries += o.queries, query_points += o.query_points, rounds = std::max(rounds, o.rounds), tets += o.tets;
    kernel_bytes += o.kernel_bytes, seconds_build += o.seconds_build, seconds_check += o.seconds_check;
    return *this;
  }
};

// The tets one zone emits: those whose minimum label is one of its points, 4 local
// vertex ids each (positively oriented), grouped by minimum label in increasing
// order, with the table from local id to label. (A segment's zones are held until its
// last one is done: 16 bytes a tet and the window's labels are half of what 4 labels a
// tet would take, and the budget buys larger zones with the difference.)
struct ZoneTets {
  std::vector<std::uint32_t> tets;    // 4 local ids per tet
  std::vector<std::uint64_t> labels;  // local id -> label
  std::size_t size() const { return tets.size() / 4; }
  std::uint64_t label(std::size_t tet, int i) const { return labels[tets[4 * tet + std::size_t(i)]]; }
  std::uint64_t min_label(std::size_t tet) const {
    return std::min(std::min(label(tet, 0), label(tet, 1)), std::min(label(tet, 2), label(tet, 3)));
  }
};

// Zone outputs recycled between zones (thread-safe): a zone takes one when it emits,
// not before, so it holds no output while its kernel builds; the merge gives them
// back. Fresh pages cost the OS's zeroing, and a zone's output is 100+ bytes a point.
class OutputPool {
 public:
  ZoneTets take();  // empty, with the capacity of a given-back one if any
  void give(ZoneTets&& v);

 private:
  std::mutex mutex_;
  std::vector<ZoneTets> spare_;
};

class SegmentWorker;
// Triangulates zones of segments, one at a time, and emits each one's tets into `out`
// (taken from `pool` when given). Every label of a segment belongs to exactly one of
// its zones, so the zones' outputs together are the segment's tets, each once. Throws
// InputError when a window has fewer than 4 affinely independent points (only possible
// when the whole input has).
//
// The kernel and the buffers keep their capacity from one zone to the next, instead
// of faulting fresh pages in for each (the OS's zeroing of fresh pages was 10.5% of
// a one-thread profile). One object per thread (not thread-safe).
class ZoneTriangulator {
 public:
  explicit ZoneTriangulator(const SortedView& view, OutputPool* pool = nullptr);
  ~ZoneTriangulator();
  SegmentStats run(const SegmentPlan& plan, const ZoneStrip& zone, ZoneTets& out);

 private:
  std::unique_ptr<SegmentWorker> worker_;
};

// The smallest of a tet's 4 labels: the label that owns it under the minimum vertex
// rule, by which the output stream is grouped.
inline std::uint64_t tet_min_label(const std::uint64_t* q) {
  return std::min(std::min(q[0], q[1]), std::min(q[2], q[3]));
}

// Merges the outputs of a segment's zones into one stream grouped by minimum label in
// increasing order: calls sink(part, begin, end) for each run [begin, end) of whole
// groups of one part (a group is one label's tets, and a label is in one zone), in
// stream order. The sink reads the labels itself: no intermediate copy.
template <class Sink>
void merge_by_min_label(const std::vector<ZoneTets>& parts, Sink&& sink) {
  constexpr std::uint64_t kDone = ~std::uint64_t(0);
  std::vector<std::size_t> at(parts.size(), 0);  // next tet of each part
  auto next_label = [&](std::size_t p) { return at[p] < parts[p].size() ? parts[p].min_label(at[p]) : kDone; };
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
    const ZoneTets& part = parts[best];
    const std::size_t begin = at[best];
    std::size_t& i = at[best];
    while (i < part.size() && part.min_label(i) < limit) ++i;
    sink(part, begin, i);
  }
}

}  // namespace tetstream::pipeline
