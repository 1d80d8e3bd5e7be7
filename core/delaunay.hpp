#pragma once
// The in-memory 3D Delaunay kernel: incremental Bowyer-Watson insertion with an
// infinite vertex, exact perturbed predicates (core/predicates.hpp), and flat
// struct-of-arrays tetrahedra. Every stage of the out-of-core pipeline runs it on a
// window of points. No I/O, no logging: results are values and counters.
//
// Anatomy of a tetrahedron t (the one picture every index trick points back to):
//
//   vertices   vertex(t, 0..3) = tets_[t].v[i] (as caller ids), positively oriented:
//              orient3d(v0, v1, v2, v3) > 0 for a finite tet.
//   facets     facet f is the triangle opposite vertex f; its vertices, in the
//              order kFacetVertex[f], see v[f] on their positive side:
//              orient3d(v[kFacetVertex[f][0]], v[kFacetVertex[f][1]], v[kFacetVertex[f][2]], v[f]) > 0.
//   neighbours tets_[t].n[f] = 4t' + f': the tet t' across facet f, and the
//              index f' of the same facet in t' (a "facet handle"), so crossing a
//              facet and knowing where you came from is one load. Invariant:
//              neighbor(neighbor(h)) == h.
//   infinite   the hull is closed by tets with one vertex kInfiniteVertex; the finite
//              facet of such a tet is a hull facet, and the hull's interior lies on
//              the negative side of it (in kFacetVertex order).
//
//            v3
//           /|\ .        facet 0 = (v1 v3 v2)   facet 1 = (v0 v2 v3)
//          / | \ .       facet 2 = (v0 v3 v1)   facet 3 = (v0 v1 v2)
//         /  |  \ .
//       v0---|---v2 .    Each facet, in this order, sees its own vertex on its
//         \  |  / .      positive side (it turns clockwise seen from outside).
//          \ | / .
//           \|/ .
//            v1
//
// Vertices are local indices into the caller's point array (uint32: a window holds
// fewer than 2^31 points; link_new_tets() borrows the top bit). Each point also has a 64-bit global label that drives
// the symbolic perturbation, so two windows that share points agree on degenerate cases.
//
// Two numberings (translated at the API boundary, never inside the insertion loop):
//   caller ids    positions in the caller's xyz/labels arrays; everything public
//                 (vertex(), point(), label(), star(), incident_tet(), ...) speaks them.
//   internal ids  the order in which points were handed to the insertion loop (BRIO
//                 + Hilbert in build(), Hilbert in insert_range()); the kernel keeps
//                 its own copy of the coordinates in that order (pts_), so points that
//                 are close in space are close in memory and the walk, the conflict
//                 tests and the linking touch few cache lines. order_[internal] is the
//                 caller id; per-point arrays the API needs (vertex_tet_) stay indexed
//                 by caller id.
//   Predicates see the same doubles and the same labels (labels_[order_[x]]) as a
//   kernel working on caller ids would, so every answer, hence the triangulation, is
//   identical.
#include "core/page_array.hpp"
#include "core/predicates.hpp"

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

namespace tetstream::core {

using VertexId = std::uint32_t;
using TetId = std::uint32_t;
using FacetHandle = std::uint32_t;  // 4 * tet + facet

inline constexpr VertexId kInfiniteVertex = 0xFFFFFFFFu;
inline constexpr VertexId kNoVertex = 0xFFFFFFFEu;
inline constexpr TetId kNoTet = 0xFFFFFFFFu;

inline constexpr int kFacetVertex[4][3] = {{1, 3, 2}, {0, 2, 3}, {0, 3, 1}, {0, 1, 2}};

// Why a build can fail. Everything else (duplicates, degeneracies) is handled.
enum class BuildStatus : std::uint8_t {
  kOk,
  kTooFewPoints,  // fewer than 4 affinely independent distinct points
};

enum class InsertOutcome : std::uint8_t {
  kInserted,
  kDuplicate,  // exact duplicate of an existing vertex; see duplicate_of()
};

// Counters of one kernel; summed by the caller across threads, never logged here.
struct DelaunayStats {
  std::uint64_t inserted = 0;
  std::uint64_t duplicates = 0;
  std::uint64_t walk_steps = 0;
  std::uint64_t cavity_tets = 0;  // tets removed by insertions (sum of cavity sizes)
};

class Delaunay {
 public:
  Delaunay() = default;

