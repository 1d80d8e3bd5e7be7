#include "pipeline/rank_cost.hpp"

#include "core/delaunay.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tetstream::pipeline {

double block_cost_factor(const PointIndex& index, const PointRecords& points, std::uint64_t b) {
  constexpr std::uint32_t kSample = 2048;
  std::uint64_t inner = 0, huge = 0;
  std::vector<double> xyz, radii;
  for (const bool last : {false, true}) {
    const std::vector<std::uint64_t> labels = index.compact_sample(b, kSample, last);
    const std::size_t n = labels.size();
    if (n < 64) continue;
    xyz.resize(3 * n);
    double lo[3], hi[3];
    for (std::size_t i = 0; i < n; ++i) {
      points.xyz(labels[i], &xyz[3 * i]);
      for (int k = 0; k < 3; ++k) {
        lo[k] = i == 0 ? xyz[3 * i + k] : std::min(lo[k], xyz[3 * i + k]);
        hi[k] = i == 0 ? xyz[3 * i + k] : std::max(hi[k], xyz[3 * i + k]);
      }
    }
    core::Delaunay dt;
    if (dt.build(xyz.data(), labels.data(), n) != core::BuildStatus::kOk) continue;
    // Inner tets: every vertex in the middle half of the sample's box along its two
    // widest sides (the pilot's own hull makes flat tets at its edges whatever the
    // data; across a surface's thin side there is no edge to keep away from).
    int thin = 0;
    for (int k = 1; k < 3; ++k)
      if (hi[k] - lo[k] < hi[thin] - lo[thin]) thin = k;
    auto inside = [&](core::VertexId v) {
      const double* p = dt.point(v);
      for (int k = 0; k < 3; ++k) {
        if (k == thin) continue;
        const double q = (hi[k] - lo[k]) / 4;
        if (p[k] < lo[k] + q || p[k] > hi[k] - q) return false;
      }
      return true;
    };
    radii.clear();
    for (std::size_t t = 0; t < dt.num_tet_slots(); ++t) {
      const core::TetId id = core::TetId(t);
      if (!dt.is_alive(id) || dt.is_infinite(id)) continue;
      bool in = true;
      for (int i = 0; i < 4 && in; ++i) in = inside(dt.vertex(id, i));
      if (!in) continue;
      const core::Circumsphere s = dt.tet_circumsphere(id);
      radii.push_back(s.valid ? s.radius : std::numeric_limits<double>::infinity());
    }
    if (radii.size() < 16) continue;
    std::vector<double> sorted = radii;
    const auto mid = sorted.begin() + std::ptrdiff_t(sorted.size() / 2);
    std::nth_element(sorted.begin(), mid, sorted.end());
    const double limit = 8 * *mid;
    inner += radii.size();
    huge += std::uint64_t(std::count_if(radii.begin(), radii.end(), [&](double r) { return !(r <= limit); }));
  }
  return inner ? 1 + kFlatTetWeight * double(huge) / double(inner) : 1.0;
}

std::vector<double> expected_cost(const PointIndex& index, const PointRecords& points, std::uint64_t first,
                                  std::uint64_t last, std::uint64_t unit) {
  if (unit == 0 || first >= last) return {};
  std::vector<double> cost(std::size_t((last - first + unit - 1) / unit), 0.0);
  const std::uint64_t bp = index.block_points();
  for (std::uint64_t b = first / bp; b <= (last - 1) / bp && b < index.block_count(); ++b) {
    const double factor = block_cost_factor(index, points, b);
    // The block's labels within [first, last), unit by unit.
    const std::uint64_t a = std::max(first, b * bp), z = std::min(last, (b + 1) * bp);
    for (std::uint64_t at = a; at < z;) {
      const std::uint64_t u = (at - first) / unit, end = std::min(z, first + (u + 1) * unit);
      cost[std::size_t(u)] += factor * double(end - at);
      at = end;
    }
  }
  return cost;
}

}  // namespace tetstream::pipeline
