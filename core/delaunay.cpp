#include "core/delaunay.hpp"

#include "core/compiler.hpp"
#include "core/spatial_sort.hpp"

#include <algorithm>
#include <cassert>
#include <numeric>

namespace tetstream::core {

namespace {

// Measured: about 6.7 finite tets per point on uniform data, fewer on shells and
// grids; the infinite tets add O(n^(2/3)). A little headroom avoids one regrowth.
constexpr double kTetsPerPointEstimate = 6.9;

TS_FORCE_INLINE bool has_infinite_vertex(const VertexId* v) {
  return v[0] == kInfiniteVertex || v[1] == kInfiniteVertex || v[2] == kInfiniteVertex ||
         v[3] == kInfiniteVertex;
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

bool Delaunay::is_infinite(TetId t) const { return has_infinite_vertex(&tet_vertex_[4 * std::size_t(t)]); }

void Delaunay::set_points(const double* xyz, const std::uint64_t* labels, std::size_t n) {
  assert(n >= num_points_ && "points can be appended, never removed");
  xyz_ = xyz;
  labels_ = labels;
  const std::size_t old = num_points_;
  num_points_ = n;
  vertex_tet_.resize(n, kNoTet);
  duplicate_of_.resize(n);
  for (std::size_t i = old; i < n; ++i) duplicate_of_[i] = VertexId(i);
}

void Delaunay::reserve(std::size_t points) {
  // Tet ids stay below 2^31: link_new_tets() borrows the top bit of vertex_tet_.
  assert(double(points) * kTetsPerPointEstimate < double(1u << 31));
  const std::size_t tets = std::size_t(double(points) * kTetsPerPointEstimate) + 64;
  tet_vertex_.reserve(4 * tets);
  tet_neighbor_.reserve(4 * tets);
  tet_flags_.reserve(tets);
  vertex_tet_.reserve(points);
  duplicate_of_.reserve(points);
}

void Delaunay::reset() {
  tet_vertex_.clear();
  tet_neighbor_.clear();
  tet_flags_.clear();
  free_head_ = kNoTet;
  num_alive_ = num_infinite_ = 0;
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
  edge_table_.assign(64 * 64, kNoTet);
}

BuildStatus Delaunay::build(const double* xyz, const std::uint64_t* labels, std::size_t n) {
  reset();
  // The order is computed before the tet arrays are reserved, so its temporary
  // keys never coexist with them: peak memory stays that of the tets.
  std::vector<std::uint32_t> order = brio_order(xyz, n);
  reserve(n);
  set_points(xyz, labels, n);

  std::uint32_t used[4];
  if (!make_initial_tet(order, used)) {
    reset();
    set_points(xyz, labels, n);
    return BuildStatus::kTooFewPoints;
  }
  TetId hint = last_tet_;
  for (std::uint32_t v : order) {
    if (v == used[0] || v == used[1] || v == used[2] || v == used[3]) continue;
    insert(v, hint);
    hint = last_tet_;
  }
  return BuildStatus::kOk;
}

// Finds four affinely independent points early in the insertion order and builds
// the first finite tet and its four infinite neighbours.
bool Delaunay::make_initial_tet(const std::vector<std::uint32_t>& order, std::uint32_t used[4]) {
  const std::size_t n = order.size();
  if (n < 4) return false;
  const VertexId a = order[0];
  const double* pa = point(a);
  std::size_t i = 1;
  while (i < n && same_point(point(order[i]), pa)) ++i;
  if (i == n) return false;
  const VertexId b = order[i];
  const double* pb = point(b);
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
  while (j < n && collinear(point(order[j]))) ++j;
  if (j >= n) return false;
  VertexId c = order[j];
  std::size_t k = j + 1;
  int sign = 0;
  while (k < n && (sign = orient3d(pa, pb, point(c), point(order[k]))) == 0) ++k;
  if (k >= n) return false;
  VertexId d = order[k];
  VertexId bb = b;
  if (sign < 0) std::swap(bb, c);  // make (a, bb, c, d) positively oriented

  // Slot 0: the finite tet. Slots 1..4: the infinite tet across facet f of slot 0,
  // made of facet f's vertices in reverse order (so the hull's interior is on the
  // negative side of it, as the anatomy requires) and the infinite vertex last.
  const VertexId fin[4] = {a, bb, c, d};
  tet_vertex_.assign(fin, fin + 4);
  tet_neighbor_.assign(4, 0);
  tet_flags_.assign(1, kAlive);
  for (int f = 0; f < 4; ++f) {
    const VertexId inf[4] = {fin[kFacetVertex[f][0]], fin[kFacetVertex[f][2]], fin[kFacetVertex[f][1]],
                             kInfiniteVertex};
    tet_vertex_.insert(tet_vertex_.end(), inf, inf + 4);
    tet_neighbor_.insert(tet_neighbor_.end(), 4, 0);
    tet_flags_.push_back(kAlive);
    tet_neighbor_[f] = 4 * (1 + f) + 3;
    tet_neighbor_[4 * (1 + f) + 3] = f;
  }
  // The infinite tets meet each other along the facets that hold the infinite
  // vertex: match them by their vertex sets (16 facets, once).
  for (int s = 1; s <= 4; ++s)
    for (int f = 0; f < 3; ++f)
      for (int s2 = s + 1; s2 <= 4; ++s2)
        for (int f2 = 0; f2 < 3; ++f2) {
          VertexId x[3], y[3];
          for (int m = 0; m < 3; ++m) {
            x[m] = tet_vertex_[4 * s + kFacetVertex[f][m]];
            y[m] = tet_vertex_[4 * s2 + kFacetVertex[f2][m]];
          }
          std::sort(x, x + 3);
          std::sort(y, y + 3);
          if (std::equal(x, x + 3, y)) {
            tet_neighbor_[4 * s + f] = 4 * s2 + f2;
            tet_neighbor_[4 * s2 + f2] = 4 * s + f;
          }
        }
  num_alive_ = 5;
  num_infinite_ = 4;
  for (VertexId v : fin) vertex_tet_[v] = 0;
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
  if (t == kNoTet || tet_flags_[t] == kFreeFlag) t = last_tet_;
  {
    const VertexId* v = &tet_vertex_[4 * std::size_t(t)];
    const int i = infinite_position(v);
    if (i >= 0) t = tet_neighbor_[4 * t + i] >> 2;  // the finite tet behind the hull facet
  }
  int came_from = -1;
  for (;;) {
    ++stats_.walk_steps;
    const VertexId* v = &tet_vertex_[4 * std::size_t(t)];
    if (has_infinite_vertex(v)) return t;
    walk_rng_ ^= walk_rng_ << 13, walk_rng_ ^= walk_rng_ >> 7, walk_rng_ ^= walk_rng_ << 17;
    const int r = int(walk_rng_ >> 62);
    bool moved = false;
    for (int k = 0; k < 4; ++k) {
      const int f = (r + k) & 3;
      if (f == came_from) continue;
      const int* fv = kFacetVertex[f];
      if (orient3d(point(v[fv[0]]), point(v[fv[1]]), point(v[fv[2]]), p) < 0) {
        const FacetHandle h = tet_neighbor_[4 * t + f];
        t = h >> 2;
        came_from = int(h & 3);
        moved = true;
        break;
      }
    }
    if (!moved) return t;
  }
}

bool Delaunay::in_conflict(TetId t, const double* p, std::uint64_t lp) const {
  const VertexId* v = &tet_vertex_[4 * std::size_t(t)];
  const int i = infinite_position(v);
  if (i < 0) {
    return insphere_sos(point(v[0]), point(v[1]), point(v[2]), point(v[3]), p, label(v[0]), label(v[1]),
                        label(v[2]), label(v[3]), lp) > 0;
  }
  const VertexId a = v[kFacetVertex[i][0]], b = v[kFacetVertex[i][1]], c = v[kFacetVertex[i][2]];
  return infinite_conflict_sos(point(a), point(b), point(c), p, label(a), label(b), label(c), lp) > 0;
}

TetId Delaunay::new_tet_slot() {
  if (free_head_ != kNoTet) {
    const TetId t = free_head_;
    free_head_ = tet_neighbor_[4 * std::size_t(t)];
    return t;
  }
  const TetId t = TetId(tet_flags_.size());
  tet_vertex_.resize(tet_vertex_.size() + 4);
  tet_neighbor_.resize(tet_neighbor_.size() + 4);
  tet_flags_.push_back(kFreeFlag);
  return t;
}

void Delaunay::free_tet_slot(TetId t) {
  tet_flags_[t] = kFreeFlag;
  tet_neighbor_[4 * std::size_t(t)] = free_head_;
  free_head_ = t;
}

InsertOutcome Delaunay::insert(VertexId v, TetId hint) {
  const double* p = point(v);
  const std::uint64_t lp = label(v);
  const TetId start = locate(p, hint);

  // A point inside (or on) a finite tet that equals one of its vertices is a duplicate.
  {
    const VertexId* tv = &tet_vertex_[4 * std::size_t(start)];
    if (!has_infinite_vertex(tv)) {
      for (int i = 0; i < 4; ++i)
        if (same_point(point(tv[i]), p)) {
          duplicate_of_[v] = tv[i];
          ++stats_.duplicates;
          return InsertOutcome::kDuplicate;
        }
    }
  }

  // Cavity: the tets whose (perturbed) circumball contains p, grown from the
  // located tet, which always is one (p lies in its closed tet, hence strictly in
  // its ball, or strictly beyond its hull facet). The cavity is connected and
  // star-shaped from p, so a breadth-first search over neighbours finds it.
  cavity_.clear();
  rejected_.clear();
  new_tets_.clear();
  tet_flags_[start] = kInCavity;
  cavity_.push_back(start);
  for (std::size_t i = 0; i < cavity_.size(); ++i) {
    const TetId c = cavity_[i];
    for (int f = 0; f < 4; ++f) {
      const FacetHandle h = tet_neighbor_[4 * std::size_t(c) + f];
      const TetId n = h >> 2;
      const std::uint8_t flag = tet_flags_[n];
      if (flag == kInCavity) continue;
      if (flag == kAlive && in_conflict(n, p, lp)) {
        tet_flags_[n] = kInCavity;
        cavity_.push_back(n);
        continue;
      }
      if (flag == kAlive) {
        tet_flags_[n] = kNotInConflict;
        rejected_.push_back(n);
      }
      // Boundary facet: the new tet is c with its vertex f replaced by v, which
      // keeps the orientation because v sees this facet from c's side.
      NewTet nt;
      const VertexId* cv = &tet_vertex_[4 * std::size_t(c)];
      nt.v[0] = cv[0], nt.v[1] = cv[1], nt.v[2] = cv[2], nt.v[3] = cv[3];
      nt.v[f] = v;
      nt.outer = h;
      nt.facet = std::uint32_t(f);
      new_tets_.push_back(nt);
    }
  }
  for (TetId t : rejected_) tet_flags_[t] = kAlive;
  stats_.cavity_tets += cavity_.size();

  // Release the cavity's slots (they are reused first by the new tets).
  for (TetId t : cavity_) {
    if (has_infinite_vertex(&tet_vertex_[4 * std::size_t(t)])) --num_infinite_;
    free_tet_slot(t);
  }
  num_alive_ -= cavity_.size();

  new_slots_.clear();
  for (const NewTet& nt : new_tets_) {
    const TetId t = new_tet_slot();
    new_slots_.push_back(t);
    VertexId* tv = &tet_vertex_[4 * std::size_t(t)];
    tv[0] = nt.v[0], tv[1] = nt.v[1], tv[2] = nt.v[2], tv[3] = nt.v[3];
    tet_flags_[t] = kAlive;
    const FacetHandle self = 4 * t + nt.facet;
    tet_neighbor_[self] = nt.outer;
    tet_neighbor_[nt.outer] = self;
    num_infinite_ += has_infinite_vertex(tv);
  }
  num_alive_ += new_tets_.size();
  link_new_tets(new_tets_.size());

  last_tet_ = new_slots_.back();
  ++num_vertices_;
  ++stats_.inserted;
  return InsertOutcome::kInserted;
}

// The new tets meet each other across the facets that hold the new point. Such a
// facet is the new point plus one edge of the cavity boundary, and each boundary
// edge belongs to exactly two boundary facets. The boundary's vertices get small
// local numbers (kept for the moment in vertex_tet_, tagged by the top bit, which
// no tet id uses), so an edge indexes a small square table directly: the first
// facet to see an edge parks its handle there, the second links the two and clears
// the entry, which leaves the table empty for the next insertion.
void Delaunay::link_new_tets(std::size_t count) {
  constexpr TetId kLocalTag = 0x80000000u;
  std::uint32_t num_local = 0;
  auto local_id = [&](VertexId x) -> std::uint32_t {
    if (x == kInfiniteVertex) return 0;  // local 0 is the infinite vertex
    TetId& slot = vertex_tet_[x];
    if (!(slot & kLocalTag)) slot = kLocalTag | ++num_local;
    return slot & ~kLocalTag;
  };
  // The boundary is a triangulated sphere: count = 2 V - 4 triangles on V vertices,
  // so V = count / 2 + 2 bounds the local ids (plus 0 for the infinite vertex).
  const std::size_t side = count / 2 + 3;
  if (edge_table_.size() < side * side) edge_table_.assign(side * side, kNoTet);
  for (std::size_t k = 0; k < count; ++k) {
    const TetId t = new_slots_[k];
    const int f = int(new_tets_[k].facet);
    const VertexId* tv = &tet_vertex_[4 * std::size_t(t)];
    std::uint32_t id[4];
    for (int m = 0; m < 4; ++m) id[m] = m == f ? 0 : local_id(tv[m]);
    for (int g = 0; g < 4; ++g) {
      if (g == f) continue;
      // The edge is made of the two positions other than f and g.
      const int a = kOtherPositions[f][g][0], b = kOtherPositions[f][g][1];
      const std::uint32_t lo = std::min(id[a], id[b]), hi = std::max(id[a], id[b]);
      FacetHandle& entry = edge_table_[lo * side + hi];
      const FacetHandle self = 4 * t + std::uint32_t(g);
      if (entry == kNoTet) {
        entry = self;
      } else {
        tet_neighbor_[self] = entry;
        tet_neighbor_[entry] = self;
        entry = kNoTet;
      }
    }
  }
  // Give vertex_tet_ back its meaning: one incident tet per vertex.
  for (std::size_t k = 0; k < count; ++k) {
    const TetId t = new_slots_[k];
    const VertexId* tv = &tet_vertex_[4 * std::size_t(t)];
    for (int m = 0; m < 4; ++m)
      if (tv[m] != kInfiniteVertex) vertex_tet_[tv[m]] = t;
  }
}

void Delaunay::insert_range(VertexId first, VertexId last) {
  const std::size_t n = last - first;
  std::vector<std::uint32_t> order = hilbert_order(point(first), n);
  TetId hint = last_tet_;
  for (std::uint32_t i : order) {
    insert(first + i, hint);
    hint = last_tet_;
  }
}

void Delaunay::star(VertexId v, std::vector<TetId>& out) const {
  const TetId start = vertex_tet_[v];
  if (start == kNoTet) return;
  const std::size_t first = out.size();
  // Breadth-first over the tets around v, marked in tet_flags_ while the search runs
  // (every alive tet is kAlive between insertions) and unmarked before returning.
  tet_flags_[start] = kStarMark;
  out.push_back(start);
  for (std::size_t i = first; i < out.size(); ++i) {
    const TetId t = out[i];
    const VertexId* tv = &tet_vertex_[4 * std::size_t(t)];
    for (int f = 0; f < 4; ++f) {
      if (tv[f] == v) continue;  // the facet opposite v does not hold v
      const TetId n = tet_neighbor_[4 * std::size_t(t) + f] >> 2;
      if (tet_flags_[n] == kStarMark) continue;
      tet_flags_[n] = kStarMark;
      out.push_back(n);
    }
  }
  for (std::size_t i = first; i < out.size(); ++i) tet_flags_[out[i]] = kAlive;
}

Circumsphere Delaunay::tet_circumsphere(TetId t) const {
  const VertexId* v = &tet_vertex_[4 * std::size_t(t)];
  return circumsphere(point(v[0]), point(v[1]), point(v[2]), point(v[3]));
}

std::size_t Delaunay::memory_bytes() const {
  return tet_vertex_.capacity() * sizeof(VertexId) + tet_neighbor_.capacity() * sizeof(FacetHandle) +
         tet_flags_.capacity() + vertex_tet_.capacity() * sizeof(TetId) +
         duplicate_of_.capacity() * sizeof(VertexId) + cavity_.capacity() * sizeof(TetId) +
         rejected_.capacity() * sizeof(TetId) + new_tets_.capacity() * sizeof(NewTet) +
         new_slots_.capacity() * sizeof(TetId) + edge_table_.capacity() * sizeof(FacetHandle);
}

}  // namespace tetstream::core
