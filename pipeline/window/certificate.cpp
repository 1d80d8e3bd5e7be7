#include "pipeline/window/certificate.hpp"

#include "core/facet_plane.hpp"
#include "core/predicates.hpp"
#include "pipeline/window/ball_bounds.hpp"
#include "pipeline/window/zone_triangulator.hpp"

#include <algorithm>
#include <cmath>

namespace tetstream::pipeline {

using core::TetId;
using core::VertexId;

namespace {

// The best-scored of the first few conflicting points a query finds (a lower score
// is a better repair). A region that holds points (a tet of the window's ragged edge)
// can hold thousands: the query stops after a few conflicts. Any conflicting point is
// a correct repair; the best of a sample converges nearly as fast.
struct BestConflict {
  static constexpr std::uint64_t kEnough = 16;
  std::uint64_t found = 0, label = Certificate::kNone;
  double score = std::numeric_limits<double>::infinity();
  double xyz[3] = {0, 0, 0};  // the best point's
  void offer(std::uint64_t l, double s, const double* p) {
    if (found++ == 0 || s < score) score = s, label = l, std::copy(p, p + 3, xyz);
  }
  bool enough() const { return found >= kEnough; }
};

// The facet of infinite tet t: its three finite vertices, in the tet's order.
void hull_facet(const core::Delaunay& dt, TetId t, VertexId f[3]) {
  int inf = 0;
  while (dt.vertex(t, inf) != core::kInfiniteVertex) ++inf;
  for (int m = 0; m < 3; ++m) f[m] = dt.vertex(t, core::kFacetVertex[inf][m]);
}

}  // namespace

ConflictBall conflict_ball(const core::Delaunay& dt, TetId t) {
  ConflictBall b{};
  const core::Circumsphere s = dt.tet_circumsphere(t);
  if (!s.valid) return b;
  for (int k = 0; k < 3; ++k) b.center[k] = s.center[k];
  // Every point of the true ball lies within radius + radius_error of the true
  // centre, hence within that plus sqrt(3) * center_error of the computed one.
  b.radius = (s.radius + s.radius_error + 1.7320508075688772 * s.center_error) * (1 + 1e-12);
  b.valid = std::isfinite(b.radius);
  return b;
}

void clipped_extent(const ConflictBall& b, const double* bbox_min, const double* bbox_max, int axis, double& lo,
                    double& hi) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    if (k == axis) continue;
    double d = 0;
    if (b.center[k] < bbox_min[k])
      d = bbox_min[k] - b.center[k];
    else if (b.center[k] > bbox_max[k])
      d = b.center[k] - bbox_max[k];
    d *= 1 - 1e-12;  // shrink the distance: a larger extent is always safe
    d2 += d * d;
  }
  const double r2 = conservative_square(b.radius);
  if (!may_reach(d2, r2)) {
    lo = 1, hi = 0;
    return;
  }
  // A centre inside the box across the other axes (most balls) leaves the extent at
  // the radius, with no square root. So does a ball whose squares are too small for a
  // relative bound (below 2^-900 the square root of an absolute error is not small).
  const double h = d2 == 0 || !(r2 - d2 >= 0x1p-900) ? b.radius : std::sqrt(r2 - d2) * (1 + 1e-12);
  const double c = b.center[axis];
  lo = c - h;
  hi = c + h;
  lo -= std::fabs(lo) * 1e-15;
  hi += std::fabs(hi) * 1e-15;
}

Certificate::Certificate(const SortedView& view) : view_(view) {
  // The index's boxes are floats rounded outward from the bounding box.
  for (int k = 0; k < 3; ++k)
    extent_[k] = ((view.bbox_max[k] - view.bbox_min[k]) +
                  (std::fabs(view.bbox_max[k]) + std::fabs(view.bbox_min[k])) * 0x1p-22) *
                 (1 + 0x1p-50);
}

void Certificate::start_zone(const SegmentPlan& plan, const Zone& zone, const std::vector<std::uint64_t>& held) {
  plan_ = &plan;
  zone_ = zone;
  held_ = &held;
  clear_lo_ = plan.window_begin == 0 ? -std::numeric_limits<double>::infinity() : view_.key(plan.window_begin - 1);
  clear_hi_ = plan.window_end == view_.count ? std::numeric_limits<double>::infinity() : view_.key(plan.window_end);
  segment_width_ = plan.label_end > plan.label_begin ? view_.key(plan.label_end - 1) - view_.key(plan.label_begin) : 0;
}

double Certificate::reach_past_window(const RangeTest& range) const {
  constexpr double kInfinity = std::numeric_limits<double>::infinity();
  if (!range.bounded) return kInfinity;
  if (range.outside_clear) return 0;
  const double past =
      std::max(range.hi >= clear_hi_ ? range.hi - clear_hi_ : 0.0, range.lo <= clear_lo_ ? clear_lo_ - range.lo : 0.0);
  if (!(segment_width_ > 0)) return kInfinity;
  // A ball that reaches a missing key exactly is past the window: never 0.
  return std::max(past / segment_width_, std::numeric_limits<double>::denorm_min());
}