  // Triangulates points [0, n) of xyz (3 doubles per point). labels[i] is point i's
  // global label (distinct); null means label i. The arrays are referenced, not
  // copied: they must outlive the kernel or be re-pointed with set_points(). (The
  // kernel keeps a private copy of the coordinates of the points it inserts, in
  // insertion order, for locality; point() still answers from the caller's array.)
  // Insertion order: biased randomized rounds, Hilbert order inside each round.
  BuildStatus build(const double* xyz, const std::uint64_t* labels, std::size_t n);

  // Re-points the kernel at a grown copy of the point arrays (same first points,
  // possibly moved in memory); then insert() or insert_range() the new ones.
  void set_points(const double* xyz, const std::uint64_t* labels, std::size_t n);
  // Inserts points [first, last) (spatially sorted first). Requires a built kernel.
  void insert_range(VertexId first, VertexId last);
  // Inserts one point, starting the walk at `hint` (kNoTet: the last created tet).
  InsertOutcome insert(VertexId v, TetId hint = kNoTet);

  // Memory is reserved from this estimate (about 6.7 tets per point).
  void reserve(std::size_t points);

  std::size_t num_points() const { return num_points_; }
  std::size_t num_vertices() const { return num_vertices_; }  // distinct points inserted
  std::size_t num_finite_tets() const { return num_alive_ - num_infinite_; }
  std::size_t num_infinite_tets() const { return num_infinite_; }
  std::size_t num_tet_slots() const { return tets_.size(); }
  bool is_alive(TetId t) const { return tets_[t].v[0] != kNoVertex; }
  bool is_infinite(TetId t) const;
  VertexId vertex(TetId t, int i) const { return to_caller(tets_[t].v[i]); }
  FacetHandle neighbor(TetId t, int f) const { return tets_[t].n[f]; }
  const double* point(VertexId v) const { return xyz_ + 3 * std::size_t(v); }
  std::uint64_t label(VertexId v) const { return labels_ ? labels_[v] : v; }

  // For each point: itself, or the first point with the same coordinates.
  VertexId duplicate_of(VertexId v) const {
    if (duplicate_of_.empty()) return v;
    const auto it = duplicate_of_.find(v);
    return it == duplicate_of_.end() ? v : it->second;
  }

  // Calls f(const VertexId v[4]) for every finite tet, positively oriented.
  template <class F>
  void for_each_finite_tet(F&& f) const {
    const std::size_t slots = num_tet_slots();
    for (std::size_t t = 0; t < slots; ++t) {
      const Tet& tet = tets_[t];
      if (tet.v[0] == kNoVertex) continue;  // a free slot
      if (tet.v[0] == kInfiniteVertex || tet.v[1] == kInfiniteVertex || tet.v[2] == kInfiniteVertex ||
          tet.v[3] == kInfiniteVertex)
        continue;
      const VertexId v[4] = {order_[tet.v[0]], order_[tet.v[1]], order_[tet.v[2]], order_[tet.v[3]]};
      f(static_cast<const VertexId*>(v));
    }
  }

  // The tets incident to v (finite and infinite), appended to out. v must be a vertex.
  // Not thread-safe on one kernel (it marks tets while it searches).
  void star(VertexId v, std::vector<TetId>& out) const;
  // One tet incident to v, or kNoTet when v is not a vertex (a duplicate, not inserted).
  TetId incident_tet(VertexId v) const { return v < vertex_tet_.size() ? vertex_tet_[v] : kNoTet; }

  Circumsphere tet_circumsphere(TetId t) const;

  // Whether p lies strictly inside a finite tet, hence strictly inside the convex
  // hull of the vertices (false on any tet's boundary, or outside the hull). Found by
  // a walk from `hint` (kNoTet: the last tet created), which is set to the tet the
  // walk ends in: queries in spatial order walk a few steps each.
  bool strictly_inside(const double* p, TetId& hint);

  const DelaunayStats& stats() const { return stats_; }
  std::size_t memory_bytes() const;  // bytes held by the kernel's own arrays

 private:
  // One tet: vertices (internal ids, kInfiniteVertex) and neighbour facet handles,
  // side by side in 32 bytes (two tets per cache line), so the conflict test of a tet
  // and the step across its facets load one line. A free slot has v[0] == kNoVertex
  // and chains the free list through n[0].
  struct alignas(32) Tet {
    VertexId v[4];
    FacetHandle n[4];
  };

