#include "pipeline/segment.hpp"

#include "pipeline/hull.hpp"

#include "core/error.hpp"
#include "core/huge_pages.hpp"
#include "core/predicates.hpp"
#include "core/spatial_sort.hpp"
#include "pipeline/temp_files.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <array>
#include <exception>
#include <limits>

namespace tetstream::pipeline {

namespace {

using core::TetId;
using core::VertexId;
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// A closed ball that contains every point that could conflict with a finite tet:
// its circumball, enlarged by the rigorous error bounds of the computed centre and
// radius.
struct ConflictBall {
  double center[3];
  double radius;
  bool valid;  // false when the tet is too flat for a usable bound
};

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

// The extent along `axis` of the ball clipped to the global bounding box in the two
// other axes (points outside the box do not exist): [lo, hi], or lo > hi when the
// clipped ball is empty. Conservative: rounding only widens it.
void clipped_extent(const ConflictBall& b, const SortedView& view, int axis, double& lo, double& hi) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    if (k == axis) continue;
    double d = 0;
    if (b.center[k] < view.bbox_min[k]) d = view.bbox_min[k] - b.center[k];
    else if (b.center[k] > view.bbox_max[k]) d = b.center[k] - view.bbox_max[k];
    d *= 1 - 1e-12;  // shrink the distance: a larger extent is always safe
    d2 += d * d;
  }
  // The squares are compared with an absolute slack of 2^-1060 as well: near the
  // subnormals each rounds by up to 2^-1075 absolutely, whatever its size.
  const double r2 = b.radius * b.radius * (1 + 1e-12);
  if (d2 > r2 + 0x1p-1060) {
    lo = 1, hi = 0;
    return;
  }
  // A centre inside the box across the other axes (most balls) leaves the extent at
  // the radius, with no square root (this function was 2.3% of a 10^7-point run's
  // samples, a sixth of the checks'). So does a ball whose squares are too small for
  // a relative bound (below 2^-900 the square root of an absolute error is not small).
  const double h = d2 == 0 || !(r2 - d2 >= 0x1p-900) ? b.radius : std::sqrt(r2 - d2) * (1 + 1e-12);
  const double c = b.center[axis];
  lo = c - h;
  hi = c + h;
  lo -= std::fabs(lo) * 1e-15;
  hi += std::fabs(hi) * 1e-15;
}

// The best-scored of the first few conflicting points a query finds (a lower score
// is a better repair). A region that holds points (a tet of the window's ragged edge)
// can hold thousands: the query stops after a few conflicts. Any conflicting point is
// a correct repair; the best of a sample converges nearly as fast.
struct BestConflict {
  static constexpr std::uint64_t kEnough = 16;
  std::uint64_t found = 0, label = std::numeric_limits<std::uint64_t>::max();  // max: none
  double score = std::numeric_limits<double>::infinity();
  void offer(std::uint64_t l, double s) {
    if (found++ == 0 || s < score) score = s, label = l;
  }
  bool enough() const { return found >= kEnough; }
};

// One point read by a query: its record as copied from the file, and its coordinates.
struct QueryScratch {
  alignas(8) std::byte record[32];
  double xyz[3];
};

}  // namespace

// The state of one thread's zone triangulations. It lives across zones: the kernel
// and the buffers keep their capacity from one zone to the next, so a thread faults
// its memory in once (fresh pages cost the OS's zeroing: 10.5% of a one-thread profile
// when every zone allocated anew).
class SegmentWorker {
 public:
  SegmentWorker(const SortedView& view, OutputPool* pool) : view_(view), pool_(pool) {
    // What |p_k - q_k| can reach for points p, q in the index's boxes (floats rounded
    // outward from the bounding box), for the hull facets' error bounds.
    for (int k = 0; k < 3; ++k)
      extent_[k] = ((view.bbox_max[k] - view.bbox_min[k]) + (std::fabs(view.bbox_max[k]) + std::fabs(view.bbox_min[k])) * 0x1p-22) *
                   (1 + 0x1p-50);
  }

  SegmentStats run(const SegmentPlan& plan, const ZoneStrip& strip, ZoneTets& out);

