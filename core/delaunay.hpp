#pragma once
// The in-memory 3D Delaunay kernel: incremental Bowyer-Watson insertion with an
// infinite vertex, exact perturbed predicates (core/predicates.hpp), and flat
// struct-of-arrays tetrahedra. Every stage of the out-of-core pipeline runs it on a
// window of points. No I/O, no logging: results are values and counters.
//
// Anatomy of a tetrahedron t (the one picture every index trick points back to):
//
//   vertices   vertex(t, 0..3) = tet_vertex_[4t + i], positively oriented:
//              orient3d(v0, v1, v2, v3) > 0 for a finite tet.
//   facets     facet f is the triangle opposite vertex f; its vertices, in the
//              order kFacetVertex[f], see v[f] on their positive side:
//              orient3d(v[kFacetVertex[f][0]], v[kFacetVertex[f][1]], v[kFacetVertex[f][2]], v[f]) > 0.
//   neighbours tet_neighbor_[4t + f] = 4t' + f': the tet t' across facet f, and the
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
// fewer than 4 G points). Each point also has a 64-bit global label that drives the
// symbolic perturbation, so two windows that share points agree on degenerate cases.
#include "core/predicates.hpp"

#include <cstddef>
#include <cstdint>
#include <span>
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
  // copied: they must outlive the kernel or be re-pointed with set_points().
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
  std::size_t num_tet_slots() const { return tet_vertex_.size() / 4; }
  bool is_alive(TetId t) const { return tet_flags_[t] != kFreeFlag; }
  bool is_infinite(TetId t) const;
  VertexId vertex(TetId t, int i) const { return tet_vertex_[4 * t + i]; }
  FacetHandle neighbor(TetId t, int f) const { return tet_neighbor_[4 * t + f]; }
  const double* point(VertexId v) const { return xyz_ + 3 * std::size_t(v); }
  std::uint64_t label(VertexId v) const { return labels_ ? labels_[v] : v; }

  // For each point: itself, or the first point with the same coordinates.
  VertexId duplicate_of(VertexId v) const { return duplicate_of_[v]; }

  // Calls f(const VertexId v[4]) for every finite tet, positively oriented.
  template <class F>
  void for_each_finite_tet(F&& f) const {
    const std::size_t slots = num_tet_slots();
    for (std::size_t t = 0; t < slots; ++t) {
      if (tet_flags_[t] == kFreeFlag) continue;
      const VertexId* v = &tet_vertex_[4 * t];
      if (v[0] == kInfiniteVertex || v[1] == kInfiniteVertex || v[2] == kInfiniteVertex ||
          v[3] == kInfiniteVertex)
        continue;
      f(v);
    }
  }

  // The tets incident to v (finite and infinite), appended to out. v must be a vertex.
  // Not thread-safe on one kernel (it marks tets while it searches).
  void star(VertexId v, std::vector<TetId>& out) const;
  // One tet incident to v, or kNoTet when v is not a vertex (a duplicate, not inserted).
  TetId incident_tet(VertexId v) const { return vertex_tet_[v]; }

  Circumsphere tet_circumsphere(TetId t) const;

  const DelaunayStats& stats() const { return stats_; }
  std::size_t memory_bytes() const;  // bytes held by the kernel's own arrays

 private:
  // tet_flags_ values. kAlive/kFree describe the slot; the two marks exist only
  // during one insertion and are reset before it returns.
  static constexpr std::uint8_t kAlive = 0;
  static constexpr std::uint8_t kInCavity = 1;
  static constexpr std::uint8_t kNotInConflict = 2;
  static constexpr std::uint8_t kStarMark = 3;  // only inside star()
  static constexpr std::uint8_t kFreeFlag = 0xFF;

  struct NewTet {  // one facet of the cavity boundary, joined to the new point
    VertexId v[4];
    FacetHandle outer;  // the facet handle across the boundary, outside the cavity
    std::uint32_t facet;  // position of the new point in v
  };

  void reset();
  bool make_initial_tet(const std::vector<std::uint32_t>& order, std::uint32_t used[4]);
  TetId locate(const double* p, TetId start);
  bool in_conflict(TetId t, const double* p, std::uint64_t label) const;
  TetId new_tet_slot();
  void free_tet_slot(TetId t);
  void link_new_tets(std::size_t count);

  const double* xyz_ = nullptr;
  const std::uint64_t* labels_ = nullptr;
  std::size_t num_points_ = 0;

  // Struct-of-arrays tet storage; free slots are chained through tet_neighbor_[4t].
  std::vector<VertexId> tet_vertex_;
  std::vector<FacetHandle> tet_neighbor_;
  mutable std::vector<std::uint8_t> tet_flags_;  // mutable: star() marks and unmarks
  TetId free_head_ = kNoTet;
  std::size_t num_alive_ = 0;
  std::size_t num_infinite_ = 0;

  std::vector<TetId> vertex_tet_;
  std::vector<VertexId> duplicate_of_;
  TetId last_tet_ = kNoTet;
  std::size_t num_vertices_ = 0;
  std::uint64_t walk_rng_ = 0x9E3779B97F4A7C15ULL;

  // Scratch, sized once and reused by every insertion (no allocation in the loop
  // once the cavity sizes of the input have been seen).
  std::vector<TetId> cavity_;
  std::vector<TetId> rejected_;
  std::vector<NewTet> new_tets_;
  std::vector<TetId> new_slots_;
  std::vector<FacetHandle> edge_table_;  // boundary edge (local ids) -> open facet

  DelaunayStats stats_;
};

}  // namespace tetstream::core
