#pragma once
// Exact point location in a tetrahedralization given as index arrays (the layout of the
// Python package's Triangulation and of the C++ API: 4 vertex indices per tet,
// positively oriented, and 4 neighbours, the tet across the facet opposite each vertex,
// negative on the hull):
//
//   core::locate_points<std::int64_t>(points, simplices, neighbors, m, vertex_tet,
//                                     npoints, queries, q, out, threads);
//
// out[i] is the tet holding query i (inside or on its boundary), -1 outside the convex
// hull or for a non-finite query. Every test is the exact orient3d, so no query is
// lost between tets. The queries are taken in Hilbert order (core/spatial_sort.hpp), and
// each is found by a walk across facets from the tet of the query before it, so a walk
// takes a few steps; the order is split into one contiguous run per thread.
#include "core/predicates.hpp"
#include "core/spatial_sort.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace tetstream::core {

namespace locate_detail {

// A C-contiguous (rows, cols) view of an integer array of type I.
template <class I>
struct Table {
  const I* data = nullptr;
  std::size_t rows = 0;
  const I* row(std::size_t r) const { return data + 4 * r; }
};

// The walk. Each step tests the facets of tet t (but the one it came through) in an
// order that rotates with a cheap generator (a remembering stochastic walk, which ends
// in any triangulation; in a Delaunay one a fixed order would too): facet j is crossed
// when xi lies strictly beyond it, that is when the tet with xi in vertex j's place is
// negatively oriented. A tet with no such facet holds xi (inside or on its boundary);
// a hull facet with xi beyond it means xi is outside the convex hull, since every hull
// facet spans a supporting plane of the hull.
template <class I>
class Walker {
 public:
  Walker(const double* points, Table<I> simplices, Table<I> neighbors)
      : points_(points), s_(simplices), nb_(neighbors) {}

  // The tet holding q, or -1 outside; `start` is the tet to walk from and becomes the
  // last tet visited (a good start for the next, nearby query).
  std::int64_t locate(const double* q, std::int64_t& start, std::uint64_t& rng) const {
    if (!std::isfinite(q[0]) || !std::isfinite(q[1]) || !std::isfinite(q[2])) return -1;
    std::int64_t t = start;
    int entered = -1;  // the facet of t it came through: xi is on t's side of it
    // In a Delaunay triangulation the walk visits each tet at most once; past that
    // many steps something is off (a triangulation that is not the one we made), and
    // an exhaustive search answers instead.
    for (std::size_t steps = 0; steps <= s_.rows; ++steps) {
      const I* v = s_.row(std::size_t(t));
      rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
      const int first = int(rng & 3);
      int cross = -1;
      for (int k = 0; k < 4; ++k) {
        const int j = (first + k) & 3;
        if (j == entered) continue;
        const double* p[4] = {pt(v[0]), pt(v[1]), pt(v[2]), pt(v[3])};
        p[j] = q;
        if (core::orient3d(p[0], p[1], p[2], p[3]) < 0) {
          cross = j;
          break;
        }
      }
      if (cross < 0) {
        start = t;
        return t;
      }
      const std::int64_t next = std::int64_t(nb_.row(std::size_t(t))[cross]);
      if (next < 0) {
        start = t;
        return -1;
      }
      const I* back = nb_.row(std::size_t(next));
      entered = -1;
      for (int j = 0; j < 4; ++j)
        if (std::int64_t(back[j]) == t) entered = j;
      t = next;
    }
    return exhaustive(q, start);
  }

 private:
  const double* pt(I v) const { return points_ + 3 * std::size_t(v); }

  std::int64_t exhaustive(const double* q, std::int64_t& start) const {
    for (std::size_t t = 0; t < s_.rows; ++t) {
      const I* v = s_.row(t);
      bool inside = true;
      for (int j = 0; j < 4 && inside; ++j) {
        const double* p[4] = {pt(v[0]), pt(v[1]), pt(v[2]), pt(v[3])};
        p[j] = q;
        inside = core::orient3d(p[0], p[1], p[2], p[3]) >= 0;
      }
      if (inside) {
        start = std::int64_t(t);
        return std::int64_t(t);
      }
    }
    return -1;
  }

  const double* points_;
  Table<I> s_, nb_;
};

}  // namespace locate_detail

// points: 3 doubles per point; simplices, neighbors: 4 per tet (m tets); vertex_tet: a
// tet of each point, negative for none (a start for the walks); queries: 3 doubles each.
template <class I, class R>
void locate_points(const double* points, const I* simplices, const I* neighbors, std::size_t m, const I* vertex_tet,
                   std::size_t npoints, const double* xi, std::size_t nq, R* out, int threads) {
  using namespace locate_detail;
  if (m == 0) {
    std::fill(out, out + nq, R(-1));
    return;
  }
  const Walker<I> walker(points, Table<I>{simplices, m}, Table<I>{neighbors, m});
  // (Non-finite queries, answered -1, are keyed as the origin.)
  std::vector<std::uint32_t> order;
  if (std::all_of(xi, xi + 3 * nq, [](double c) { return std::isfinite(c); })) {
    order = hilbert_order(xi, nq);
  } else {
    std::vector<double> finite(xi, xi + 3 * nq);
    for (double& c : finite)
      if (!std::isfinite(c)) c = 0;
    order = hilbert_order(finite.data(), nq);
  }
  // A start for each thread's first query: the tet of the vertex nearest to it among a
  // few spread over the input (a short first walk; later ones start nearby anyway).
  std::vector<std::size_t> probes;
  for (std::size_t k = 0; k < 64 && k < npoints; ++k) {
    const std::size_t v = k * npoints / std::min<std::size_t>(64, npoints);
    if (vertex_tet[v] >= 0) probes.push_back(v);
  }
  const int team = threads > 0 ? threads : omp_get_max_threads();
#pragma omp parallel num_threads(team)
  {
    const std::size_t tid = std::size_t(omp_get_thread_num()), nt = std::size_t(omp_get_num_threads());
    const std::size_t lo = nq * tid / nt, hi = nq * (tid + 1) / nt;
    std::uint64_t rng = 0x9E3779B97F4A7C15ull ^ (tid + 1);
    std::int64_t start = 0;
    if (lo < hi) {
      const double* q = xi + 3 * std::size_t(order[lo]);
      double best = std::numeric_limits<double>::infinity();
      for (const std::size_t v : probes) {
        const double* p = points + 3 * v;
        const double d = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) + (p[2] - q[2]) * (p[2] - q[2]);
        if (d < best) best = d, start = std::int64_t(vertex_tet[v]);
      }
    }
    for (std::size_t k = lo; k < hi; ++k) {
      const std::size_t i = order[k];
      out[i] = R(walker.locate(xi + 3 * i, start, rng));
    }
  }
}

}  // namespace tetstream::core