 private:
  // The zone's window: its label range's points inside the strip's window; with
  // `with_hull`, also the global hull's vertices (only for a window too flat for a
  // triangulation of its own).
  void load_window(bool with_hull);
  // One round: marks the pending zone vertices whose stars hold a tet that is not
  // safe (collecting repair points), declares the others final, and returns how
  // many zone vertices remain pending.
  std::size_t check_round(std::vector<std::uint64_t>& repairs);
  void emit(ZoneTets& out);
  // Whether tet t passes the range test (or is a hull facet that its query clears, or
  // was proved empty before). A finite tet that fails it goes to queued_, and
  // query_tet() settles it once the round has queued all of them.
  bool check_tet(TetId t, std::vector<std::uint64_t>& repairs);
  // The emptiness query of a queued tet: true when no missing point conflicts with it,
  // else false with the repair point pushed.
  struct QueuedTet;
  bool query_tet(const QueuedTet& q, std::vector<std::uint64_t>& repairs);
  // The range of the sort axis a finite tet's query reads, clipped ball and all:
  // [lo, hi] (lo > hi: empty), and whether the missing points outside the window's
  // label range (outside_clear) or outside the strip's window inside it (strip_clear)
  // are out of its reach. Returns false when the ball has no usable bound (then the
  // query reads everything).
  bool query_extent(TetId t, ConflictBall& ball, double& lo, double& hi, bool& outside_clear, bool& strip_clear) const;
  // A round's tets that failed the range test, by the low end of their extent along
  // the sort axis: queried in that order, they read the file from one end to the
  // other (in the kernel's order they jumped all over the window's label range, and
  // and again). Each keeps the ball and extent check_tet computed: on a terrain
  // nearly every tet fails the range test, most of them flat, and computing their
  // circumspheres again (exactly, for the flattest) was a tenth of the run.
  struct QueuedTet {
    double lo, hi;  // the extent along the sort axis (query_extent)
    TetId tet;
    bool bounded, outside_clear, strip_clear;  // query_extent's result and flags
    ConflictBall ball;
    bool operator<(const QueuedTet& o) const { return lo < o.lo || (lo == o.lo && tet < o.tet); }
    bool operator==(const QueuedTet& o) const { return tet == o.tet; }
  };
  std::vector<QueuedTet> queued_;
  // The same for an infinite tet: its facet is a facet of the global hull when no
  // missing point conflicts with it (lies beyond its plane, or on it inside its
  // circumcircle under the perturbation).
  bool check_hull_facet(TetId t, std::vector<std::uint64_t>& repairs);
  // The tet's key in proved_empty_: its sorted vertex ids, 128 bits.
  std::pair<std::uint64_t, std::uint64_t> tet_key(TetId t) const;
  // Exact emptiness query of a star tet's conflict region against the missing points
  // whose axis coordinate lies in [lo, hi]: those outside the window's label range
  // (unless `outside_clear`) and those inside it but outside the strip's window
  // (unless `strip_clear`), among the index boxes may_meet(lo, hi) lets through.
  // conflict(label, p) is the point's score when it conflicts (lower: a better
  // repair), NaN otherwise. Returns the best-scored conflicting label of the first
  // few found, or kNone.
  template <class MayMeet, class Conflict>
  std::uint64_t best_missing_conflict(MayMeet&& may_meet, Conflict&& conflict, double lo, double hi,
                                      bool outside_clear, bool strip_clear);
  // The queries read points of the mapped sorted file all over it, and mapped pages
  // count in the resident set until they are handed back: every read of the file
  // outside the sequential window load goes through the view's MappedRegions, which
  // keeps the regions it maps within their share of the budget, or reads the points
  // without mapping them when they are few and far between (points in memory: read
  // directly).
  // (scratch: room for one record; the point is decoded into `xyz`.)
  const double* query_point(std::uint64_t label, QueryScratch& scratch) const {
    if (!view_.query_regions) {
      view_.points.xyz(label, scratch.xyz);
    } else {
      view_.query_regions->read(view_.points.record(label), scratch.record, view_.points.record_bytes());
      view_.points.decode(scratch.record, scratch.xyz);
    }
    return scratch.xyz;
  }
  bool in_strip_window(const double* xyz) const {
    return strip_.axis < 0 || (xyz[strip_.axis] >= strip_.window_lo && xyz[strip_.axis] <= strip_.window_hi);
  }
  // Whether the point (label, xyz) is in the window proper: its label range, and the
  // strip's window inside it.
  bool in_window(std::uint64_t label, const double* xyz) const {
    return label >= plan_->window_begin && label < plan_->window_end && in_strip_window(xyz);
  }

  static constexpr std::uint64_t kNone = std::numeric_limits<std::uint64_t>::max();
  double extent_[3];
  // Along the sort axis, the missing points of the zone being triangulated have
  // coordinates <= clear_lo_ (left of the window's label range) or >= clear_hi_
  // (right of it); infinite when there are none on that side.
  double clear_lo_ = 0, clear_hi_ = 0;

  const SortedView& view_;
  OutputPool* const pool_;
  const SegmentPlan* plan_ = nullptr;  // of the zone being triangulated
  ZoneStrip strip_;
  core::Delaunay dt_;
  std::vector<double> xyz_;
  std::vector<std::uint64_t> labels_;
  std::vector<std::size_t> hull_extra_;  // load_window's scratch
  std::vector<std::uint64_t> extra_;  // labels outside the window range held anyway (hull, repairs), sorted
  // Zone index of local vertex v (its label minus zone_begin), or -1 outside the zone
  // (outside the segment's labels, or in another worker's strip). One 4-byte load:
  // zone_of_ is filled once in run(), so the rounds' hot loops read no labels or
  // coordinates.
  std::int64_t zone_index(VertexId v) const {
    const std::uint32_t z = zone_of_[v];
    return z == kNoZone ? -1 : std::int64_t(z);
  }
  static constexpr std::uint32_t kNoZone = 0xFFFFFFFFu;
  std::vector<std::uint32_t> zone_of_;  // by local vertex: zone index or kNoZone
  // Per zone vertex (by zone index): kPending until it is final and its tets
  // are emitted, then kDone.
  std::vector<std::uint8_t> zone_state_;
  std::vector<VertexId> zone_vertex_;  // by zone index: the local vertex (kNoVertex: another strip's)
  std::vector<VertexId> pending_;      // the zone vertices still pending after a round
  std::vector<TetId> star_;        // scratch for a pending vertex's star
  // The tets proved empty, by their sorted vertex ids packed in 128 bits: an
  // open-addressing table (linear probing, at most half full): one cache line per
  // lookup and no allocation per insert, where a node-based std::unordered_set chased a
  // bucket and then a node (its bucket load alone was 8% of check_tet's samples).
  class TetSet {
   public:
    bool contains(std::uint64_t a, std::uint64_t b) const {
      if (slots_.empty()) return false;
      for (std::size_t i = hash(a, b) & mask_;; i = (i + 1) & mask_) {
        if (slots_[i].a == a && slots_[i].b == b) return true;
        if (slots_[i].a == kEmpty) return false;
      }
    }
    void insert(std::uint64_t a, std::uint64_t b) {
      if (2 * (size_ + 1) > slots_.size()) grow();
      for (std::size_t i = hash(a, b) & mask_;; i = (i + 1) & mask_) {
        if (slots_[i].a == a && slots_[i].b == b) return;
        if (slots_[i].a == kEmpty) {
          slots_[i] = {a, b};
          ++size_;
          return;
        }
      }
    }
    void clear() {
      std::fill(slots_.begin(), slots_.end(), Slot{});
      size_ = 0;
    }

