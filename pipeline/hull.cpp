#include "pipeline/hull.hpp"

#include "core/delaunay.hpp"
#include "core/predicates.hpp"

#include <algorithm>
#include <limits>
#include <numeric>

namespace tetstream::pipeline {

namespace {

// Indices of the vertices of the kernel's hull (points incident to an infinite tet),
// ascending, mapped through `index`.
std::vector<std::uint32_t> kernel_hull_vertices(const core::Delaunay& dt, const std::vector<std::uint32_t>& index) {
  std::vector<std::uint32_t> out;
  for (std::size_t t = 0; t < dt.num_tet_slots(); ++t) {
    if (!dt.is_alive(core::TetId(t)) || !dt.is_infinite(core::TetId(t))) continue;
    for (int i = 0; i < 4; ++i) {
      const core::VertexId v = dt.vertex(core::TetId(t), i);
      if (v != core::kInfiniteVertex) out.push_back(index[v]);
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace

std::vector<std::uint32_t> hull_vertex_candidates(const double* xyz, std::size_t n) {
  std::vector<std::uint32_t> all(n);
  std::iota(all.begin(), all.end(), 0u);
  if (n < 4) return all;

  // The extreme point in each of the 26 directions of {-1,0,1}^3 \ {0}, in one pass.
  int dir[26][3];
  int nd = 0;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz)
        if (dx != 0 || dy != 0 || dz != 0) dir[nd][0] = dx, dir[nd][1] = dy, dir[nd][2] = dz, ++nd;
  std::uint32_t best[26] = {};
  double best_dot[26];
  std::fill(best_dot, best_dot + 26, -std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < n; ++i) {
    const double* p = xyz + 3 * i;
    for (int d = 0; d < 26; ++d) {
      const double dot = dir[d][0] * p[0] + dir[d][1] * p[1] + dir[d][2] * p[2];
      if (dot > best_dot[d]) best_dot[d] = dot, best[d] = std::uint32_t(i);
    }
  }
  std::vector<std::uint32_t> extreme(best, best + 26);
  std::sort(extreme.begin(), extreme.end());
  extreme.erase(std::unique(extreme.begin(), extreme.end()), extreme.end());

  std::vector<double> ex(3 * extreme.size());
  for (std::size_t i = 0; i < extreme.size(); ++i)
    std::copy_n(xyz + 3 * std::size_t(extreme[i]), 3, &ex[3 * i]);
  core::Delaunay inner;
  std::vector<std::uint32_t> survivors;
  if (inner.build(ex.data(), nullptr, extreme.size()) == core::BuildStatus::kOk) {
    // The hull facets of the extremes, as point triples seen with the interior on
    // their negative side; a point strictly inside all of them is not a vertex.
    std::vector<const double*> facets;
    for (std::size_t t = 0; t < inner.num_tet_slots(); ++t) {
      if (!inner.is_alive(core::TetId(t)) || !inner.is_infinite(core::TetId(t))) continue;
      int inf = 0;
      while (inner.vertex(core::TetId(t), inf) != core::kInfiniteVertex) ++inf;
      for (int m = 0; m < 3; ++m) facets.push_back(inner.point(inner.vertex(core::TetId(t), core::kFacetVertex[inf][m])));
    }
    for (std::size_t i = 0; i < n; ++i) {
      const double* p = xyz + 3 * i;
      bool strictly_inside = true;
      for (std::size_t f = 0; f < facets.size() && strictly_inside; f += 3)
        strictly_inside = core::orient3d(facets[f], facets[f + 1], facets[f + 2], p) < 0;
      if (!strictly_inside) survivors.push_back(std::uint32_t(i));
    }
  } else {
    survivors = all;
  }

  std::vector<double> sv(3 * survivors.size());
  for (std::size_t i = 0; i < survivors.size(); ++i)
    std::copy_n(xyz + 3 * std::size_t(survivors[i]), 3, &sv[3 * i]);
  core::Delaunay dt;
  if (dt.build(sv.data(), nullptr, survivors.size()) != core::BuildStatus::kOk) return survivors;
  return kernel_hull_vertices(dt, survivors);
}

}  // namespace tetstream::pipeline
