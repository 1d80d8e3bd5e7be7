#include "pipeline/distributed/rank_cost.hpp"

#include "core/delaunay.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

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

std::vector<std::uint64_t> rank_label_bounds(std::uint64_t count, std::uint64_t block, int ranks,
                                             std::uint64_t rank0_done, const std::vector<std::uint64_t>& costs) {
  const std::uint64_t k = std::uint64_t(std::max(ranks, 1));
  const std::uint64_t blocks = block ? (count + block - 1) / block : 0;
  if (!costs.empty() && costs.size() != blocks) throw std::logic_error("rank_label_bounds: a cost a block");
  // prefix[i]: the cost of blocks [0, i) (i itself without costs).
  std::vector<std::uint64_t> prefix(std::size_t(blocks) + 1, 0);
  for (std::uint64_t i = 0; i < blocks; ++i)
    prefix[std::size_t(i) + 1] = prefix[std::size_t(i)] + (costs.empty() ? 1 : costs[std::size_t(i)]);
  // The block boundary in [from, to] whose cost from `from` is nearest part j of
  // `parts` of the cost of [from, to) (the lower one on a tie), in exact integers.
  auto cut = [&](std::uint64_t from, std::uint64_t to, std::uint64_t parts, std::uint64_t j) {
    if (j == 0 || j == parts) return j == 0 ? from : to;
    using Wide = unsigned __int128;
    const std::uint64_t base = prefix[std::size_t(from)];
    const Wide target = Wide(prefix[std::size_t(to)] - base) * j;  // times parts, like the candidates below
    const auto first = prefix.begin() + std::ptrdiff_t(from), end = prefix.begin() + std::ptrdiff_t(to) + 1;
    // The first boundary at or past the target, and the one before it.
    auto it = std::partition_point(first, end, [&](std::uint64_t p) { return Wide(p - base) * parts < target; });
    if (it == end) --it;
    if (it != first) {
      const Wide over = Wide(*it - base) * parts - target, under = target - Wide(*(it - 1) - base) * parts;
      if (under <= over) --it;
    }
    return std::uint64_t(it - prefix.begin());
  };
  std::vector<std::uint64_t> bounds(k + 1);
  for (std::uint64_t r = 0; r <= k; ++r) bounds[r] = std::min(count, cut(0, blocks, k, r) * block);
  if (k == 1 || rank0_done <= bounds[1]) return bounds;
  // Rank 0 keeps its blocks up to the one that holds the end of its frames; the others
  // share the blocks after it.
  const std::uint64_t first = std::min(blocks, (rank0_done + block - 1) / block);
  bounds[1] = std::min(count, first * block);
  for (std::uint64_t r = 1; r <= k; ++r) bounds[r] = std::min(count, cut(first, blocks, k - 1, r - 1) * block);
  return bounds;
}

}  // namespace tetstream::pipeline