   private:
    // No key has a == kEmpty: its low half is a vertex id below kNoVertex.
    static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
    struct Slot {
      std::uint64_t a = kEmpty, b = 0;
    };
    static std::size_t hash(std::uint64_t a, std::uint64_t b) {
      std::uint64_t h = (a ^ (b * 0x9E3779B97F4A7C15ULL)) * 0xBF58476D1CE4E5B9ULL;
      return std::size_t(h ^ (h >> 29));
    }
    void grow() {
      std::vector<Slot> old(std::max<std::size_t>(1024, 2 * slots_.size()));
      old.swap(slots_);
      mask_ = slots_.size() - 1;
      size_ = 0;
      for (const Slot& s : old)
        if (s.a != kEmpty) insert(s.a, s.b);
    }
    std::vector<Slot> slots_;
    std::size_t mask_ = 0, size_ = 0;
  };
  TetSet proved_empty_;
  static constexpr std::uint8_t kDone = 0, kPending = 1, kBlocked = 2;
  SegmentStats stats_;
  // One round's work, for the debug log (`--log-level debug`, scripts/plot-rounds): on
  // a terrain the rounds after the first, the window's ragged edge, cost more than the
  // first. queries: those run in the round (the queued tets not proved before, and the
  // hull facets', which run with the range tests and count in their seconds);
  // conflicts: queued tets a missing point was found in.
  struct RoundWork {
    std::uint64_t checked = 0, queued = 0, queries = 0, conflicts = 0;
    double seconds_range = 0, seconds_queries = 0;
  };
  RoundWork round_;
};

void SegmentWorker::load_window(bool with_hull) {
  const std::uint64_t w0 = plan_->window_begin, w1 = plan_->window_end;
  // extra_: labels held although outside the window proper (the label range, and the
  // strip's window inside it): the repair points, and in a flat window the hull's
  // vertices. The hull's coordinates come from the view, not the file: a shell's
  // hull has points all over the file, and reading them mapped every page of it.
  extra_.clear();
  std::vector<std::size_t>& hull_extra = hull_extra_;  // indices into view_.hull_points
  hull_extra.clear();
  for (std::size_t i = 0; with_hull && i < view_.hull_points.size(); ++i) {
    const SortedPoint& h = view_.hull_points[i];
    if (!in_window(h.original, h.xyz)) extra_.push_back(h.original), hull_extra.push_back(i);
  }
  xyz_.clear();
  labels_.clear();
  // A strip reads its segment's whole window range to pick its points: the pages of
  // that range are handed back as the copy goes (two threads loading 50 MiB windows at
  // once took the mapped pages past their share of the budget). One loop per record
  // type: each point is converted to doubles once, here.
  view_.points.visit([&](const auto* records) {
    ReleaseBehind release(view_.points, w0, view_.query_regions != nullptr);
    for (std::uint64_t label = w0; label < w1; ++label) {
      double p[3];
      records[label].xyz(p);
      if (in_strip_window(p)) {
        xyz_.insert(xyz_.end(), p, p + 3);
        labels_.push_back(label);
      }
      release.reached(label);
    }
  });
  for (std::size_t i : hull_extra) {
    xyz_.insert(xyz_.end(), view_.hull_points[i].xyz, view_.hull_points[i].xyz + 3);
    labels_.push_back(view_.hull_points[i].original);
  }
  const std::size_t total = labels_.size();
  // Local ids in Hilbert order: the kernel touches coordinates by vertex id, and a
  // spatially coherent numbering keeps those accesses in cache (the labels, not the
  // local ids, carry the order of the sorted file).
  const std::vector<std::uint32_t> order = core::hilbert_order(xyz_.data(), total);
  std::vector<double> xyz(3 * total);
  std::vector<std::uint64_t> labels(total);
  for (std::size_t i = 0; i < total; ++i) {
    std::copy_n(&xyz_[3 * std::size_t(order[i])], 3, &xyz[3 * i]);
    labels[i] = labels_[order[i]];
  }
  // The arrays in Hilbert order are kept (with their capacity, for the next zone);
  // the unordered ones go (not worth holding while the kernel builds).
  xyz_.swap(xyz);
  labels_.swap(labels);
  stats_.window_points = total;
}

template <class MayMeet, class Conflict>
std::uint64_t SegmentWorker::best_missing_conflict(MayMeet&& may_meet, Conflict&& conflict, double lo, double hi,
                                                   bool outside_clear, bool strip_clear) {
  ++stats_.queries;
  BestConflict best;
  QueryScratch scratch;
  auto in_window_already = [&](std::uint64_t label) { return std::binary_search(extra_.begin(), extra_.end(), label); };
  auto offer = [&](std::uint64_t label, const double* xyz) {
    const double score = conflict(label, xyz);
    if (!std::isnan(score)) best.offer(label, score);
  };
  auto visit = [&](std::uint64_t label) {
    if (!in_window_already(label)) offer(label, query_point(label, scratch));
  };
  // Missing points with an axis coordinate in [lo, hi]: two label ranges, one on
  // each side of the window, searched through the spatial index; and, for a strip,
  // the points of the window's range outside the strip's window. The label range is
  // taken from the key samples alone: up to a stride wider on each side, whose
  // points the ball test drops, and no probes of the file (the exact searches were
  // 40% of the page faults of uniform 10^7 at 256M, and their pages were nobody's
  // share of the budget).
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
      const double* xyz = query_point(label, scratch);
      if (!in_strip_window(xyz) && !in_window_already(label)) offer(label, xyz);
    };
    // The strip window's own points are not missing: whole index nodes inside it are
    // skipped, the rest filtered point by point.
    search(std::max(first, plan_->window_begin), std::min(last, plan_->window_end), visit_outside_strip,
           ExcludedSlab{strip_.axis, strip_.window_lo, strip_.window_hi});
  }
  return best.label;
}

