#include "pipeline/window/zone_triangulator.hpp"

#include "core/error.hpp"
#include "core/huge_pages.hpp"
#include "core/spatial_sort.hpp"
#include "pipeline/window/certificate.hpp"
#include "pipeline/window/shared_rim.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>

namespace tetstream::pipeline {

namespace {
using core::TetId;
using core::VertexId;
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
}  // namespace

// The state of one thread's zone triangulations. It lives across zones: the kernel
// and the buffers keep their capacity from one zone to the next, so a thread faults
// its memory in once.
class ZoneWorker {
 public:
  ZoneWorker(const SortedView& view, OutputPool* pool, SharedRim* shared)
      : view_(view), pool_(pool), shared_(shared), certificate_(view) {}

  SegmentStats run(const SegmentPlan& plan, const Zone& zone, ZoneTets& out);

 private:
  // The zone's window: its label range's points inside the strip's window; with
  // `with_hull`, also the global hull's vertices (only for a window too flat for a
  // triangulation of its own).
  void load_window(bool with_hull);
  // Adds to the window the vertices of the shared tets with a point of this zone.
  void seed_from_neighbours();
  // Whether the point with this label is one of the zone's: a label of the segment's
  // zone range and, with strips, a coordinate in this zone's strip.
  bool zone_point(std::uint64_t label, const double* xyz) const {
    return in_strip(xyz) && label >= plan_->label_begin && label < plan_->label_end;
  }
  bool in_strip(const double* xyz) const {
    return zone_.axis < 0 || (xyz[zone_.axis] >= zone_.lo && xyz[zone_.axis] < zone_.hi);
  }
  // One round: checks the rim tets not yet certified (collecting repair points) and
  // returns how many it left unproved (0: the rim holds, every zone vertex is final).
  std::size_t check_round(std::vector<std::uint64_t>& repairs);
  void emit(ZoneTets& out);
  // The finished zone's rim tets that a zone still running may hold (a vertex of a
  // later label or of another strip), for shared_.
  void publish_rim();
  // Whether a finished zone certified a tet with t's labels (shared_).
  bool certified_by_neighbour(TetId t) const;
  // Rim tet t's certificate: the range test, the wall, or a query (queued_; a hull
  // facet's runs at once). One left unproved goes to recheck_next_.
  enum class TetKind : std::uint8_t;
  void check_tet(TetId t, TetKind kind, std::vector<std::uint64_t>& repairs);
  // A round's finite tets that failed the range test, by the low end of their extent
  // along the sort axis: queried in that order, they read the file from one end to
  // the other. Each keeps the ball and extent of its range test: on a surface nearly
  // every tet fails the range test, most of them flat, and their circumspheres are
  // costly to compute again (exactly, for the flattest).
  struct QueuedTet {
    RangeTest range;
    TetId tet;
    bool operator<(const QueuedTet& o) const {
      return range.lo < o.range.lo || (range.lo == o.range.lo && tet < o.tet);
    }
    bool operator==(const QueuedTet& o) const { return tet == o.tet; }
  };
  bool query_tet(const QueuedTet& q, std::vector<std::uint64_t>& repairs);
  // Runs the queued tets' queries (along the sort axis) and empties the queue: at the
  // end of a round's range tests, and whenever the queue reaches queue_cap_.
  void run_queued_queries(std::vector<std::uint64_t>& repairs);
  // The first two rounds' waiting rule: a conflict blocks its tet's zone vertices for
  // the round (blocked_round_), and a queued tet whose zone vertices are all blocked
  // waits for the next round.
  void block_zone_vertices(TetId t);
  // Whether some zone vertex of t (with `every`: each one) was blocked in `round`.
  bool zone_vertex_blocked(TetId t, std::uint64_t round, bool every) const;
  // The rim and the wall (docs/certificate.md, Lemmas 5 and 6). A window vertex that
  // is not a zone vertex is *beyond* when its label is past the segment's (label_end
  // on) and it lies in the strip's window; every other one (an earlier label, another
  // strip's point, a held point outside the strip's window) is a *wall* vertex. The
  // zone's *rim* is the tets of DT(W) with a zone vertex and another vertex. Once a
  // round has certified every rim tet with a wall vertex and every hull facet of the
  // zone's stars (the wall holds), a rim tet without a wall vertex is Delaunay when its
  // clipped ball ends before the key of label_end (Lemma 5); once it has certified
  // every rim tet (the rim holds), a tet of zone vertices alone is Delaunay whatever
  // its ball (Lemma 6): a missing point in its ball would be in the ball of a rim tet.
  // kOutside: no zone vertex; kInterior: four zone vertices; otherwise a rim tet (a
  // hull facet with a zone vertex too): kWall when it has a wall vertex, else kBeyond.
  enum class TetKind : std::uint8_t { kOutside, kInterior, kBeyond, kWall };
  TetKind kind(TetId t) const {
    bool zone = false, other = false, wall = false;
    for (int i = 0; i < 4; ++i) {
      const VertexId v = dt_.vertex(t, i);
      const bool in_zone = v != core::kInfiniteVertex && zone_of_[v] != kNoZone;
      zone |= in_zone, other |= !in_zone;
      wall |= !in_zone && v != core::kInfiniteVertex && !beyond_[v];
    }
    if (!zone) return TetKind::kOutside;
    if (!other) return TetKind::kInterior;
    return wall ? TetKind::kWall : TetKind::kBeyond;
  }
  // Whether tet t's certificate is settled: a query or the range test proved it, or it
  // leaned on the wall in an earlier round whose wall held (proved_empty_'s marks).
  bool proved(TetId t) const {
    const std::uint8_t m = proved_empty_[t];
    if (m == kProved || m == kRanged || m == kShared) return true;
    return m >= kLeaned && std::uint64_t(m - kLeaned) < stats_.rounds - 1 && wall_held_[m - kLeaned];
  }
  // Classifies window vertices [first, end) beyond the zone or not (beyond_).
  void mark_beyond(VertexId first, VertexId end);
  bool check_hull_facet(TetId t, std::vector<std::uint64_t>& repairs);
  // Zone index of local vertex v (its label minus label_begin), or -1 outside the zone
  // (outside the segment's labels, or in another worker's strip). One 4-byte load:
  // zone_of_ is filled once in run(), so the rounds' hot loops read no labels or
  // coordinates.
  std::int64_t zone_index(VertexId v) const {
    const std::uint32_t z = zone_of_[v];
    return z == kNoZone ? -1 : std::int64_t(z);
  }