  struct NewTet {  // one facet of the cavity boundary, joined to the new point
    VertexId v[4];
    FacetHandle outer;    // the facet handle across the boundary, outside the cavity
    std::uint32_t facet;  // position of the new point in v
  };

  // Marks per tet slot, set only during one insertion (or one star()) and cleared
  // before it returns: 2 bits per tet in one word, instead of a flag byte, keeps
  // them cache-resident, and both marks of a tet come in one load.
  static constexpr std::uint64_t kInCavity = 1;  // during insert(): in the cavity
  static constexpr std::uint64_t kVisited = 2;   // insert(): tested, not in conflict; star(): in the star
  struct Marks {
    std::vector<std::uint64_t> bits;
    std::uint64_t get(TetId t) const { return (bits[t >> 5] >> (2 * (t & 31))) & 3; }
    void set(TetId t, std::uint64_t m) { bits[t >> 5] |= m << (2 * (t & 31)); }
    void clear(TetId t) { bits[t >> 5] &= ~(std::uint64_t(3) << (2 * (t & 31))); }
    void grow(std::size_t slots) {
      if (bits.size() * 32 < slots) bits.resize(std::max(2 * bits.size(), slots / 32 + 1), 0);
    }
  };

  VertexId to_caller(VertexId x) const { return x >= kNoVertex ? x : order_[x]; }
  const double* ipoint(VertexId x) const { return &pts_[3 * std::size_t(x)]; }
  std::uint64_t ilabel(VertexId x) const {
    const VertexId c = order_[x];
    return labels_ ? labels_[c] : c;
  }
  VertexId assign_internal(VertexId v);  // the next internal id, for v (copies v's point)

  void reset();
  bool make_initial_tet(std::uint32_t used[4]);
  TetId locate(const double* p, TetId start);
  bool in_conflict(const Tet& t, const double* p, VertexId x) const;
  InsertOutcome insert_internal(VertexId x, TetId hint);
  TetId new_tet_slot();
  void free_tet_slot(TetId t);
  void link_new_tets(std::size_t count);

  const double* xyz_ = nullptr;
  const std::uint64_t* labels_ = nullptr;
  std::size_t num_points_ = 0;

  PageArray<Tet> tets_;  // grows without copies; pages past a window's need handed back
  TetId free_head_ = kNoTet;
  std::size_t num_alive_ = 0;
  std::size_t num_infinite_ = 0;
  mutable Marks marks_;  // mutable: star() marks and unmarks

  // Internal numbering (see the top of this file).
  std::vector<double> pts_;                              // 3 per internal id
  std::vector<VertexId> order_;                          // internal -> caller
  std::vector<TetId> vertex_tet_;                        // caller -> one incident tet (kNoTet: not a vertex)
  std::unordered_map<VertexId, VertexId> duplicate_of_;  // caller -> caller; rare
  TetId last_tet_ = kNoTet;
  std::size_t num_vertices_ = 0;
  std::uint64_t walk_rng_ = 0x9E3779B97F4A7C15ULL;

  // Scratch, sized once and reused by every insertion (no allocation in the loop
  // once the cavity sizes of the input have been seen).
  std::vector<TetId> cavity_;
  std::vector<TetId> rejected_;
  std::vector<NewTet> new_tets_;
  std::vector<TetId> new_slots_;
  std::vector<std::array<std::uint32_t, 3>> local_ids_;  // per new tet: its boundary vertices
  std::vector<VertexId> local_vertex_;                   // local id -> caller id (saved from order_)
  std::vector<VertexId> local_internal_;                 // local id -> internal id
  std::vector<TetId> local_tet_;                         // local id -> a new tet holding it
  // Directed boundary edge (local ids) -> new facet: a dense table for cavities of
  // up to kDenseEdgeSide local ids (at most 256 KiB), a hash table beyond.
  static constexpr std::size_t kDenseEdgeSide = 256;
  struct EdgeSlot {
    static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
    std::uint64_t key = kEmpty;  // a << 32 | b
    FacetHandle facet = 0;
  };
  std::vector<FacetHandle> edge_table_;
  std::vector<EdgeSlot> edge_hash_;

  DelaunayStats stats_;
};

}  // namespace tetstream::core
