#pragma once
// The certificate: the tests that prove a tet of a zone's window Delaunay with respect
// to *all* the points, not only the window's (docs/certificate.md states the rule and
// its proof; this file names the same pieces).
//
// A zone's window holds its own points and buffers; every other point is *missing*:
// the labels outside the window's label range, and, for a zone that is a strip of its
// segment, the points of that range outside the strip's window. A window tet is
// certified when no missing point is in conflict with it, under the kernel's own exact
// predicates and symbolic perturbation:
//   - range test (cheap, conservative): the tet's conflict ball, clipped to the
//     bounding box across the sort axis, reaches no missing point's place (RangeTest);
//     for an infinite tet (a hull facet of the window), the half-space beyond the facet
//     misses the parts of the bounding box where missing points lie;
//   - emptiness query (exact): the missing points the point index cannot rule out are
//     tested one by one (Certificate::query); for a hull facet only the global hull's
//     boundary points need to be (Certificate::hull_facet_query).
// A query that finds conflicting points returns the deepest of the first few found: the
// repair point the zone inserts before its next round.
#include "core/delaunay.hpp"
#include "pipeline/window/segment_plan.hpp"
#include "pipeline/window/sorted_view.hpp"

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace tetstream::pipeline {

struct SegmentStats;

// A closed ball that contains every point that could conflict with a finite tet: its
// circumball, enlarged by the rigorous error bounds of the computed centre and radius.
struct ConflictBall {
  double center[3];
  double radius;
  bool valid;  // false when the tet is too flat for a usable bound
};
ConflictBall conflict_ball(const core::Delaunay& dt, core::TetId t);

// The extent along `axis` of the ball clipped to the box [bbox_min, bbox_max] in the two
// other axes (points outside the box do not exist): [lo, hi], or lo > hi when the
// clipped ball is empty. Conservative: rounding only widens it.
void clipped_extent(const ConflictBall& b, const double* bbox_min, const double* bbox_max, int axis, double& lo,
                    double& hi);

// A finite tet's range test and what its query, if it needs one, will read: the range
// of the sort axis its clipped ball reaches, [lo, hi] (lo > hi: empty), and whether
// the missing points outside the window's label range (outside_clear) or outside the
// strip's window inside it (strip_clear) are out of its reach. `bounded` is false
// when the ball has no usable bound: the query then examines every missing point.
struct RangeTest {
  ConflictBall ball;
  double lo, hi;
  bool bounded, outside_clear, strip_clear;
  // The tet is certified by the range test alone.
  bool clears() const { return bounded && (lo > hi || (outside_clear && strip_clear)); }
};

// Whether point p (label) conflicts with finite tet t of `dt`, whose conflict ball is
// `ball`: NaN when it does not (the ball's distance test first, then insphere_sos),
// else its squared distance to the ball's centre (a query's score). `tested`, when
// given, counts the exact tests. The queries' test, and ZoneWorker's for the repair
// points a round has already found.
double conflict_score(const core::Delaunay& dt, core::TetId t, const ConflictBall& ball, std::uint64_t label,
                      const double* p, std::uint64_t* tested);

// One point read by a query: its record as copied from the file, and its coordinates.
struct QueryScratch {
  alignas(8) std::byte record[32];
  double xyz[3];
};

class Certificate {
 public:
  static constexpr std::uint64_t kNone = std::numeric_limits<std::uint64_t>::max();

  explicit Certificate(const SortedView& view);

  // Starts a zone of `plan`. `held` (sorted, kept by the caller for the zone's life)
  // lists the labels outside the window proper that the window holds anyway: repair
  // points and, in a window too flat for a triangulation of its own, hull vertices.
  void start_zone(const SegmentPlan& plan, const Zone& zone, const std::vector<std::uint64_t>& held);

  // Whether the point lies in the zone's strip window across the strip axis.
  bool in_strip_window(const double* xyz) const {
    return zone_.axis < 0 || (xyz[zone_.axis] >= zone_.window_lo && xyz[zone_.axis] <= zone_.window_hi);
  }
  // Whether the point (label, xyz) is in the window proper: its label range, and the
  // strip's window inside it.
  bool in_window(std::uint64_t label, const double* xyz) const {
    return label >= plan_->window_begin && label < plan_->window_end && in_strip_window(xyz);
  }

  // The range test of finite tet t.
  RangeTest range_test(const core::Delaunay& dt, core::TetId t) const;
  // How far the clipped ball of a tet that failed `range` reaches past the window's
  // keys along the sort axis, in widths of the zone's segment (the keys of its first
  // and last labels): 0 when it stays between them (only the strip's window was too
  // narrow), infinite for a ball without a bound or a segment of one key. The
  // distance a certificate that waits for later (or looks back at earlier) segments
  // would have to see: --json's empty_query_reach.
  double reach_past_window(const RangeTest& range) const;
  // The emptiness query of finite tet t, which failed `range`: kNone when no missing
  // point conflicts with it, else the deepest (nearest the ball's centre) of the first
  // few conflicting points found, whose coordinates go to found_xyz when given.
  std::uint64_t query(const core::Delaunay& dt, core::TetId t, const RangeTest& range, SegmentStats& stats,
                      double* found_xyz = nullptr);

  // The range test of infinite tet t (a hull facet of the window): true when the
  // closed half-space beyond its facet misses every place a missing point can be.
  bool hull_facet_range_test(const core::Delaunay& dt, core::TetId t) const;
  // Whether the hull facet of infinite tet t is one of the global hull's facets that
  // the view lists (SortedView::hull_facets): then no point conflicts with it, and no
  // query is needed. False also when the view lists none.
  bool is_global_hull_facet(const core::Delaunay& dt, core::TetId t) const;
  // Whether the hull facet of infinite tet t is a facet of the global hull: kNone when
  // no missing point conflicts with it, else the conflicting global hull boundary point
  // nearest the facet's centroid of the first few found.
  std::uint64_t hull_facet_query(const core::Delaunay& dt, core::TetId t, SegmentStats& stats);

  // Reads a missing point's coordinates (into scratch) without mapping more of the
  // sorted file than its share of the budget (SortedView::query_regions).
  const double* read_point(std::uint64_t label, QueryScratch& scratch) const;

 private:
  // Exact search of the missing points whose axis coordinate lies in [lo, hi], among
  // the index boxes may_meet lets through; conflict(label, p) is the point's score
  // when it conflicts (lower: a better repair), NaN otherwise.
  template <class MayMeet, class Conflict>
  std::uint64_t best_missing_conflict(MayMeet&& may_meet, Conflict&& conflict, double lo, double hi, bool outside_clear,
                                      bool strip_clear, SegmentStats& stats, double* best_xyz = nullptr);
  bool held(std::uint64_t label) const;

  const SortedView& view_;
  // What |p_k - q_k| can reach for points p, q in the index's boxes, for the hull
  // facets' error bounds.
  double extent_[3];
  const SegmentPlan* plan_ = nullptr;
  Zone zone_;
  const std::vector<std::uint64_t>* held_ = nullptr;
  // Along the sort axis, the missing points left of the window's label range have
  // coordinates <= clear_lo_, those right of it >= clear_hi_ (infinite: none).
  double clear_lo_ = 0, clear_hi_ = 0;
  double segment_width_ = 0;  // key(label_end - 1) - key(label_begin)
};

}  // namespace tetstream::pipeline