std::pair<std::uint64_t, std::uint64_t> SegmentWorker::tet_key(TetId t) const {
  std::array<VertexId, 4> v;
  for (int i = 0; i < 4; ++i) v[i] = dt_.vertex(t, i);
  std::sort(v.begin(), v.end());
  return {std::uint64_t(v[1]) << 32 | v[0], std::uint64_t(v[3]) << 32 | v[2]};
}

bool SegmentWorker::query_extent(TetId t, ConflictBall& ball, double& lo, double& hi, bool& outside_clear,
                                 bool& strip_clear) const {
  ball = conflict_ball(dt_, t);
  lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
  outside_clear = false, strip_clear = strip_.axis < 0;
  if (!ball.valid) return false;
  clipped_extent(ball, view_, view_.axis, lo, hi);
  if (lo > hi) return true;
  // Missing points on the left have axis coordinates <= key(window_begin - 1), on
  // the right >= key(window_end).
  outside_clear = lo > clear_lo_ && hi < clear_hi_;
  if (!strip_clear) {
    // Missing points of the window's range lie outside [window_lo, window_hi]
    // along the strip's axis.
    double lo2, hi2;
    clipped_extent(ball, view_, strip_.axis, lo2, hi2);
    strip_clear = lo2 > hi2 || (lo2 >= strip_.window_lo && hi2 <= strip_.window_hi);
  }
  return true;
}

bool SegmentWorker::check_tet(TetId t, std::vector<std::uint64_t>& repairs) {
  ++round_.checked;
  if (dt_.is_infinite(t)) return check_hull_facet(t, repairs);
  QueuedTet q;
  q.tet = t;
  q.bounded = query_extent(t, q.ball, q.lo, q.hi, q.outside_clear, q.strip_clear);
  if (q.bounded && (q.lo > q.hi || (q.outside_clear && q.strip_clear))) return true;
  ++stats_.range_failures;
  if (!q.bounded) {
    // No usable bound: the query examines every missing point exactly.
    q.ball.radius = std::numeric_limits<double>::infinity();
    q.ball.center[0] = q.ball.center[1] = q.ball.center[2] = 0;
  }
  queued_.push_back(q);
  return true;
}

bool SegmentWorker::query_tet(const QueuedTet& q, std::vector<std::uint64_t>& repairs) {
  const TetId t = q.tet;
  // A tet proved empty stays empty for the rest of the segment: later repairs insert
  // only points that were missing, and none of those is in its ball. (In the first
  // round the table is empty and each queued tet unique: no lookup, a cache miss each
  // on a table of millions of tets.)
  const auto [key_a, key_b] = tet_key(t);
  if (stats_.rounds > 1 && proved_empty_.contains(key_a, key_b)) return true;
  const ConflictBall& query_ball = q.ball;
  const double lo = q.lo, hi = q.hi;
  const bool outside_clear = q.outside_clear, strip_clear = q.strip_clear;
  VertexId v[4];
  for (int i = 0; i < 4; ++i) v[i] = dt_.vertex(t, i);
  const double r2 = query_ball.radius * query_ball.radius;
  // The deepest conflicting point: the one nearest the enclosing ball's centre.
  auto conflict = [&](std::uint64_t label, const double* p) {
    double d2 = 0;
    for (int k = 0; k < 3; ++k) d2 += (p[k] - query_ball.center[k]) * (p[k] - query_ball.center[k]);
    if (d2 > r2 + 0x1p-1060) return std::numeric_limits<double>::quiet_NaN();  // outside the enclosing ball (slack: as in clipped_extent)
    ++stats_.query_points;
    const bool conflicts = core::insphere_sos(dt_.point(v[0]), dt_.point(v[1]), dt_.point(v[2]), dt_.point(v[3]), p,
                                              dt_.label(v[0]), dt_.label(v[1]), dt_.label(v[2]), dt_.label(v[3]),
                                              label) > 0;
    // The score ranks points within this one query, where r2 is fixed: d2 alone (never
    // NaN; r2 - d2 was inf - inf once the squares overflowed, and dropped the point).
    return conflicts ? d2 : std::numeric_limits<double>::quiet_NaN();
  };
  auto may_meet = [&](const double* box_lo, const double* box_hi) {
    return PointIndex::box_meets_ball(box_lo, box_hi, query_ball.center, query_ball.radius);
  };
  const std::uint64_t deepest = best_missing_conflict(may_meet, conflict, lo, hi, outside_clear, strip_clear);
  if (deepest == kNone) {
    proved_empty_.insert(key_a, key_b);
    return true;
  }
  repairs.push_back(deepest);
  return false;
}

