#include "pipeline/sort/hull.hpp"

#include "core/facet_plane.hpp"

#include "core/delaunay.hpp"
#include "core/predicates.hpp"
#include "core/spatial_sort.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace tetstream::pipeline {

using core::FacetPlane;

namespace {

// An axis-aligned box strictly inside the extremes' hull (all eight corners are,
// checked exactly; the box is their hull): a point in it needs no facet test. On a
// cube or a ball most points are in it; on a thin shell none are, and it costs
// nothing. Empty (contains nothing) when no such box was found.
struct InnerBox {
  double lo[3] = {1, 1, 1}, hi[3] = {0, 0, 0};
  bool contains(const double* p) const {
    return p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1] && p[2] >= lo[2] && p[2] <= hi[2];
  }
};

// The box around the extremes' centroid with the points' box's proportions, as large
// as the facet planes allow (scaled by 0.99, for the rounding of the planes).
InnerBox inscribed_box(const std::vector<FacetPlane>& facets, const std::vector<double>& extremes, const double* lo,
                       const double* hi) {
  InnerBox box;
  const std::size_t m = extremes.size() / 3;
  double center[3] = {0, 0, 0}, half[3];
  for (std::size_t i = 0; i < m; ++i)
    for (int k = 0; k < 3; ++k) center[k] += extremes[3 * i + k] / double(m);
  for (int k = 0; k < 3; ++k) half[k] = (hi[k] - lo[k]) / 2;
  double scale = 1;
  for (const FacetPlane& f : facets) {
    // The corner farthest along n reaches n.(center - a) + scale * sum |n_k| half_k.
    const double depth = -f.value(center),
                 reach = std::fabs(f.n[0]) * half[0] + std::fabs(f.n[1]) * half[1] + std::fabs(f.n[2]) * half[2];
    if (!(depth > 0)) return box;
    if (reach > 0) scale = std::min(scale, depth / reach);
  }
  scale *= 0.99;
  InnerBox candidate;
  for (int k = 0; k < 3; ++k)
    candidate.lo[k] = center[k] - scale * half[k], candidate.hi[k] = center[k] + scale * half[k];
  for (int corner = 0; corner < 8; ++corner) {
    double q[3];
    for (int k = 0; k < 3; ++k) q[k] = (corner >> k & 1) ? candidate.hi[k] : candidate.lo[k];
    for (const FacetPlane& f : facets)
      if (core::orient3d(f.a, f.b, f.c, q) >= 0) return box;
  }
  return candidate;
}

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

// The coordinates of the points `indices` of xyz, packed (3 doubles each).
std::vector<double> gather(const double* xyz, const std::vector<std::uint32_t>& indices) {
  std::vector<double> out(3 * indices.size());
  for (std::size_t i = 0; i < indices.size(); ++i) std::copy_n(xyz + 3 * std::size_t(indices[i]), 3, &out[3 * i]);
  return out;
}

// The survivors of the extremes' filter that are not strictly inside the hull of a
// sample of them: a point strictly inside one of the sample's tets is strictly inside
// conv(points). On a thin shell most points pass the extremes' filter, and
// triangulating them all would double the sort phase: a sample's hull hugs the
// shell's outer side, and a walk in its triangulation (the points in Hilbert order:
// a few steps each) costs a fraction of an insertion.
// (The default sample, 16384 points, triangulates in a few MiB.)
std::vector<std::uint32_t> outside_sample_hull(const double* xyz, const std::vector<std::uint32_t>& survivors,
                                               std::size_t sample_points) {
  const std::size_t m = survivors.size();
  if (sample_points == 0 || m < 4 * sample_points) return survivors;
  const std::vector<double> sv = gather(xyz, survivors);
  std::vector<std::uint32_t> picks;  // every stride-th survivor, by its position in sv
  for (std::size_t i = 0, stride = m / sample_points; i < m; i += stride) picks.push_back(std::uint32_t(i));
  const std::vector<double> sample = gather(sv.data(), picks);
  core::Delaunay dt;
  if (dt.build(sample.data(), nullptr, picks.size()) != core::BuildStatus::kOk) return survivors;
  std::vector<std::uint8_t> keep(m, 1);
  core::TetId hint = core::kNoTet;
  for (const std::uint32_t i : core::hilbert_order(sv.data(), m))
    keep[i] = !dt.strictly_inside(&sv[3 * std::size_t(i)], hint);
  std::vector<std::uint32_t> out;
  for (std::size_t i = 0; i < m; ++i)
    if (keep[i]) out.push_back(survivors[i]);
  return out;
}

}  // namespace