  static constexpr std::uint32_t kNoZone = 0xFFFFFFFFu;
  // proved_empty_'s marks: kProved by a query, kRanged by the range test (a tet checked
  // again computes no ball twice), kShared by a finished neighbour (shared_); kLeaned +
  // r: leaned on the wall in round r + 1 (past kLeanRounds rounds the tets are queried
  // instead).
  static constexpr std::uint64_t kLeanRounds = 250;
  static constexpr std::uint8_t kProved = 1, kRanged = 2, kShared = 3, kLeaned = 4;

  const SortedView& view_;
  OutputPool* const pool_;
  SharedRim* const shared_;  // the finished zones' rim tets (null: none shared)
  static constexpr std::size_t kPublishBatch = 2048;
  std::vector<SharedRim::Labels> publish_;  // publish_rim's scratch: one batch
  Certificate certificate_;
  const SegmentPlan* plan_ = nullptr;  // of the zone being triangulated
  Zone zone_;
  core::Delaunay dt_;
  std::vector<double> xyz_;
  std::vector<std::uint64_t> labels_;
  std::vector<std::size_t> hull_extra_;  // load_window's scratch
  std::vector<std::uint64_t> held_;      // labels outside the window range held anyway (hull, repairs, seeds), sorted
  std::vector<std::uint64_t> seeded_;    // of those, the finished neighbours' (load_window), sorted
  std::vector<QueuedTet> queued_;
  std::vector<std::uint32_t> zone_of_;        // by local vertex: zone index or kNoZone
  std::vector<std::uint32_t> blocked_round_;  // by zone index: the round a conflict blocked it in
  // The rim tets left unproved by the last round (checked again in this one: a slot
  // reused since holds another tet, checked if it is on the rim), and this round's.
  std::vector<TetId> recheck_, recheck_next_;
  std::vector<TetId> leaned_;  // this round's tets that leaned on the wall
  // Rim tets met in a round's repair stars whose zone vertices no conflict blocked in
  // the round before: checked once a round inserts no repair point (their stars have
  // settled: checked at once, most were destroyed by later repairs on a surface).
  std::vector<TetId> deferred_;
  // The last repair points this round's queries found (label, point), newest at
  // recent_next_ - 1 (mod kRecent): a queued tet in conflict with one of them is
  // removed when the round inserts it, and needs no query (conflicts_with_recent).
  static constexpr std::size_t kRecent = 8;
  struct RecentRepair {
    std::uint64_t label;
    double xyz[3];
  };
  std::array<RecentRepair, kRecent> recent_{};
  std::size_t recent_count_ = 0, recent_next_ = 0;
  bool conflicts_with_recent(const QueuedTet& q) const;
  VertexId repairs_from_ = 0;  // the local ids of the last round's repair points start here
  bool force_ = false;         // a round after one that left tets unproved without a repair: no waiting
  std::vector<TetId> star_;    // scratch for a repair point's star
  // By tet slot: how the tet was certified (kProved, kRanged, kLeaned + round; 0: not
  // yet). A certified tet stays in its slot for the rest of the zone: no missing point
  // is in its ball (or beyond its hull facet), and the repairs insert only missing points, so it is never in a
  // repair's cavity and its slot is never freed and reused. One byte a slot, where a
  // table keyed by the vertices took 32-64 bytes an entry and, on a surface (about 4
  // entries a window point on `gen --dist hills`), took a zone past its share of the
  // budget.
  std::vector<std::uint8_t> proved_empty_;
  std::vector<std::uint8_t> beyond_;     // by local vertex: 1 for a beyond vertex (see kind)
  double wall_key_ = 0;                  // the key of label_end (infinite for the last label)
  bool wall_broken_ = false;             // this round: a wall tet or hull facet not certified
  std::vector<std::uint8_t> wall_held_;  // by round - 1
  // The most entries queued_ holds, from the window's size (run()): on a surface nearly
  // every tet fails the range test (10-25 a point on `gen --dist hills`), and an
  // unbounded queue of 72-byte entries was, with the table above, what took hills
  // windows past their share.
  std::size_t queue_cap_ = 0;
  SegmentStats stats_;
  // One round's work, for the debug log (`--log-level debug`, scripts/plot-rounds).
  // queries: those run in the round (the queued tets not proved before, and the hull
  // facets', which run with the range tests and count in their seconds); conflicts:
  // queued tets a missing point was found in.
  struct RoundWork {
    std::uint64_t checked = 0, queued = 0, queries = 0, conflicts = 0, unproved = 0;
    double seconds_range = 0, seconds_queries = 0;
    bool wall_held = false;
  };
  RoundWork round_;
};

void ZoneWorker::load_window(bool with_hull) {
  const std::uint64_t w0 = plan_->window_begin, w1 = plan_->window_end;
  // held_: labels held although outside the window proper (the label range, and the
  // strip's window inside it): the repair points, and in a flat window the hull's
  // vertices. The hull's coordinates come from the view, not the file: a shell's
  // hull has points all over the file, and reading them mapped every page of it.
  held_.clear();
  std::vector<std::size_t>& hull_extra = hull_extra_;  // indices into view_.hull_points
  hull_extra.clear();
  for (std::size_t i = 0; with_hull && i < view_.hull_points.size(); ++i) {
    const SortedPoint& h = view_.hull_points[i];
    if (!certificate_.in_window(h.original, h.xyz)) held_.push_back(h.original), hull_extra.push_back(i);
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
      if (certificate_.in_strip_window(p)) {
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
  seed_from_neighbours();
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

// The finished zones' rim tets with a point of this zone: their vertices are the true
// neighbours of its points there (Lemma 7), which repairs would otherwise bring in one a
// query (on a surface, the far ends of the long edges across the zone's boundary). Held,
// as repair points are; those the window has already are left out.
void ZoneWorker::seed_from_neighbours() {
  seeded_.clear();
  if (!shared_) return;
  QueryScratch scratch;
  shared_->for_each_touching(plan_->label_begin, plan_->label_end, [&](const SharedRim::Labels& t) {
    const bool touches = std::any_of(t.begin(), t.end(), [&](std::uint64_t l) {
      return l >= plan_->label_begin && l < plan_->label_end && zone_point(l, certificate_.read_point(l, scratch));
    });
    if (touches) seeded_.insert(seeded_.end(), t.begin(), t.end());
  });
  std::sort(seeded_.begin(), seeded_.end());
  seeded_.erase(std::unique(seeded_.begin(), seeded_.end()), seeded_.end());
  std::size_t kept = 0;
  for (std::uint64_t label : seeded_) {
    const double* p = certificate_.read_point(label, scratch);
    if (certificate_.in_window(label, p) || std::binary_search(held_.begin(), held_.end(), label)) continue;
    xyz_.insert(xyz_.end(), p, p + 3);
    labels_.push_back(label);
    seeded_[kept++] = label;
  }
  seeded_.resize(kept);
  held_.insert(held_.end(), seeded_.begin(), seeded_.end());
  std::sort(held_.begin(), held_.end());
}

// Tet t of the rim (a zone vertex and another: finite, or a hull facet): its range
// test, then the wall, or the queue (a hull facet's query runs at once). One left
// unproved in this round (in conflict, waiting, or leaning on a wall that broke) is
// checked again in the next.
void ZoneWorker::check_tet(TetId t, TetKind kind, std::vector<std::uint64_t>& repairs) {
  ++round_.checked;
  if (dt_.is_infinite(t)) {
    if (!check_hull_facet(t, repairs)) wall_broken_ = true, block_zone_vertices(t), recheck_next_.push_back(t);
    return;
  }
  if (proved(t)) return;
  QueuedTet q{certificate_.range_test(dt_, t), t};
  if (q.range.clears()) {
    proved_empty_[t] = kRanged;
    return;
  }
  if (certified_by_neighbour(t)) {
    proved_empty_[t] = kShared;
    ++stats_.rim_from_neighbours;
    return;
  }
  // The wall: certified with this round if the wall holds in it (the round's end tells).
  if (!force_ && stats_.rounds <= kLeanRounds && kind == TetKind::kBeyond && q.range.bounded &&
      q.range.hi < wall_key_) {
    proved_empty_[t] = std::uint8_t(kLeaned + stats_.rounds - 1);
    leaned_.push_back(t);
    return;
  }
  ++stats_.range_failures;
  queued_.push_back(q);
  if (queued_.size() >= queue_cap_) run_queued_queries(repairs);
}

bool ZoneWorker::query_tet(const QueuedTet& q, std::vector<std::uint64_t>& repairs) {
  // A tet proved empty stays empty, and in its slot, for the rest of the zone: later
  // repairs insert only points that were missing, and none of those is in its ball.
  if (proved(q.tet)) return true;
  if (conflicts_with_recent(q)) {
    ++stats_.queries_spared;
    return false;
  }
  RecentRepair& r = recent_[recent_next_];
  const std::uint64_t deepest = certificate_.query(dt_, q.tet, q.range, stats_, r.xyz);
  if (deepest == Certificate::kNone) {
    stats_.count_empty_query(certificate_.reach_past_window(q.range));
    proved_empty_[q.tet] = kProved;
    return true;
  }
  repairs.push_back(deepest);
  r.label = deepest;
  recent_next_ = (recent_next_ + 1) % kRecent;
  recent_count_ = std::min(recent_count_ + 1, kRecent);
  return false;
}

// A repair point found this round is inserted before the next: a tet in conflict with
// it (exactly, under the perturbation) is in its cavity then, and gone. Its query
// would find a conflict too, at the cost of a walk through the index; on a surface
// the queued tets along the sort axis share their repair points (hills 10^6: 767 k
// queries found a conflict for 297 k repair points). The newest first: the queue runs
// along the sort axis, and the last repair is the nearest.
bool ZoneWorker::conflicts_with_recent(const QueuedTet& q) const {
  for (std::size_t k = 1; k <= recent_count_; ++k) {
    const RecentRepair& r = recent_[(recent_next_ + kRecent - k) % kRecent];
    if (!std::isnan(conflict_score(dt_, q.tet, q.range.ball, r.label, r.xyz, nullptr))) return true;
  }
  return false;
}

// An infinite tet of the window is a hull facet of the window's points. It is one of
// the global hull when no missing point conflicts with it; otherwise the missing
// points beyond it are what the window lacks there, and the one nearest the facet is
// inserted.
bool ZoneWorker::check_hull_facet(TetId t, std::vector<std::uint64_t>& repairs) {
  if (certificate_.hull_facet_range_test(dt_, t)) return true;
  // A facet of the global hull: the window's hull facet with these three labels faces
  // the same way (every point lies on its inner side or on it), and nothing conflicts.
  // On a box-shaped scan the hull's flat faces hold thousands of boundary points, all
  // on the facet's plane, that the query would test one by one.
  if (certificate_.is_global_hull_facet(dt_, t)) return true;
  ++stats_.range_failures;
  if (proved(t)) return true;
  const std::uint64_t nearest = certificate_.hull_facet_query(dt_, t, stats_);
  if (nearest == Certificate::kNone) {
    proved_empty_[t] = kProved;
    return true;
  }
  repairs.push_back(nearest);
  return false;
}

void ZoneWorker::block_zone_vertices(TetId t) {
  for (int i = 0; i < 4; ++i) {
    const VertexId v = dt_.vertex(t, i);
    if (v != core::kInfiniteVertex && zone_of_[v] != kNoZone)
      blocked_round_[zone_of_[v]] = std::uint32_t(stats_.rounds);
  }
}

bool ZoneWorker::zone_vertex_blocked(TetId t, std::uint64_t round, bool every) const {
  for (int i = 0; i < 4; ++i) {
    const VertexId v = dt_.vertex(t, i);
    if (v == core::kInfiniteVertex || zone_of_[v] == kNoZone) continue;
    if ((blocked_round_[zone_of_[v]] == round) != every) return !every;
  }
  return every;
}

// A round checks the rim tets not yet certified: in the first, every rim tet (one scan
// of the tet array in memory order); in later ones, those left unproved by the round
// before and the new ones, every one of which is in the star of a point that round's
// repairs inserted (an insertion's new tets all have the new point). The tets of zone
// vertices alone are never checked: when a round leaves no rim tet unproved, the rim
// holds and they are all Delaunay (Lemma 6), and so every zone vertex is final.
std::size_t ZoneWorker::check_round(std::vector<std::uint64_t>& repairs) {
  round_ = RoundWork{};
  recent_count_ = recent_next_ = 0;  // the last round's repair points are window points now
  const std::uint64_t queries_before = stats_.queries;
  const auto t0 = Clock::now();
  recheck_next_.clear();
  leaned_.clear();
  auto visit = [&](TetId t) {
    if (!dt_.is_alive(t)) return;
    const TetKind k = kind(t);
    if (k == TetKind::kBeyond || k == TetKind::kWall) check_tet(t, k, repairs);
  };
  if (stats_.rounds == 1) {
    const std::size_t slots = dt_.num_tet_slots();
    for (std::size_t t = 0; t < slots; ++t) visit(TetId(t));
  } else if (repairs_from_ == VertexId(labels_.size())) {
    // No repair point last round: the deferred tets' turn.
    for (TetId t : recheck_) visit(t);
    for (TetId t : deferred_) visit(t);
    deferred_.clear();
  } else {
    for (TetId t : recheck_) visit(t);
    for (VertexId v = repairs_from_; v < VertexId(labels_.size()); ++v) {
      star_.clear();
      dt_.star(v, star_);
      for (TetId t : star_) {
        if (zone_vertex_blocked(t, stats_.rounds - 1, /*every=*/false))
          visit(t);
        else
          deferred_.push_back(t);
      }
    }
  }
  run_queued_queries(repairs);
  round_.seconds_range = since(t0) - round_.seconds_queries;
  round_.queries = stats_.queries - queries_before;
  wall_held_.push_back(!wall_broken_);
  round_.wall_held = !wall_broken_;
  if (wall_broken_) recheck_next_.insert(recheck_next_.end(), leaned_.begin(), leaned_.end());
  wall_broken_ = false;
  recheck_.swap(recheck_next_);
  round_.unproved = recheck_.size();
  stats_.rim_rechecks += recheck_.size();
  return recheck_.size() + deferred_.size();
}

void ZoneWorker::run_queued_queries(std::vector<std::uint64_t>& repairs) {
  const auto t0 = Clock::now();
  // The queries, along the sort axis (a tet met twice once).
  std::sort(queued_.begin(), queued_.end());
  queued_.erase(std::unique(queued_.begin(), queued_.end()), queued_.end());
  round_.queued += queued_.size();
  // In the first two rounds, a tet whose zone vertices a conflict has already blocked
  // in this round waits for the next round: near the window's ragged edge the repairs
  // often remove it. Not in later rounds: there a zone's last few conflicts would then
  // be repaired one a round. A rim tet left unproved (waiting, or in conflict) is
  // checked again next round; one with a wall vertex breaks the wall.
  constexpr std::uint64_t kDeferRounds = 2;
  for (const QueuedTet& q : queued_) {
    const bool wait =
        !force_ && stats_.rounds <= kDeferRounds && zone_vertex_blocked(q.tet, stats_.rounds, /*every=*/true);
    if (!wait && query_tet(q, repairs)) continue;
    if (!wait) block_zone_vertices(q.tet), ++round_.conflicts;
    wall_broken_ |= kind(q.tet) == TetKind::kWall;
    recheck_next_.push_back(q.tet);
  }
  queued_.clear();
  round_.seconds_queries += since(t0);
}

bool ZoneWorker::certified_by_neighbour(TetId t) const {
  if (!shared_) return false;
  SharedRim::Labels l;
  for (int i = 0; i < 4; ++i) l[std::size_t(i)] = labels_[dt_.vertex(t, i)];
  std::sort(l.begin(), l.end());
  return shared_->contains(l);
}

// Once the rim holds, every rim tet is a tet of DT(P). Those with a vertex that another
// zone may still hold as its own (a label past the zone's first that is not a zone
// vertex: a later segment's, or another strip's) go to shared_; the others' vertices
// are all in segments before this one, whose zones have all started before it.
void ZoneWorker::publish_rim() {
  if (!shared_) return;
  publish_.clear();
  const std::size_t slots = dt_.num_tet_slots();
  for (std::size_t t = 0; t < slots; ++t) {
    if (!dt_.is_alive(TetId(t)) || dt_.is_infinite(TetId(t))) continue;
    const TetKind k = kind(TetId(t));
    if (k != TetKind::kBeyond && k != TetKind::kWall) continue;
    bool later = false;
    SharedRim::Labels l;
    for (int i = 0; i < 4; ++i) {
      const VertexId v = dt_.vertex(TetId(t), i);
      later |= zone_of_[v] == kNoZone && labels_[v] >= plan_->label_begin;
      l[std::size_t(i)] = labels_[v];
    }
    if (!later) continue;
    std::sort(l.begin(), l.end());
    publish_.push_back(l);
    // In batches: the scratch stays small (a zone's rim is tens of thousands of tets).
    if (publish_.size() == kPublishBatch)
      stats_.rim_published += shared_->publish(publish_, &stats_.rim_no_room), publish_.clear();
  }
  stats_.rim_published += shared_->publish(publish_, &stats_.rim_no_room);
}

void ZoneWorker::mark_beyond(VertexId first, VertexId end) {
  beyond_.resize(end, 0);
  for (VertexId v = first; v < end; ++v)
    beyond_[v] = zone_of_[v] == kNoZone && labels_[v] >= plan_->label_end &&
                 certificate_.in_strip_window(&xyz_[3 * std::size_t(v)]);
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
void ZoneWorker::emit(ZoneTets& out) {
  const std::size_t slots = dt_.num_tet_slots();
  const std::size_t zone_size = blocked_round_.size();
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
    if (z != kNoZone) {
      ++bucket_start[(z >> shift) + 1];
      // How it was certified: four zone vertices, by the rim (never checked itself);
      // otherwise by its mark (a query, the wall in a round it held, or the range test).
      const bool interior = kind(TetId(t)) == TetKind::kInterior;
      const std::uint8_t mark = proved_empty_[t];
      stats_.tets_by_rim += interior;
      stats_.tets_by_query += !interior && mark == kProved;
      stats_.tets_by_wall += !interior && mark >= kLeaned && wall_held_[mark - kLeaned];
      stats_.tets_by_neighbour += !interior && mark == kShared;
    }
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
  // Pass 3: each bucket by zone index (its minimum label minus label_begin).
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
      return (m - plan_->label_begin) & low_mask;
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
  out.xyz = std::span<const double>(xyz_.data(), xyz_.size());
}

SegmentStats ZoneWorker::run(const SegmentPlan& plan, const Zone& zone, ZoneTets& out) {
  plan_ = &plan;
  zone_ = zone;
  certificate_.start_zone(plan, zone, held_);
  stats_ = SegmentStats{};
  recheck_.clear();
  deferred_.clear();
  repairs_from_ = 0;
  force_ = false;
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
  // A window point's share of the zone plan's bytes (kWindowBytesPerPoint) holds an
  // eighth of a queue entry (9 bytes) and the memo's byte for each of its ~7 tet slots.
  queue_cap_ = std::max<std::size_t>(256, labels_.size() / 8);
  proved_empty_.assign(dt_.num_tet_slots(), 0);
  wall_held_.clear();
  wall_broken_ = false;
  wall_key_ = plan_->label_end < view_.count ? view_.key(plan_->label_end) : std::numeric_limits<double>::infinity();

  t0 = Clock::now();
  // The zone vertices: the window's points with a label in the segment's zone and,
  // with strips, a coordinate in this strip. Every other label of the zone is
  // another strip's.
  blocked_round_.assign(plan_->label_end - plan_->label_begin, 0);
  zone_of_.assign(labels_.size(), kNoZone);
  for (VertexId v = 0; v < labels_.size(); ++v) {
    const std::uint64_t l = labels_[v];
    const double* p = &xyz_[3 * std::size_t(v)];
    if (!zone_point(l, p)) {
      if (std::binary_search(seeded_.begin(), seeded_.end(), l))
        ++stats_.neighbour_points;
      else if (std::binary_search(held_.begin(), held_.end(), l))
        ++stats_.hull_points;
      else if (!in_strip(p))
        ++stats_.zone_buffer_points;
      else
        ++stats_.segment_buffer_points;
      continue;
    }
    const std::uint64_t z = l - plan_->label_begin;
    zone_of_[v] = std::uint32_t(z);
  }
  mark_beyond(0, VertexId(labels_.size()));
  std::vector<std::uint64_t> repairs;
  // (round: its work as check_round counted it; inserted, seconds: the repairs after it.
  // A zone that is its whole segment spans (-inf, inf) across, on no axis ('-'). The
  // strip's bounds exactly, so that a zone's points can be found again from the log:
  // scripts/bench/zoo/cross-zone-facets.)
  const double inf = std::numeric_limits<double>::infinity();
  const double strip_lo = zone_.axis >= 0 ? zone_.lo : -inf, strip_hi = zone_.axis >= 0 ? zone_.hi : inf;
  auto log_round = [&](std::size_t inserted, double seconds) {
    spdlog::debug(
        "zone [{}, {}) strip [{}, {}) on {} round {}: {} tets checked ({:.3f} s), {} queued, {} queries "
        "({} found a conflict, {:.3f} s), wall {}, {} rim tets left, {} repair points inserted ({:.3f} s)",
        plan_->label_begin, plan_->label_end, strip_lo, strip_hi, zone_.axis >= 0 ? "xyz"[zone_.axis] : '-',
        stats_.rounds, round_.checked, round_.seconds_range, round_.queued, round_.queries, round_.conflicts,
        round_.seconds_queries, round_.wall_held ? "held" : "broken", round_.unproved, inserted, seconds);
  };
  for (;;) {
    ++stats_.rounds;
    repairs.clear();
    if (check_round(repairs) == 0) {
      log_round(0, 0);
      break;
    }
    // Tets left unproved without a repair (not expected: a wait or a broken wall comes
    // with a conflict) are checked next round without waiting or leaning.
    force_ = repairs.empty() && round_.unproved != 0;
    const auto t_insert = Clock::now();
    std::sort(repairs.begin(), repairs.end());
    repairs.erase(std::unique(repairs.begin(), repairs.end()), repairs.end());
    // Append the repair points to the window and insert them.
    const std::size_t old_n = labels_.size();
    QueryScratch scratch;
    for (std::uint64_t label : repairs) {
      const double* p = certificate_.read_point(label, scratch);
      xyz_.insert(xyz_.end(), p, p + 3);
      labels_.push_back(label);
      held_.insert(std::upper_bound(held_.begin(), held_.end(), label), label);
    }
    zone_of_.resize(labels_.size(), kNoZone);  // repair points are never zone points
    mark_beyond(VertexId(old_n), VertexId(labels_.size()));
    dt_.set_points(xyz_.data(), labels_.data(), labels_.size());
    dt_.insert_range(VertexId(old_n), VertexId(labels_.size()));
    repairs_from_ = VertexId(old_n);
    proved_empty_.resize(dt_.num_tet_slots(), 0);  // new slots; a reused one was never proved
    stats_.repair_points += repairs.size();
    log_round(repairs.size(), since(t_insert));
  }
  publish_rim();
  emit(out);
  stats_.seconds_check = since(t0);
  stats_.kernel_bytes = dt_.memory_bytes();
  return stats_;
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

void OutputPool::clear() {
  std::lock_guard lock(mutex_);
  spare_ = {};
}

ZoneTriangulator::ZoneTriangulator(const SortedView& view, OutputPool* pool, SharedRim* shared)
    : worker_(std::make_unique<ZoneWorker>(view, pool, shared)) {}
ZoneTriangulator::~ZoneTriangulator() = default;

SegmentStats ZoneTriangulator::run(const SegmentPlan& plan, const Zone& zone, ZoneTets& out) {
  return worker_->run(plan, zone, out);
}

}  // namespace tetstream::pipeline