// An infinite tet of the window is a hull facet (a, b, c) of the window's points. It
// is one of the global hull when no missing point conflicts with it; otherwise the
// missing points beyond it are what the window lacks there (the global hull's
// vertices, or simply the points past a window's edge), and the one nearest the
// facet is inserted. (Windows used to hold every global hull vertex instead: an
// ellipsoid shell's 57,538 in each of 24 windows were 14% redundant insertions.)
bool SegmentWorker::check_hull_facet(TetId t, std::vector<std::uint64_t>& repairs) {
  int inf = 0;
  while (dt_.vertex(t, inf) != core::kInfiniteVertex) ++inf;
  VertexId f[3];
  for (int m = 0; m < 3; ++m) f[m] = dt_.vertex(t, core::kFacetVertex[inf][m]);
  const double *a = dt_.point(f[0]), *b = dt_.point(f[1]), *c = dt_.point(f[2]);
  const FacetPlane plane(a, b, c, extent_);
  // Range test: the closed half-space beyond the facet misses the parts of the
  // bounding box where missing points can lie (left and right of the window's label
  // range along the axis; outside the strip's window inside it).
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
  const bool strip_clear = strip_.axis < 0 || (!reaches(strip_.axis, strip_.window_lo, -1, 0) &&
                                               !reaches(-1, 0, strip_.axis, strip_.window_hi));
  if (outside_clear && strip_clear) return true;
  ++stats_.range_failures;
  const auto [key_a, key_b] = tet_key(t);
  if (proved_empty_.contains(key_a, key_b)) return true;
  // Only the global hull's boundary points need to be searched. If abc is not a
  // global hull facet, a boundary point lies beyond its plane or conflicts on it: the
  // hull of all points is the hull of the boundary points, and a window vertex not on
  // the boundary is strictly inside it, so a plane through it has boundary points on
  // both sides. If abc is one, every point is on or below its plane, and those on it
  // are boundary points. The window's own points never conflict with its hull facet.
  ++stats_.queries;
  const std::uint64_t la = dt_.label(f[0]), lb = dt_.label(f[1]), lc = dt_.label(f[2]);
  double centroid[3];
  for (int k = 0; k < 3; ++k) centroid[k] = (a[k] + b[k] + c[k]) / 3;
  BestConflict nearest;
  auto visit = [&](std::uint64_t i) {
    const SortedPoint& h = view_.hull_points[i];
    const std::uint64_t label = h.original;
    if (in_window(label, h.xyz) || std::binary_search(extra_.begin(), extra_.end(), label)) return;
    ++stats_.query_points;
    if (core::infinite_conflict_sos(a, b, c, h.xyz, la, lb, lc, label) <= 0) return;
    double d2 = 0;
    for (int k = 0; k < 3; ++k) d2 += (h.xyz[k] - centroid[k]) * (h.xyz[k] - centroid[k]);
    nearest.offer(label, d2);
  };
  view_.hull_index->for_each_candidate_where(
      [&](const double* box_lo, const double* box_hi) { return plane.box_may_reach(box_lo, box_hi); }, 0,
      view_.hull_points.size(), visit, [&] { return nearest.enough(); });
  if (nearest.found == 0) {
    proved_empty_.insert(key_a, key_b);
    return true;
  }
  repairs.push_back(nearest.label);
  return false;
}

// A zone vertex is final when no tet incident to it is unsafe. The first round, with
// every zone vertex pending, scans the tet array in memory order (a tet belongs to
// the star of each of its vertices, so one pass marks the blocked vertices); later
// rounds, with few vertices left, walk the stars of those alone. A final vertex's
// star never changes again (no later repair point lies in any of its tets' balls),
// so its tets can be emitted after the last round.
std::size_t SegmentWorker::check_round(std::vector<std::uint64_t>& repairs) {
  round_ = RoundWork{};
  const std::uint64_t queries_before = stats_.queries;
  auto t0 = Clock::now();
  // The states of tet t's vertices in this zone (other vertices have none).
  auto zone_states = [&](TetId t, auto&& visit) {
    for (int i = 0; i < 4; ++i) {
      const VertexId v = dt_.vertex(t, i);
      if (v == core::kInfiniteVertex) continue;
      const std::int64_t z = zone_index(v);
      if (z >= 0) visit(zone_state_[std::size_t(z)]);
    }
  };
  auto block_pending = [&](TetId t) {
    zone_states(t, [](std::uint8_t& state) {
      if (state != kDone) state = kBlocked;
    });
  };
  if (stats_.rounds == 1) {
    const std::size_t slots = dt_.num_tet_slots();
    for (std::size_t t = 0; t < slots; ++t) {
      if (!dt_.is_alive(TetId(t))) continue;
      bool touches_zone = false;
      for (int i = 0; i < 4; ++i) {
        const VertexId v = dt_.vertex(TetId(t), i);
        touches_zone |= v != core::kInfiniteVertex && zone_of_[v] != kNoZone;
      }
      if (touches_zone && !check_tet(TetId(t), repairs)) block_pending(TetId(t));
    }
  } else {
    for (VertexId v : pending_) {
      star_.clear();
      dt_.star(v, star_);
      for (TetId t : star_)
        if (!check_tet(t, repairs)) block_pending(t);
    }
  }
  round_.seconds_range = since(t0);
  t0 = Clock::now();
  // The queries, along the sort axis (a tet of several pending stars once).
  std::sort(queued_.begin(), queued_.end());
  queued_.erase(std::unique(queued_.begin(), queued_.end()), queued_.end());
  round_.queued = queued_.size();
  // In the first two rounds, a tet whose zone vertices a conflict has already blocked
  // in this round waits: its vertices stay pending, so the next round checks it again
  // if the repairs leave it (near the window's ragged edge they often do not). No
  // vertex becomes final with a tet of its star unchecked. Terrain 10^6 at 128M: 7.8%
  // fewer queries, checks 14.4 -> 13.4 s summed; 10^7 at 1G: 76.7 -> 72.1 s. Not in
  // later rounds: there a zone's last few conflicts then repaired one a round (943
  // rounds, the range tests of its stars 3.1 -> 5.7 s summed).
  constexpr std::uint64_t kDeferRounds = 2;
  auto blocks_nothing_new = [&](TetId t) {
    bool pending = false;
    zone_states(t, [&](std::uint8_t state) { pending |= state == kPending; });
    return !pending;
  };
  for (const QueuedTet& q : queued_) {
    if (stats_.rounds <= kDeferRounds && blocks_nothing_new(q.tet)) continue;
    if (!query_tet(q, repairs)) block_pending(q.tet), ++round_.conflicts;
  }
  round_.seconds_queries = since(t0);
  round_.queries = stats_.queries - queries_before;
  queued_.clear();
  pending_.clear();
  for (std::size_t z = 0; z < zone_state_.size(); ++z) {
    std::uint8_t& state = zone_state_[z];
    if (state == kPending) state = kDone;
    else if (state == kBlocked) state = kPending, pending_.push_back(zone_vertex_[z]);
  }
  return pending_.size();
}

