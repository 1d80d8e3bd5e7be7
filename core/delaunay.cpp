#include "core/delaunay.hpp"

#include "core/compiler.hpp"
#include "core/huge_pages.hpp"
#include "core/spatial_sort.hpp"

#include <algorithm>
#include <bit>
#include <cassert>
#include <numeric>

namespace tetstream::core {

namespace {

// Measured: about 6.7 finite tets per point on uniform data, fewer on shells and
// grids; the infinite tets add O(n^(2/3)). A little headroom avoids one regrowth.
constexpr double kTetsPerPointEstimate = 6.9;

TS_FORCE_INLINE bool has_infinite_vertex(const VertexId* v) {
  return v[0] == kInfiniteVertex || v[1] == kInfiniteVertex || v[2] == kInfiniteVertex || v[3] == kInfiniteVertex;
}

TS_FORCE_INLINE int infinite_position(const VertexId* v) {
  for (int i = 0; i < 4; ++i)
    if (v[i] == kInfiniteVertex) return i;
  return -1;
}

// kOtherPositions[f][g]: the two positions of a tet other than f and g (f != g).
constexpr int kOtherPositions[4][4][2] = {
    {{-1, -1}, {2, 3}, {1, 3}, {1, 2}},
    {{2, 3}, {-1, -1}, {0, 3}, {0, 2}},
    {{1, 3}, {0, 3}, {-1, -1}, {0, 1}},
    {{1, 2}, {0, 2}, {0, 1}, {-1, -1}},
};

TS_FORCE_INLINE bool same_point(const double* a, const double* b) {
  return a[0] == b[0] && a[1] == b[1] && a[2] == b[2];
}

}  // namespace

bool Delaunay::is_infinite(TetId t) const { return has_infinite_vertex(tets_[t].v); }

void Delaunay::set_points(const double* xyz, const std::uint64_t* labels, std::size_t n) {
  assert(n >= num_points_ && "points can be appended, never removed");
  assert(n < (std::size_t(1) << 31) && "caller ids must leave the top bit free");
  xyz_ = xyz;
  labels_ = labels;
  num_points_ = n;
  vertex_tet_.resize(n, kNoTet);
}

// The caller's point v gets the next internal id (and its coordinates are copied)
// when it is handed to the insertion loop. (A point handed in twice gets two ids;
// the second copy is then found as a duplicate of the first, as any duplicate is.)
VertexId Delaunay::assign_internal(VertexId v) {
  const VertexId x = VertexId(order_.size());
  order_.push_back(v);
  const double* p = point(v);
  pts_.insert(pts_.end(), p, p + 3);
  return x;
}

void Delaunay::reserve(std::size_t points) {
  // Tet ids stay below 2^30 (facet handles are 4t + f in 32 bits); caller ids below
  // 2^31 (link_new_tets() borrows their top bit).
  assert(double(points) * kTetsPerPointEstimate < double(1u << 30));
  const std::size_t tets = std::size_t(double(points) * kTetsPerPointEstimate) + 64;
  tets_.reserve(tets);
  // A kernel reused for a smaller window keeps only what this one needs resident.
  tets_.release_beyond(tets);
  marks_.grow(tets);
  pts_.reserve(3 * points);
  advise_huge_pages(pts_.data(), pts_.capacity() * sizeof(double));
  order_.reserve(points);
  vertex_tet_.reserve(points);
}

void Delaunay::reset() {
  tets_.clear();
  free_head_ = kNoTet;
  num_alive_ = num_infinite_ = 0;
  marks_.bits.clear();
  pts_.clear();
  order_.clear();
  vertex_tet_.clear();
  duplicate_of_.clear();
  num_points_ = 0;
  num_vertices_ = 0;
  last_tet_ = kNoTet;
  stats_ = {};
  cavity_.reserve(256);
  rejected_.reserve(256);
  new_tets_.reserve(256);
  new_slots_.reserve(256);
  local_ids_.reserve(256);
  local_vertex_.reserve(256);
  local_internal_.reserve(256);
  local_tet_.reserve(256);
  edge_table_.assign(64 * 64, kNoTet);
}

BuildStatus Delaunay::build(const double* xyz, const std::uint64_t* labels, std::size_t n) {
  reset();
  // The order is computed before the tet arrays are reserved, so its temporary
  // keys never coexist with them: peak memory stays that of the tets. It becomes
  // order_ (internal id = position in it), and the coordinates are copied in it.
  order_ = brio_order(xyz, n);
  reserve(n);
  set_points(xyz, labels, n);
  pts_.resize(3 * n);
  for (std::size_t k = 0; k < n; ++k) {
    const double* p = xyz + 3 * std::size_t(order_[k]);
    double* q = &pts_[3 * k];
    q[0] = p[0], q[1] = p[1], q[2] = p[2];
  }

  std::uint32_t used[4];
  if (!make_initial_tet(used)) {
    reset();
    set_points(xyz, labels, n);
    return BuildStatus::kTooFewPoints;
  }
  TetId hint = last_tet_;
  for (VertexId x = 0; x < VertexId(n); ++x) {
    if (x == used[0] || x == used[1] || x == used[2] || x == used[3]) continue;
    insert_internal(x, hint);
    hint = last_tet_;
  }
  return BuildStatus::kOk;
}

// Finds four affinely independent points early in the insertion order (internal
// ids 0, 1, ...) and builds the first finite tet and its four infinite neighbours.
bool Delaunay::make_initial_tet(std::uint32_t used[4]) {
  const std::size_t n = order_.size();
  if (n < 4) return false;
  const VertexId a = 0;
  const double* pa = ipoint(a);
  std::size_t i = 1;
  while (i < n && same_point(ipoint(VertexId(i)), pa)) ++i;
  if (i == n) return false;
  const VertexId b = VertexId(i);
  const double* pb = ipoint(b);
  // a, b, c are collinear iff orient3d(a, b, c, q) = 0 for the three points q made
  // by moving a along each axis: the plane through a, b, c (if any) has a non-zero
  // normal component along some axis, and the q on that axis is off it.
  double q[3][3];
  for (int k = 0; k < 3; ++k) {
    for (int j = 0; j < 3; ++j) q[k][j] = pa[j];
    q[k][k] = pa[k] + (pa[k] == 0 ? 1.0 : std::abs(pa[k]));
  }
  auto collinear = [&](const double* pc) {
    for (int k = 0; k < 3; ++k)
      if (orient3d(pa, pb, pc, q[k]) != 0) return false;
    return true;
  };
  std::size_t j = i + 1;
  while (j < n && collinear(ipoint(VertexId(j)))) ++j;
  if (j >= n) return false;
  VertexId c = VertexId(j);
  std::size_t k = j + 1;
  int sign = 0;
  while (k < n && (sign = orient3d(pa, pb, ipoint(c), ipoint(VertexId(k)))) == 0) ++k;
  if (k >= n) return false;
  VertexId d = VertexId(k);
  VertexId bb = b;
  if (sign < 0) std::swap(bb, c);  // make (a, bb, c, d) positively oriented

  // Slot 0: the finite tet. Slots 1..4: the infinite tet across facet f of slot 0,
  // made of facet f's vertices in reverse order (so the hull's interior is on the
  // negative side of it, as the anatomy requires) and the infinite vertex last.
  const VertexId fin[4] = {a, bb, c, d};
  tets_.assign(5, Tet{});
  for (int m = 0; m < 4; ++m) tets_[0].v[m] = fin[m];
  for (int f = 0; f < 4; ++f) {
    Tet& inf = tets_[1 + f];
    inf.v[0] = fin[kFacetVertex[f][0]], inf.v[1] = fin[kFacetVertex[f][2]], inf.v[2] = fin[kFacetVertex[f][1]];
    inf.v[3] = kInfiniteVertex;
    tets_[0].n[f] = 4 * (1 + f) + 3;
    inf.n[3] = FacetHandle(f);
  }
  // The infinite tets meet each other along the facets that hold the infinite
  // vertex: match them by their vertex sets (16 facets, once).
  for (int s = 1; s <= 4; ++s)
    for (int f = 0; f < 3; ++f)
      for (int s2 = s + 1; s2 <= 4; ++s2)
        for (int f2 = 0; f2 < 3; ++f2) {
          VertexId x[3], y[3];
          for (int m = 0; m < 3; ++m) {
            x[m] = tets_[s].v[kFacetVertex[f][m]];
            y[m] = tets_[s2].v[kFacetVertex[f2][m]];
          }
          std::sort(x, x + 3);
          std::sort(y, y + 3);
          if (std::equal(x, x + 3, y)) {
            tets_[s].n[f] = 4 * s2 + f2;
            tets_[s2].n[f2] = 4 * s + f;
          }
        }
  marks_.grow(tets_.size());
  num_alive_ = 5;
  num_infinite_ = 4;
  for (VertexId v : fin) vertex_tet_[order_[v]] = 0;
  num_vertices_ = 4;
  stats_.inserted = 4;
  last_tet_ = 0;
  used[0] = a, used[1] = bb, used[2] = c, used[3] = d;
  return true;
}

// Visibility walk: step across any facet that separates the tet from p (exact
// orient3d), starting from a random facet so that the walk cannot cycle. Stops at
// the finite tet that contains p (closed), or at the infinite tet whose hull facet
// p lies strictly beyond. A Delaunay triangulation makes this walk terminate.
TetId Delaunay::locate(const double* p, TetId t) {
  if (t == kNoTet || !is_alive(t)) t = last_tet_;
  {
    const int i = infinite_position(tets_[t].v);
    if (i >= 0) t = tets_[t].n[i] >> 2;  // the finite tet behind the hull facet
  }
  int came_from = -1;
  for (;;) {
    ++stats_.walk_steps;
    const Tet& tet = tets_[t];
    const VertexId* v = tet.v;
    if (has_infinite_vertex(v)) return t;
    walk_rng_ ^= walk_rng_ << 13, walk_rng_ ^= walk_rng_ >> 7, walk_rng_ ^= walk_rng_ << 17;
    const int r = int(walk_rng_ >> 62);
    bool moved = false;
    for (int k = 0; k < 4; ++k) {
      const int f = (r + k) & 3;
      if (f == came_from) continue;
      const int* fv = kFacetVertex[f];
      if (orient3d(ipoint(v[fv[0]]), ipoint(v[fv[1]]), ipoint(v[fv[2]]), p) < 0) {
        const FacetHandle h = tet.n[f];
        t = h >> 2;
        came_from = int(h & 3);
        moved = true;
        break;
      }
    }
    if (!moved) return t;
  }
}

// The perturbed conflict test of the point with internal id x (coordinates p).
// Exactly insphere_sos / infinite_conflict_sos, with the labels looked up only
// when the unperturbed sign is 0 (they cost a dependent load each).
TS_FORCE_INLINE bool Delaunay::in_conflict(const Tet& t, const double* p, VertexId x) const {
  const VertexId* v = t.v;
  const int i = infinite_position(v);
  if (i < 0) {
    const double *a = ipoint(v[0]), *b = ipoint(v[1]), *c = ipoint(v[2]), *d = ipoint(v[3]);
    const int s = insphere(a, b, c, d, p);
    if (TS_LIKELY(s != 0)) return s > 0;
    return detail::insphere_sos_tiebreak(a, b, c, d, p, ilabel(v[0]), ilabel(v[1]), ilabel(v[2]), ilabel(v[3]),
                                         ilabel(x)) > 0;
  }
  const VertexId a = v[kFacetVertex[i][0]], b = v[kFacetVertex[i][1]], c = v[kFacetVertex[i][2]];
  const int s = orient3d(ipoint(a), ipoint(b), ipoint(c), p);
  if (TS_LIKELY(s != 0)) return s > 0;
  return detail::infinite_conflict_coplanar(ipoint(a), ipoint(b), ipoint(c), p, ilabel(a), ilabel(b), ilabel(c),
                                            ilabel(x)) > 0;
}

TetId Delaunay::new_tet_slot() {
  if (free_head_ != kNoTet) {
    const TetId t = free_head_;
    free_head_ = tets_[t].n[0];
    return t;
  }
  const TetId t = TetId(tets_.size());
  tets_.emplace_back();
  marks_.grow(tets_.size());
  return t;
}

void Delaunay::free_tet_slot(TetId t) {
  tets_[t].v[0] = kNoVertex;
  tets_[t].n[0] = free_head_;
  free_head_ = t;
}

InsertOutcome Delaunay::insert(VertexId v, TetId hint) {
  assert(v < num_points_);
  return insert_internal(assign_internal(v), hint);
}

InsertOutcome Delaunay::insert_internal(VertexId x, TetId hint) {
  const double* p = ipoint(x);
  const TetId start = locate(p, hint);

  // A point inside (or on) a finite tet that equals one of its vertices is a duplicate.
  {
    const VertexId* tv = tets_[start].v;
    if (!has_infinite_vertex(tv)) {
      for (int i = 0; i < 4; ++i)
        if (same_point(ipoint(tv[i]), p)) {
          const VertexId self = order_[x], first = order_[tv[i]];
          if (first != self) duplicate_of_[self] = first;
          ++stats_.duplicates;
          return InsertOutcome::kDuplicate;
        }
    }
  }

  // Cavity: the tets whose (perturbed) circumball contains p, grown from the
  // located tet, which always is one (p lies in its closed tet, hence strictly in
  // its ball, or strictly beyond its hull facet). The cavity is connected and
  // star-shaped from p, so a breadth-first search over neighbours finds it.
  // kInCavity marks its tets, kVisited the tets tested and found not in conflict.
  cavity_.clear();
  rejected_.clear();
  new_tets_.clear();
  // Each tet that joins the cavity gets its neighbours prefetched: they are tested
  // a few steps later, and their slots are scattered (the conflict test used to
  // wait on that load more than on the arithmetic).
  const auto prefetch_neighbors = [this](const Tet& t) {
    for (int f = 0; f < 4; ++f) TS_PREFETCH(&tets_[t.n[f] >> 2]);
  };
  marks_.set(start, kInCavity);
  cavity_.push_back(start);
  prefetch_neighbors(tets_[start]);
  for (std::size_t i = 0; i < cavity_.size(); ++i) {
    const TetId c = cavity_[i];
    const Tet& ct = tets_[c];
    for (int f = 0; f < 4; ++f) {
      const FacetHandle h = ct.n[f];
      const TetId n = h >> 2;
      const std::uint64_t mark = marks_.get(n);
      if (mark == kInCavity) continue;
      if (mark == 0) {
        const Tet& nt = tets_[n];
        if (in_conflict(nt, p, x)) {
          marks_.set(n, kInCavity);
          cavity_.push_back(n);
          prefetch_neighbors(nt);
          continue;
        }
        marks_.set(n, kVisited);
        rejected_.push_back(n);
      }
      // Boundary facet: the new tet is c with its vertex f replaced by x, which
      // keeps the orientation because x sees this facet from c's side.
      // (Element by element: a whole copy followed by a store into the middle made
      // the next load of the record stall on store forwarding.)
      NewTet& nt = new_tets_.emplace_back();
      for (int m = 0; m < 4; ++m) nt.v[m] = m == f ? x : ct.v[m];
      nt.outer = h;
      nt.facet = std::uint32_t(f);
    }
  }
  for (TetId t : rejected_) marks_.clear(t);
  stats_.cavity_tets += cavity_.size();

  // Release the cavity's slots (they are reused first by the new tets).
  for (TetId t : cavity_) {
    if (has_infinite_vertex(tets_[t].v)) --num_infinite_;
    marks_.clear(t);
    free_tet_slot(t);
  }
  num_alive_ -= cavity_.size();

  new_slots_.clear();
  if (local_ids_.size() < new_tets_.size()) local_ids_.resize(new_tets_.size());
  for (const NewTet& nt : new_tets_) {
    const TetId t = new_tet_slot();
    new_slots_.push_back(t);
    Tet& tet = tets_[t];
    tet.v[0] = nt.v[0], tet.v[1] = nt.v[1], tet.v[2] = nt.v[2], tet.v[3] = nt.v[3];
    const FacetHandle self = 4 * t + nt.facet;
    tet.n[nt.facet] = nt.outer;
    tets_[nt.outer >> 2].n[nt.outer & 3] = self;
    num_infinite_ += has_infinite_vertex(tet.v);
  }
  num_alive_ += new_tets_.size();
  link_new_tets(new_tets_.size());

  last_tet_ = new_slots_.back();
  vertex_tet_[order_[x]] = last_tet_;
  ++num_vertices_;
  ++stats_.inserted;
  return InsertOutcome::kInserted;
}

// The new tets meet each other across the facets that hold the new point. Such a
// facet is the new point plus one edge of the cavity boundary. The boundary is a
// closed surface, and its triangles (facet f of each new tet, in kFacetVertex[f]
// order) are all oriented alike (the new point on their positive side), so each
// boundary edge appears exactly twice, once in each direction. The boundary's
// vertices get small local numbers, so a directed edge (a, b) indexes a small square
// table directly: pass 1 parks in (a, b) the handle of the new facet over that edge,
// pass 2 reads its partner from (b, a). No branches, and no clearing: every entry
// read was written by this insertion.
//
// The local numbers live for the moment in order_ (indexed by internal id, so the
// boundary's entries are close together), tagged by the top bit, which no caller id
// uses (n < 2^31); local_vertex_ keeps the caller ids they replace and restores them.
void Delaunay::link_new_tets(std::size_t count) {
  constexpr VertexId kLocalTag = 0x80000000u;
  // The boundary is a triangulated sphere: count = 2 V - 4 triangles on V vertices,
  // so V = count / 2 + 2 bounds the local ids (plus 0 for the infinite vertex).
  const std::size_t max_local = count / 2 + 2;
  const std::size_t side = max_local + 1;
  if (local_tet_.size() < side + 1) {
    local_tet_.resize(side + 1);
    local_vertex_.resize(side + 1);
    local_internal_.resize(side + 1);
  }
  VertexId* local_vertex = local_vertex_.data();
  VertexId* local_internal = local_internal_.data();
  VertexId* order = order_.data();
  std::uint32_t num_local = 0;
  // Without branches (whether a vertex is new is a coin flip for the predictor):
  // the next local id's entries are written speculatively and kept only if new.
  auto local_id = [&](VertexId x) -> std::uint32_t {
    if (x == kInfiniteVertex) return 0;  // local 0 is the infinite vertex
    const VertexId slot = order[x];
    const bool fresh = !(slot & kLocalTag);
    const std::uint32_t next = num_local + 1;
    local_vertex[next] = slot;
    local_internal[next] = x;
    order[x] = fresh ? (kLocalTag | next) : slot;
    num_local += fresh;
    return fresh ? next : (slot & ~kLocalTag);
  };
  // The new facets meet along the boundary's edges: the directed edge (a, b) of one
  // new facet is (b, a) of its neighbour. edge(a, b) is the slot of (a, b).
  auto link = [&](auto&& edge) {
    for (std::size_t k = 0; k < count; ++k) {
      const TetId t = new_slots_[k];
      const int* fv = kFacetVertex[new_tets_[k].facet];
      const VertexId* tv = tets_[t].v;
      const std::uint32_t a = local_id(tv[fv[0]]), b = local_id(tv[fv[1]]), c = local_id(tv[fv[2]]);
      // Edge (a, b) lies in the new facet opposite c's position, and so on around.
      edge(a, b) = 4 * t + std::uint32_t(fv[2]);
      edge(b, c) = 4 * t + std::uint32_t(fv[0]);
      edge(c, a) = 4 * t + std::uint32_t(fv[1]);
      local_tet_[a] = t, local_tet_[b] = t, local_tet_[c] = t;
      local_ids_[k] = {a, b, c};
    }
    for (std::size_t k = 0; k < count; ++k) {
      Tet& tet = tets_[new_slots_[k]];
      const int* fv = kFacetVertex[new_tets_[k].facet];
      const auto [a, b, c] = local_ids_[k];
      tet.n[fv[2]] = edge(b, a);
      tet.n[fv[0]] = edge(c, b);
      tet.n[fv[1]] = edge(a, c);
    }
  };
  if (side <= kDenseEdgeSide) {
    // The common case: a dense table indexed by both local ids.
    if (edge_table_.size() < side * side) edge_table_.resize(side * side);
    FacetHandle* table = edge_table_.data();
    link([table, side](std::uint32_t a, std::uint32_t b) -> FacetHandle& { return table[a * side + b]; });
  } else {
    // A large cavity (flat regions make them: thousands of tets): a hash table of its
    // 3 count edges, at most half full. A dense table is quadratic in the cavity: a
    // terrain's 3,336-vertex cavity took 44 MB, and the kernel kept it for good.
    const std::size_t slots = std::bit_ceil(6 * count);
    if (edge_hash_.size() < slots) edge_hash_.resize(slots);
    std::fill_n(edge_hash_.begin(), slots, EdgeSlot{});
    EdgeSlot* table = edge_hash_.data();
    const std::size_t mask = slots - 1;
    link([table, mask](std::uint32_t a, std::uint32_t b) -> FacetHandle& {
      const std::uint64_t key = std::uint64_t(a) << 32 | b;
      for (std::size_t i = std::size_t((key * 0x9E3779B97F4A7C15ULL) >> 32) & mask;; i = (i + 1) & mask) {
        if (table[i].key == key) return table[i].facet;
        if (table[i].key == EdgeSlot::kEmpty) {
          table[i].key = key;
          return table[i].facet;
        }
      }
    });
  }
  // Restore order_, and give each boundary vertex one incident tet.
  for (std::uint32_t i = 1; i <= num_local; ++i) {
    order[local_internal[i]] = local_vertex[i];
    vertex_tet_[local_vertex[i]] = local_tet_[i];
  }
}

void Delaunay::insert_range(VertexId first, VertexId last) {
  const std::size_t n = last - first;
  const std::vector<std::uint32_t> order = hilbert_order(point(first), n);
  // Internal ids in Hilbert order (coordinates copied in that order), then insert.
  pts_.reserve(pts_.size() + 3 * n);
  order_.reserve(order_.size() + n);
  TetId hint = last_tet_;
  for (std::uint32_t i : order) {
    insert_internal(assign_internal(first + i), hint);
    hint = last_tet_;
  }
}

void Delaunay::star(VertexId v, std::vector<TetId>& out) const {
  const TetId start = v < vertex_tet_.size() ? vertex_tet_[v] : kNoTet;
  if (start == kNoTet) return;
  VertexId x = kNoVertex;  // v's internal id
  for (int i = 0; i < 4; ++i)
    if (to_caller(tets_[start].v[i]) == v) x = tets_[start].v[i];
  const std::size_t first = out.size();
  // Breadth-first over the tets around v, marked kVisited while the search runs
  // (no mark is set between insertions) and unmarked before returning.
  marks_.set(start, kVisited);
  out.push_back(start);
  for (std::size_t i = first; i < out.size(); ++i) {
    const Tet& t = tets_[out[i]];
    for (int f = 0; f < 4; ++f) {
      if (t.v[f] == x) continue;  // the facet opposite v does not hold v
      const TetId n = t.n[f] >> 2;
      if (marks_.get(n)) continue;
      marks_.set(n, kVisited);
      out.push_back(n);
    }
  }
  for (std::size_t i = first; i < out.size(); ++i) marks_.clear(out[i]);
}

bool Delaunay::strictly_inside(const double* p, TetId& hint) {
  const TetId t = locate(p, hint);
  hint = t;
  const VertexId* v = tets_[t].v;
  if (has_infinite_vertex(v)) return false;
  // The walk stopped where no facet has p strictly beyond it: p is in the closed tet.
  for (int f = 0; f < 4; ++f) {
    const int* fv = kFacetVertex[f];
    if (orient3d(ipoint(v[fv[0]]), ipoint(v[fv[1]]), ipoint(v[fv[2]]), p) <= 0) return false;
  }
  return true;
}

Circumsphere Delaunay::tet_circumsphere(TetId t) const {
  const VertexId* v = tets_[t].v;
  return circumsphere(ipoint(v[0]), ipoint(v[1]), ipoint(v[2]), ipoint(v[3]));
}

std::size_t Delaunay::memory_bytes() const {
  return tets_.size() * sizeof(Tet) + marks_.bits.capacity() * 8 + pts_.capacity() * sizeof(double) +
         order_.capacity() * sizeof(VertexId) + local_internal_.capacity() * sizeof(VertexId) +
         vertex_tet_.capacity() * sizeof(TetId) + duplicate_of_.size() * (2 * sizeof(VertexId) + 2 * sizeof(void*)) +
         duplicate_of_.bucket_count() * sizeof(void*) + cavity_.capacity() * sizeof(TetId) +
         rejected_.capacity() * sizeof(TetId) + new_tets_.capacity() * sizeof(NewTet) +
         new_slots_.capacity() * sizeof(TetId) + local_ids_.capacity() * sizeof(local_ids_[0]) +
         local_vertex_.capacity() * sizeof(VertexId) + local_tet_.capacity() * sizeof(TetId) +
         edge_table_.capacity() * sizeof(FacetHandle) + edge_hash_.capacity() * sizeof(EdgeSlot);
}

}  // namespace tetstream::core