bool Certificate::held(std::uint64_t label) const { return std::binary_search(held_->begin(), held_->end(), label); }

const double* Certificate::read_point(std::uint64_t label, QueryScratch& scratch) const {
  // The queries read points of the mapped sorted file all over it, and mapped pages
  // count in the resident set until they are handed back: every such read goes
  // through the view's MappedRegions, which keeps the regions it maps within their
  // share of the budget, or reads the points without mapping them when they are few
  // and far between. Points in memory are read directly.
  if (!view_.query_regions) {
    view_.points.xyz(label, scratch.xyz);
  } else {
    view_.query_regions->read(view_.points.record(label), scratch.record, view_.points.record_bytes());
    view_.points.decode(scratch.record, scratch.xyz);
  }
  return scratch.xyz;
}

RangeTest Certificate::range_test(const core::Delaunay& dt, TetId t) const {
  RangeTest r;
  r.ball = conflict_ball(dt, t);
  r.lo = -std::numeric_limits<double>::infinity(), r.hi = std::numeric_limits<double>::infinity();
  r.outside_clear = false, r.strip_clear = zone_.axis < 0;
  r.bounded = r.ball.valid;
  if (!r.bounded) {
    // No usable bound: the query examines every missing point exactly.
    r.ball.radius = std::numeric_limits<double>::infinity();
    r.ball.center[0] = r.ball.center[1] = r.ball.center[2] = 0;
    return r;
  }
  clipped_extent(r.ball, view_.bbox_min, view_.bbox_max, view_.axis, r.lo, r.hi);
  if (r.lo > r.hi) return r;
  r.outside_clear = r.lo > clear_lo_ && r.hi < clear_hi_;
  if (!r.strip_clear) {
    // Missing points of the window's label range lie outside [window_lo, window_hi]
    // along the strip's axis.
    double lo2, hi2;
    clipped_extent(r.ball, view_.bbox_min, view_.bbox_max, zone_.axis, lo2, hi2);
    r.strip_clear = lo2 > hi2 || (lo2 >= zone_.window_lo && hi2 <= zone_.window_hi);
  }
  return r;
}

template <class MayMeet, class Conflict>
std::uint64_t Certificate::best_missing_conflict(MayMeet&& may_meet, Conflict&& conflict, double lo, double hi,
                                                 bool outside_clear, bool strip_clear, SegmentStats& stats,
                                                 double* best_xyz) {
  ++stats.queries;
  BestConflict best;
  QueryScratch scratch;
  auto offer = [&](std::uint64_t label, const double* xyz) {
    const double score = conflict(label, xyz);
    if (!std::isnan(score)) best.offer(label, score, xyz);
  };
  auto visit = [&](std::uint64_t label) {
    if (!held(label)) offer(label, read_point(label, scratch));
  };
  // Missing points with an axis coordinate in [lo, hi]: two label ranges, one on each
  // side of the window, searched through the spatial index; and, for a strip, the
  // points of the window's range outside the strip's window. The label range is taken
  // from the key samples alone: up to a stride wider on each side, whose points the
  // ball test drops, and no probes of the file (their pages would be nobody's share
  // of the budget).
  const std::uint64_t first = view_.lower_bound_below(lo), last = view_.upper_bound_above(hi);
  auto enough = [&] { return best.enough(); };
  // The index prunes its nodes by the range's keys: bounds from the samples, so that
  // it reads no record of the file itself.
  auto search = [&](std::uint64_t a, std::uint64_t b, auto&& visit_label, const ExcludedSlab& exclude) {
    if (a >= b || enough()) return;
    const KeyRange keys = view_.key_range(a, b);
    view_.index->for_each_candidate_where(may_meet, a, b, visit_label, enough, exclude, &keys);
  };
  if (!outside_clear) {
    search(first, std::min(last, plan_->window_begin), visit, ExcludedSlab{});
    search(std::max(first, plan_->window_end), last, visit, ExcludedSlab{});
  }
  if (!strip_clear) {
    auto visit_outside_strip = [&](std::uint64_t label) {
      const double* xyz = read_point(label, scratch);
      if (!in_strip_window(xyz) && !held(label)) offer(label, xyz);
    };
    // The strip window's own points are not missing: whole index nodes inside it are
    // skipped, the rest filtered point by point.
    search(std::max(first, plan_->window_begin), std::min(last, plan_->window_end), visit_outside_strip,
           ExcludedSlab{zone_.axis, zone_.window_lo, zone_.window_hi});
  }
  if (best_xyz && best.found > 0) std::copy(best.xyz, best.xyz + 3, best_xyz);
  return best.label;
}

double conflict_score(const core::Delaunay& dt, TetId t, const ConflictBall& ball, std::uint64_t label, const double* p,
                      std::uint64_t* tested) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) d2 += (p[k] - ball.center[k]) * (p[k] - ball.center[k]);
  if (!may_reach(d2, conservative_square(ball.radius))) return std::numeric_limits<double>::quiet_NaN();
  if (tested) ++*tested;
  VertexId v[4];
  for (int i = 0; i < 4; ++i) v[i] = dt.vertex(t, i);
  const bool conflicts = core::insphere_sos(dt.point(v[0]), dt.point(v[1]), dt.point(v[2]), dt.point(v[3]), p,
                                            dt.label(v[0]), dt.label(v[1]), dt.label(v[2]), dt.label(v[3]), label) > 0;
  // The score ranks points within one query, where the ball is fixed: d2 alone (never
  // NaN, also when the squares overflow).
  return conflicts ? d2 : std::numeric_limits<double>::quiet_NaN();
}