// Minimum vertex filter, once every zone vertex is final: each finite tet whose
// smallest label is a zone vertex is emitted, grouped by that label in increasing
// order. The stream of a whole job is then ordered by minimum label whatever the
// segment plan, which lets the writer cut identical frames for any budget split or
// thread count.
//
// The grouping is a two-level counting sort. Placing each tet straight at its
// label's position would scatter writes over the whole output (100+ MiB, a cache
// miss each: the tets come in the kernel's spatial order, the labels follow the sort
// axis); instead the tets go to at most 2048 buckets of consecutive zone indices (one
// write stream per bucket, all of them cache-resident), and each bucket, small enough
// for the cache, is then ordered in place by its own counting sort.
void SegmentWorker::emit(ZoneTets& out) {
  const std::size_t slots = dt_.num_tet_slots();
  const std::size_t zone_size = zone_state_.size();
  const int shift = std::max(0, int(std::bit_width(zone_size)) - 11);
  const std::size_t buckets = (zone_size >> shift) + 1;
  // Pass 1: each tet's owner (the zone index of its smallest label, or kNoZone),
  // counted per bucket.
  std::vector<std::uint32_t> owner(slots, kNoZone);
  std::vector<std::size_t> bucket_start(buckets + 1, 0);
  for (std::size_t t = 0; t < slots; ++t) {
    if (!dt_.is_alive(TetId(t)) || dt_.is_infinite(TetId(t))) continue;
    VertexId m = dt_.vertex(TetId(t), 0);
    std::uint64_t lm = labels_[m];
    for (int i = 1; i < 4; ++i) {
      const VertexId v = dt_.vertex(TetId(t), i);
      if (labels_[v] < lm) lm = labels_[v], m = v;
    }
    const std::uint32_t z = zone_of_[m];
    owner[t] = z;
    if (z != kNoZone) ++bucket_start[(z >> shift) + 1];
  }
  for (std::size_t b = 1; b <= buckets; ++b) bucket_start[b] += bucket_start[b - 1];
  const std::size_t total = bucket_start[buckets];
  stats_.tets += total;
  if (pool_) out = pool_->take();
  std::vector<VertexId>& tets = out.tets;
  tets.reserve(4 * total);
  core::advise_huge_pages(tets.data(), tets.capacity() * sizeof(VertexId));
  tets.resize(4 * total);
  // Pass 2: into the buckets, in the kernel's order.
  std::vector<std::size_t> fill(bucket_start.begin(), bucket_start.end() - 1);
  for (std::size_t t = 0; t < slots; ++t) {
    const std::uint32_t z = owner[t];
    if (z == kNoZone) continue;
    VertexId* q = &tets[4 * fill[z >> shift]++];
    for (int i = 0; i < 4; ++i) q[i] = dt_.vertex(TetId(t), i);
  }
  std::vector<std::uint32_t>().swap(owner);
  // Pass 3: each bucket by zone index (its minimum label minus zone_begin).
  std::vector<VertexId> scratch;
  std::vector<std::size_t> count(std::size_t(1) << shift);
  const std::uint64_t low_mask = (std::uint64_t(1) << shift) - 1;
  for (std::size_t b = 0; shift > 0 && b < buckets; ++b) {  // shift 0: one zone index a bucket
    const std::size_t first = bucket_start[b], n = bucket_start[b + 1] - first;
    if (n < 2) continue;
    scratch.assign(tets.begin() + std::ptrdiff_t(4 * first), tets.begin() + std::ptrdiff_t(4 * (first + n)));
    std::fill(count.begin(), count.end(), 0);
    auto key = [&](std::size_t i) {
      const VertexId* q = &scratch[4 * i];
      const std::uint64_t m = std::min(std::min(labels_[q[0]], labels_[q[1]]), std::min(labels_[q[2]], labels_[q[3]]));
      return (m - plan_->zone_begin) & low_mask;
    };
    for (std::size_t i = 0; i < n; ++i) ++count[key(i)];
    std::size_t at = first;
    for (std::size_t& c : count) {
      const std::size_t k = c;
      c = at;
      at += k;
    }
    for (std::size_t i = 0; i < n; ++i) std::copy_n(&scratch[4 * i], 4, &tets[4 * count[key(i)]++]);
  }
  // The local ids' labels go with the tets (the worker's table is refilled by the
  // next zone's load_window anyway).
  out.labels.swap(labels_);
}

