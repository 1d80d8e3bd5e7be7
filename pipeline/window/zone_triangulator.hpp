#pragma once
// A zone's triangulation: its window built with the kernel, the certificate's rounds
// (pipeline/window/certificate.hpp) until every zone vertex is final, and the minimum
// vertex filter that emits each tet once, grouped by its minimum label.
//
// A zone vertex is *final* when every tet of its star is certified. A round checks the
// zone's *rim* (its tets with a zone vertex and another vertex) where it is not yet
// certified; a query that finds missing points in a tet's ball inserts the deepest one
// (a repair point), and the next round checks the rim tets left and new. When a round
// leaves none, the tets of zone vertices alone are Delaunay too, unchecked
// (docs/certificate.md, Lemma 6), and every zone vertex is final. A certified tet stays:
// its ball is empty of every point, so no repair point lands in it ("Invariants"). Then
// each finite tet whose minimum label is a zone vertex is emitted: every tet exactly
// once over the whole job.
#include "core/delaunay.hpp"
#include "pipeline/window/segment_plan.hpp"
#include "pipeline/window/sorted_view.hpp"

#include <algorithm>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

namespace tetstream::pipeline {

struct SegmentStats {
  std::uint64_t window_points = 0;  // zone + buffers + hull vertices, before repairs
  // Where the window's points beyond the zone's own come from: the segment's buffers
  // along the sort axis (inside the zone's strip), the strip buffers that cutting the
  // segment into zones adds (everything outside the strip: the price of parallel
  // zones), and the hull's vertices from elsewhere.
  std::uint64_t segment_buffer_points = 0, zone_buffer_points = 0, hull_points = 0;
  std::uint64_t neighbour_points = 0;           // held from the start: finished zones' rim tets' vertices (SharedRim)
  std::uint64_t repair_points = 0;              // inserted by the emptiness queries
  std::uint64_t range_failures = 0;             // star tets the range test could not clear
  std::uint64_t queries = 0;                    // emptiness queries run
  std::uint64_t query_points = 0;               // points the queries examined
  std::uint64_t rounds = 0;                     // check/repair rounds
  std::uint64_t tets = 0;                       // tets emitted
  std::uint64_t tets_by_query = 0;              // of those, certified by a query
  std::uint64_t tets_by_wall = 0;               // of those, by the wall
  std::uint64_t tets_by_rim = 0;                // of those, by the rim
  std::uint64_t tets_by_neighbour = 0;          // of those, by a finished zone (the rest: by the range test)
  std::uint64_t rim_published = 0;              // rim tets handed to the zones still running (SharedRim)
  std::uint64_t rim_no_room = 0;                // rim tets a finished zone offered that found the table full
  std::uint64_t rim_from_neighbours = 0;        // rim tets certified by finding them there
  std::uint64_t rim_rechecks = 0;               // rim tets left unproved by a round, checked again
  std::uint64_t queries_spared = 0;             // queued tets in conflict with a repair point already found
  std::uint64_t kernel_bytes = 0;               // the kernel's arrays at the end
  double seconds_build = 0, seconds_check = 0;  // check includes repairs and emission
  // The queries that found no conflict (the rim's true Delaunay tets), by how far the
  // tet's clipped ball reaches past the window's keys (Certificate::reach_past_window):
  // not at all, under half the segment's width, under one, under two, farther.
  std::uint64_t empty_reach_none = 0, empty_reach_half = 0, empty_reach_one = 0, empty_reach_two = 0,
                empty_reach_farther = 0;
  void count_empty_query(double reach) {
    ++(reach <= 0    ? empty_reach_none
       : reach < 0.5 ? empty_reach_half
       : reach < 1   ? empty_reach_one
       : reach < 2   ? empty_reach_two
                     : empty_reach_farther);
  }

  // Sums another worker's counters into these (rounds: the larger).
  SegmentStats& operator+=(const SegmentStats& o) {
    window_points += o.window_points, repair_points += o.repair_points, range_failures += o.range_failures;
    segment_buffer_points += o.segment_buffer_points, zone_buffer_points += o.zone_buffer_points;
    hull_points += o.hull_points, neighbour_points += o.neighbour_points;
    queries += o.queries, query_points += o.query_points, rounds = std::max(rounds, o.rounds), tets += o.tets;
    tets_by_query += o.tets_by_query, tets_by_wall += o.tets_by_wall, tets_by_rim += o.tets_by_rim,
        rim_rechecks += o.rim_rechecks, queries_spared += o.queries_spared;
    empty_reach_none += o.empty_reach_none, empty_reach_half += o.empty_reach_half,
        empty_reach_one += o.empty_reach_one, empty_reach_two += o.empty_reach_two,
        empty_reach_farther += o.empty_reach_farther;
    tets_by_neighbour += o.tets_by_neighbour, rim_published += o.rim_published, rim_no_room += o.rim_no_room,
        rim_from_neighbours += o.rim_from_neighbours;
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
  // The window's coordinates by local id (3 a point): the zone worker's own, valid
  // until it starts its next zone, so for SegmentSink::zone_done only (the periodic
  // keep's code words and balls read them there instead of the sorted file).
  std::span<const double> xyz;
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
  void clear();  // the given-back buffers freed (the triangulation is over)

 private:
  std::mutex mutex_;
  std::vector<ZoneTets> spare_;
};

class ZoneWorker;
class SharedRim;
// Triangulates zones of segments, one at a time, and emits each one's tets into `out`
// (taken from `pool` when given). Every label of a segment belongs to exactly one of
// its zones, so the zones' outputs together are the segment's tets, each once. Throws
// InputError when a window has fewer than 4 affinely independent points (only possible
// when the whole input has).
//
// The kernel and the buffers keep their capacity from one zone to the next, instead
// of faulting fresh pages in for each (the OS zeroes every fresh page). One object
// per thread (not thread-safe).
class ZoneTriangulator {
 public:
  // `shared`: the rim tets finished zones certified, looked up before a query and
  // added to when a zone ends (null: each zone proves its whole rim itself).
  explicit ZoneTriangulator(const SortedView& view, OutputPool* pool = nullptr, SharedRim* shared = nullptr);
  ~ZoneTriangulator();
  SegmentStats run(const SegmentPlan& plan, const Zone& zone, ZoneTets& out);

 private:
  std::unique_ptr<ZoneWorker> worker_;
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
      if (l < best_label)
        limit = best_label, best_label = l, best = p;
      else
        limit = std::min(limit, l);
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