std::uint64_t Certificate::query(const core::Delaunay& dt, TetId t, const RangeTest& range, SegmentStats& stats,
                                 double* found_xyz) {
  // The deepest conflicting point: the one nearest the enclosing ball's centre.
  auto conflict = [&](std::uint64_t label, const double* p) {
    return conflict_score(dt, t, range.ball, label, p, &stats.query_points);
  };
  const BallRegion may_meet{range.ball.center, range.ball.radius};
  return best_missing_conflict(may_meet, conflict, range.lo, range.hi, range.outside_clear, range.strip_clear, stats,
                               found_xyz);
}

bool Certificate::hull_facet_range_test(const core::Delaunay& dt, TetId t) const {
  VertexId f[3];
  hull_facet(dt, t, f);
  const core::FacetPlane plane(dt.point(f[0]), dt.point(f[1]), dt.point(f[2]), extent_);
  // The closed half-space beyond the facet must miss the parts of the bounding box
  // where missing points can lie: left and right of the window's label range along
  // the sort axis, outside the strip's window inside it.
  auto reaches = [&](int k1, double hi1, int k2, double lo2) {  // the box with bbox_max[k1] = hi1, bbox_min[k2] = lo2
    double lo[3], hi[3];
    for (int k = 0; k < 3; ++k) lo[k] = view_.bbox_min[k], hi[k] = view_.bbox_max[k];
    if (k1 >= 0) hi[k1] = std::min(hi[k1], hi1);
    if (k2 >= 0) lo[k2] = std::max(lo[k2], lo2);
    return plane.box_may_reach(lo, hi);
  };
  const std::uint64_t w0 = plan_->window_begin, w1 = plan_->window_end;
  const bool outside_clear = (w0 == 0 || !reaches(view_.axis, view_.key(w0 - 1), -1, 0)) &&
                             (w1 == view_.count || !reaches(-1, 0, view_.axis, view_.key(w1)));
  const bool strip_clear =
      zone_.axis < 0 || (!reaches(zone_.axis, zone_.window_lo, -1, 0) && !reaches(-1, 0, zone_.axis, zone_.window_hi));
  return outside_clear && strip_clear;
}

bool Certificate::is_global_hull_facet(const core::Delaunay& dt, TetId t) const {
  if (view_.hull_facets.empty()) return false;
  VertexId f[3];
  hull_facet(dt, t, f);
  LabelTriple key{dt.label(f[0]), dt.label(f[1]), dt.label(f[2])};
  std::sort(key.begin(), key.end());
  return std::binary_search(view_.hull_facets.begin(), view_.hull_facets.end(), key);
}

std::uint64_t Certificate::hull_facet_query(const core::Delaunay& dt, TetId t, SegmentStats& stats) {
  // Only the global hull's boundary points need to be searched. If abc is not a
  // global hull facet, a boundary point lies beyond its plane or conflicts on it: the
  // hull of all points is the hull of the boundary points, and a window vertex not on
  // the boundary is strictly inside it, so a plane through it has boundary points on
  // both sides. If abc is one, every point is on or below its plane, and those on it
  // are boundary points. The window's own points never conflict with its hull facet.
  ++stats.queries;
  VertexId f[3];
  hull_facet(dt, t, f);
  const double *a = dt.point(f[0]), *b = dt.point(f[1]), *c = dt.point(f[2]);
  const core::FacetPlane plane(a, b, c, extent_);
  const std::uint64_t la = dt.label(f[0]), lb = dt.label(f[1]), lc = dt.label(f[2]);
  double centroid[3];
  for (int k = 0; k < 3; ++k) centroid[k] = (a[k] + b[k] + c[k]) / 3;
  BestConflict nearest;
  auto visit = [&](std::uint64_t i) {
    const SortedPoint& h = view_.hull_points[i];
    const std::uint64_t label = h.original;
    if (in_window(label, h.xyz) || held(label)) return;
    ++stats.query_points;
    if (core::infinite_conflict_sos(a, b, c, h.xyz, la, lb, lc, label) <= 0) return;
    double d2 = 0;
    for (int k = 0; k < 3; ++k) d2 += (h.xyz[k] - centroid[k]) * (h.xyz[k] - centroid[k]);
    nearest.offer(label, d2, h.xyz);
  };
  view_.hull_index->for_each_candidate_where(
      [&](const double* box_lo, const double* box_hi) { return plane.box_may_reach(box_lo, box_hi); }, 0,
      view_.hull_points.size(), visit, [&] { return nearest.enough(); });
  return nearest.found == 0 ? kNone : nearest.label;
}

}  // namespace tetstream::pipeline