SegmentStats SegmentWorker::run(const SegmentPlan& plan, const ZoneStrip& strip, ZoneTets& out) {
  plan_ = &plan;
  strip_ = strip;
  clear_lo_ = plan.window_begin == 0 ? -std::numeric_limits<double>::infinity() : view_.key(plan.window_begin - 1);
  clear_hi_ = plan.window_end == view_.count ? std::numeric_limits<double>::infinity() : view_.key(plan.window_end);
  stats_ = SegmentStats{};
  pending_.clear();
  proved_empty_.clear();
  auto t0 = Clock::now();
  // A window is triangulated on its own points; its hull facets are checked like its
  // other tets. A window too flat for a triangulation (a slab of a planar region)
  // takes the global hull's vertices, which make it solid.
  load_window(/*with_hull=*/false);
  if (dt_.build(xyz_.data(), labels_.data(), labels_.size()) != core::BuildStatus::kOk) {
    load_window(/*with_hull=*/true);
    if (dt_.build(xyz_.data(), labels_.data(), labels_.size()) != core::BuildStatus::kOk)
      throw InputError("the input has fewer than 4 affinely independent distinct points");
  }
  stats_.seconds_build = since(t0);

  t0 = Clock::now();
  // The zone vertices: the window's points with a label in the segment's zone and,
  // with strips, a coordinate in this strip. Every other label of the zone is
  // another strip's (kDone here from the start).
  zone_state_.assign(plan_->zone_end - plan_->zone_begin, kDone);
  zone_vertex_.assign(plan_->zone_end - plan_->zone_begin, core::kNoVertex);
  zone_of_.assign(labels_.size(), kNoZone);
  for (VertexId v = 0; v < labels_.size(); ++v) {
    const std::uint64_t l = labels_[v];
    const bool in_strip =
        strip_.axis < 0 || (xyz_[3 * std::size_t(v) + std::size_t(strip_.axis)] >= strip_.lo &&
                            xyz_[3 * std::size_t(v) + std::size_t(strip_.axis)] < strip_.hi);
    const bool in_range = l >= plan_->zone_begin && l < plan_->zone_end;
    if (!in_range || !in_strip) {
      if (std::binary_search(extra_.begin(), extra_.end(), l)) ++stats_.hull_points;
      else if (!in_strip) ++stats_.zone_buffer_points;
      else ++stats_.segment_buffer_points;
      continue;
    }
    const std::uint64_t z = l - plan_->zone_begin;
    zone_of_[v] = std::uint32_t(z);
    zone_vertex_[z] = v;
    zone_state_[z] = kPending;
  }
  std::vector<std::uint64_t> repairs;
  // (round: its work as check_round counted it; inserted, seconds: the repairs after it.
  // A zone that is its whole segment spans (-inf, inf) across.)
  const double inf = std::numeric_limits<double>::infinity();
  const double strip_lo = strip_.axis >= 0 ? strip_.lo : -inf, strip_hi = strip_.axis >= 0 ? strip_.hi : inf;
  auto log_round = [&](std::size_t inserted, double seconds) {
    spdlog::debug("zone [{}, {}) strip [{:g}, {:g}) round {}: {} tets checked ({:.3f} s), {} queued, {} queries "
                  "({} found a conflict, {:.3f} s), {} repair points inserted ({:.3f} s)",
                  plan_->zone_begin, plan_->zone_end, strip_lo, strip_hi, stats_.rounds, round_.checked,
                  round_.seconds_range, round_.queued, round_.queries, round_.conflicts, round_.seconds_queries,
                  inserted, seconds);
  };
  for (;;) {
    ++stats_.rounds;
    repairs.clear();
    if (check_round(repairs) == 0) {
      log_round(0, 0);
      break;
    }
    const auto t_insert = Clock::now();
    std::sort(repairs.begin(), repairs.end());
    repairs.erase(std::unique(repairs.begin(), repairs.end()), repairs.end());
    // Append the repair points to the window and insert them.
    const std::size_t old_n = labels_.size();
    QueryScratch scratch;
    for (std::uint64_t label : repairs) {
      const double* p = query_point(label, scratch);
      xyz_.insert(xyz_.end(), p, p + 3);
      labels_.push_back(label);
      extra_.insert(std::upper_bound(extra_.begin(), extra_.end(), label), label);
    }
    zone_of_.resize(labels_.size(), kNoZone);  // repair points are never zone points
    dt_.set_points(xyz_.data(), labels_.data(), labels_.size());
    dt_.insert_range(VertexId(old_n), VertexId(labels_.size()));
    stats_.repair_points += repairs.size();
    log_round(repairs.size(), since(t_insert));
  }
  emit(out);
  stats_.seconds_check = since(t0);
  stats_.kernel_bytes = dt_.memory_bytes();
  return stats_;
}


void SortedView::sample_keys(bool release_file_pages) {
  key_samples.clear();
  key_samples.reserve(std::size_t(count / kKeyStride + 1));
  ReleaseBehind release(points, 0, release_file_pages);
  for (std::uint64_t label = 0; label < count; label += kKeyStride) {
    key_samples.push_back(key(label));
    release.reached(label);
  }
}

namespace {
// The labels in [0, count) between which the first one for which `after(key)` holds
// lies (keys are sorted, and `after` is monotone along them), from the samples alone:
// [lo, hi], at most one stride apart.
template <class After>
std::pair<std::uint64_t, std::uint64_t> sample_bracket(const SortedView& view, After after) {
  if (view.key_samples.empty()) return {0, view.count};
  // Sample s is label s * kKeyStride: the answer lies after the last sample that is
  // not `after`, and at or before the first that is.
  const auto s = std::size_t(std::partition_point(view.key_samples.begin(), view.key_samples.end(),
                                                  [&](double k) { return !after(k); }) -
                             view.key_samples.begin());
  return {s == 0 ? 0 : (s - 1) * SortedView::kKeyStride + 1, std::min(view.count, s * SortedView::kKeyStride)};
}

// The first label for which `after(key)` holds: the samples' bracket, then a binary
// search of the file within it.
template <class After>
std::uint64_t partition_point(const SortedView& view, After after) {
  auto [lo, hi] = sample_bracket(view, after);
  while (lo < hi) {
    const std::uint64_t mid = lo + (hi - lo) / 2;
    if (after(view.key(mid))) hi = mid;
    else lo = mid + 1;
  }
  return lo;
}
auto at_or_after(double x) {
  return [x](double k) { return k >= x; };
}
auto after(double x) {
  return [x](double k) { return k > x; };
}
}  // namespace

std::uint64_t SortedView::lower_bound(double x) const { return partition_point(*this, at_or_after(x)); }
std::uint64_t SortedView::upper_bound(double x) const { return partition_point(*this, after(x)); }
KeyRange SortedView::key_range(std::uint64_t first, std::uint64_t last) const {
  if (key_samples.empty()) return {key(first), key(last - 1)};
  // Sample i is label i * kKeyStride, and keys grow with labels: the sample at or
  // before `first`, and the one at or after `last` - 1 (none: no bound).
  const std::size_t after = std::size_t((last - 1 + kKeyStride - 1) / kKeyStride);
  return {key_samples[std::size_t(first / kKeyStride)],
          after < key_samples.size() ? key_samples[after] : std::numeric_limits<double>::infinity()};
}

std::uint64_t SortedView::lower_bound_below(double x) const { return sample_bracket(*this, at_or_after(x)).first; }
std::uint64_t SortedView::upper_bound_above(double x) const { return sample_bracket(*this, after(x)).second; }