std::vector<std::uint32_t> hull_vertex_candidates(const double* xyz, std::size_t n, std::size_t sample_points) {
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
  // The points' box, from the extremes along the axes (their dot products are the
  // coordinates, exactly), and a bound on |p_k - q_k| for the facet planes.
  double lo[3], hi[3], extent[3];
  for (int d = 0; d < nd; ++d) {
    const int nonzero = std::abs(dir[d][0]) + std::abs(dir[d][1]) + std::abs(dir[d][2]);
    if (nonzero != 1) continue;
    const int k = dir[d][0] != 0 ? 0 : dir[d][1] != 0 ? 1 : 2;
    if (dir[d][k] > 0)
      hi[k] = best_dot[d];
    else
      lo[k] = -best_dot[d];
  }
  for (int k = 0; k < 3; ++k) extent[k] = (hi[k] - lo[k]) * (1 + 0x1p-50);
  std::vector<std::uint32_t> extreme(best, best + 26);
  std::sort(extreme.begin(), extreme.end());
  extreme.resize(std::size_t(std::unique(extreme.begin(), extreme.end()) - extreme.begin()));

  const std::vector<double> ex = gather(xyz, extreme);
  core::Delaunay inner;
  std::vector<std::uint32_t> survivors;
  if (inner.build(ex.data(), nullptr, extreme.size()) == core::BuildStatus::kOk) {
    // The hull facets of the extremes, seen with the interior on their negative side;
    // a point strictly inside all of them is not a vertex.
    std::vector<FacetPlane> facets;
    for (std::size_t t = 0; t < inner.num_tet_slots(); ++t) {
      if (!inner.is_alive(core::TetId(t)) || !inner.is_infinite(core::TetId(t))) continue;
      int inf = 0;
      while (inner.vertex(core::TetId(t), inf) != core::kInfiniteVertex) ++inf;
      const double* v[3];
      for (int m = 0; m < 3; ++m) v[m] = inner.point(inner.vertex(core::TetId(t), core::kFacetVertex[inf][m]));
      facets.push_back(FacetPlane(v[0], v[1], v[2], extent));
    }
    const InnerBox box = inscribed_box(facets, ex, lo, hi);
    for (std::size_t i = 0; i < n; ++i) {
      const double* p = xyz + 3 * i;
      if (box.contains(p)) continue;
      bool strictly_inside = true;
      for (std::size_t f = 0; f < facets.size() && strictly_inside; ++f) strictly_inside = facets[f].strictly_below(p);
      if (!strictly_inside) survivors.push_back(std::uint32_t(i));
    }
  } else {
    survivors = all;
  }
  survivors = outside_sample_hull(xyz, survivors, sample_points);

  const std::vector<double> sv = gather(xyz, survivors);
  core::Delaunay dt;
  if (dt.build(sv.data(), nullptr, survivors.size()) != core::BuildStatus::kOk) return survivors;
  return kernel_hull_vertices(dt, survivors);
}

std::vector<LabelTriple> hull_facet_labels(const double* xyz, const std::uint64_t* labels, std::size_t n) {
  std::vector<LabelTriple> facets;
  core::Delaunay dt;
  if (n < 4 || dt.build(xyz, labels, n) != core::BuildStatus::kOk) return facets;
  // The infinite tets are the hull facets, one each.
  for (std::size_t t = 0; t < dt.num_tet_slots(); ++t) {
    const auto id = core::TetId(t);
    if (!dt.is_alive(id) || !dt.is_infinite(id)) continue;
    LabelTriple f{};
    int m = 0;
    for (int i = 0; i < 4; ++i)
      if (dt.vertex(id, i) != core::kInfiniteVertex) f[std::size_t(m++)] = dt.label(dt.vertex(id, i));
    std::sort(f.begin(), f.end());
    facets.push_back(f);
  }
  std::sort(facets.begin(), facets.end());
  return facets;
}

}  // namespace tetstream::pipeline