int strip_axis(const SortedView& view) {
  const int a1 = (view.axis + 1) % 3, a2 = (view.axis + 2) % 3;
  return view.bbox_max[a1] - view.bbox_min[a1] >= view.bbox_max[a2] - view.bbox_min[a2] ? a1 : a2;
}

std::vector<SegmentPlan> plan_segments(const SortedView& view, std::uint64_t zone_points, double buffer_width,
                                       std::uint64_t first_label, std::uint64_t end_label) {
  std::vector<SegmentPlan> plans;
  end_label = std::min(end_label, view.count);
  if (first_label >= end_label) return plans;
  zone_points = std::max<std::uint64_t>(zone_points, 1);
  const std::uint64_t todo = end_label - first_label;
  const std::uint64_t segments = std::max<std::uint64_t>(1, (todo + zone_points - 1) / zone_points);
  for (std::uint64_t s = 0; s < segments; ++s) {
    SegmentPlan p;
    // Even split, so the last segment is not a sliver.
    p.zone_begin = first_label + todo * s / segments;
    p.zone_end = first_label + todo * (s + 1) / segments;
    if (p.zone_begin == p.zone_end) continue;
    p.window_begin = view.lower_bound(view.key(p.zone_begin) - buffer_width);
    p.window_end = view.upper_bound(view.key(p.zone_end - 1) + buffer_width);
    p.buffer_width = buffer_width;
    plans.push_back(p);
  }
  return plans;
}

namespace {

// Cuts `zones` strips along `axis` from the sorted sample of the segment's zone
// coordinates (split_into_zones).
void cut_strips(const std::vector<double>& coords, SegmentPlan& plan, int axis, int zones) {
  plan.zones.assign(1, ZoneStrip{});
  if (zones <= 1 || coords.empty()) return;
  // Each cut at the emptiest place near its quantile: of the sampled coordinates
  // within a tenth of a zone's share on either side, the one with the fewest others
  // within the buffer width of it. A strip's window holds the points within the
  // buffer width of its cuts, and a cut through a dense cluster put thousands there:
  // clustered 10^7 at 1G inserted 3.56 M zone buffer points (24% of insertions) and
  // its windows outgrew their share of the budget (1,123 MiB resident at 1G).
  // Zones stay within +-10% of an equal share (their outputs are planned by it).
  const std::size_t m = coords.size();
  const double w = plan.buffer_width;
  std::vector<double> cuts;  // increasing cut values
  for (int z = 1; z < zones; ++z) {
    const std::size_t at = m * std::size_t(z) / std::size_t(zones), slack = m / std::size_t(zones) / 10;
    const std::size_t first = at > slack ? at - slack : 0, last = std::min(m - 1, at + slack);
    std::size_t best = at, best_count = std::numeric_limits<std::size_t>::max();
    std::size_t lo = first, hi = first;  // [lo, hi): the samples within w of coords[i]
    for (std::size_t i = first; i <= last; ++i) {
      while (lo < i && coords[lo] < coords[i] - w) ++lo;
      while (lo > 0 && coords[lo - 1] >= coords[i] - w) --lo;
      hi = std::max(hi, i);
      while (hi < m && coords[hi] <= coords[i] + w) ++hi;
      // The cut value must differ from its neighbours' (strips need positive width):
      // the first of a run of equal coordinates stands for the run.
      if (i > first && coords[i] == coords[i - 1]) continue;
      if (hi - lo < best_count) best_count = hi - lo, best = i;
    }
    if (cuts.empty() || coords[best] > cuts.back()) cuts.push_back(coords[best]);
  }
  const double inf = std::numeric_limits<double>::infinity();
  plan.zones.assign(cuts.size() + 1, ZoneStrip{});
  for (std::size_t z = 0; z < plan.zones.size(); ++z) {
    ZoneStrip& st = plan.zones[z];
    st.axis = axis;
    st.lo = z == 0 ? -inf : cuts[z - 1];
    st.hi = z == cuts.size() ? inf : cuts[z];
    st.window_lo = st.lo - plan.buffer_width;
    st.window_hi = st.hi + plan.buffer_width;
  }
}

}  // namespace

void split_into_zones(const SortedView& view, SegmentPlan& plan, int zones) {
  const std::uint64_t zone_points = plan.zone_end - plan.zone_begin;
  zones = int(std::clamp<std::uint64_t>(std::uint64_t(std::max(zones, 1)), 1, std::max<std::uint64_t>(zone_points / 256, 1)));
  plan.zones.assign(1, ZoneStrip{});
  if (zones == 1) return;
  // Quantiles of a sample (at most ~64k points, every stride-th label): the zones
  // need about equal counts, not exact ones, and the sample keeps this pass cheap.
  const int axis = strip_axis(view);
  const std::uint64_t stride = std::max<std::uint64_t>(1, zone_points / 65536);
  std::vector<double> coords;
  coords.reserve(std::size_t(zone_points / stride + 1));
  for (std::uint64_t l = plan.zone_begin; l < plan.zone_end; l += stride) coords.push_back(view.points.coord(l, axis));
  std::sort(coords.begin(), coords.end());
  cut_strips(coords, plan, axis, zones);
}

ZoneTets OutputPool::take() {
  std::lock_guard lock(mutex_);
  if (spare_.empty()) return {};
  ZoneTets v = std::move(spare_.back());
  spare_.pop_back();
  return v;
}

void OutputPool::give(ZoneTets&& v) {
  v.tets.clear();
  v.labels.clear();
  std::lock_guard lock(mutex_);
  spare_.push_back(std::move(v));
}

ZoneTriangulator::ZoneTriangulator(const SortedView& view, OutputPool* pool)
    : worker_(std::make_unique<SegmentWorker>(view, pool)) {}
ZoneTriangulator::~ZoneTriangulator() = default;

SegmentStats ZoneTriangulator::run(const SegmentPlan& plan, const ZoneStrip& zone, ZoneTets& out) {
  return worker_->run(plan, zone, out);
}

}  // namespace tetstream::pipeline
