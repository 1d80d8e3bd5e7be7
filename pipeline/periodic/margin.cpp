#include "pipeline/periodic/margin.hpp"

#include "pipeline/files/temp_files.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace tetstream::pipeline::periodic {

std::array<double, 3> mean_spacing_margin(const PeriodicOptions& p, std::uint64_t n) {
  const double volume = p.period[0] * p.period[1] * p.period[2];
  const double spacing = std::cbrt(volume / double(std::max<std::uint64_t>(n, 1)));
  std::array<double, 3> m;
  for (int k = 0; k < 3; ++k) m[k] = std::min(p.margin_spacings * spacing, 0.5 * p.period[k]);
  return m;
}

namespace {

constexpr std::size_t kChunk = std::size_t(1) << 16;
constexpr double kPointsPerCell = 8, kNeighbourhoodPoints = 1000;

// Sums each cell's run of 2h + 1 cells along `axis`, periodically (in place, through `line`).
void box_sum(std::vector<std::uint32_t>& cells, const std::array<std::int64_t, 3>& n, int axis, std::int64_t h,
             std::vector<std::uint32_t>& line) {
  const std::int64_t len = n[std::size_t(axis)];
  const std::int64_t stride = axis == 0 ? 1 : axis == 1 ? n[0] : n[0] * n[1];
  const std::int64_t width = std::min(2 * h + 1, len);
  const std::int64_t lines = n[0] * n[1] * n[2] / len;
  line.resize(std::size_t(len));
  for (std::int64_t l = 0; l < lines; ++l) {
    // The line's first cell: l enumerates the other two axes.
    const std::int64_t base = axis == 0 ? l * len : axis == 1 ? (l / n[0]) * n[0] * n[1] + l % n[0] : l;
    for (std::int64_t i = 0; i < len; ++i) line[std::size_t(i)] = cells[std::size_t(base + i * stride)];
    std::uint64_t sum = 0;
    for (std::int64_t d = -h; d < -h + width; ++d) sum += line[std::size_t(((d % len) + len) % len)];
    for (std::int64_t i = 0; i < len; ++i) {
      // Saturated: a neighbourhood past 2^32 points (a halo of 10^10) reads as dense.
      cells[std::size_t(base + i * stride)] = std::uint32_t(std::min<std::uint64_t>(sum, UINT32_MAX));
      if (width == len) continue;  // the whole line: every cell the same sum
      sum += line[std::size_t(((i - h + width) % len + len) % len)];
      sum -= line[std::size_t(((i - h) % len + len) % len)];
    }
  }
}

}  // namespace

DensityGrid::DensityGrid(std::uint64_t count, const std::array<double, 3>& period, std::uint64_t memory_bytes)
    : count_(count), period_(period) {
  if (count == 0) return;
  // Cubes of about kPointsPerCell points of the mean density, as many as the memory
  // allows (the counts and their sums: 4 bytes a cell, and a line's copy).
  const double volume = period[0] * period[1] * period[2];
  const double most = std::max(1.0, std::min(double(count) / kPointsPerCell, double(memory_bytes / 4) / 4));
  const double side = std::cbrt(volume / std::min(most, double(std::uint64_t(1) << 26)));
  for (int k = 0; k < 3; ++k) n_[std::size_t(k)] = std::max<std::int64_t>(1, std::int64_t(period[k] / side));
  grid_.assign(std::size_t(n_[0] * n_[1] * n_[2]), 0);
}

void DensityGrid::add(const double* xyz, std::size_t m) {
  if (grid_.empty()) return;
  for (std::size_t i = 0; i < m; ++i) {
    std::int64_t at = 0, stride = 1;
    for (int k = 0; k < 3; ++k) {
      const auto c = std::min<std::int64_t>(
          n_[std::size_t(k)] - 1, std::int64_t(xyz[3 * i + std::size_t(k)] / period_[k] * double(n_[std::size_t(k)])));
      at += std::max<std::int64_t>(c, 0) * stride;
      stride *= n_[std::size_t(k)];
    }
    std::uint32_t& cell = grid_[std::size_t(at)];
    cell += cell != UINT32_MAX;
  }
}

DensityMargin DensityGrid::margin(std::array<double, 3> margin) && {
  DensityMargin out;
  out.margin = margin;
  if (count_ == 0) return out;
  const std::array<std::int64_t, 3>& n = n_;
  std::vector<std::uint32_t>& grid = grid_;
  const std::array<double, 3>& period = period_;
  const std::size_t cells = grid.size();
  out.cells = cells;
  const std::uint64_t count = count_;
  // Each cell's neighbourhood: (2h + 1)^3 cells holding about kNeighbourhoodPoints.
  const double per_cell = double(count) / double(cells);
  const auto h = std::int64_t(std::ceil((std::cbrt(kNeighbourhoodPoints / per_cell) - 1) / 2));
  std::vector<std::uint32_t> line;
  for (int axis = 0; axis < 3; ++axis) box_sum(grid, n, axis, std::max<std::int64_t>(h, 0), line);
  double expected = per_cell;
  for (int k = 0; k < 3; ++k) expected *= double(std::min(2 * std::max<std::int64_t>(h, 0) + 1, n[std::size_t(k)]));
  // Per axis, the sparsest neighbourhood about the cells near its faces: within the
  // band [L - 3 M, L) u [0, M), where the balls that could fail the keep's condition (a
  // radius of M/2 or more, about a centre in C = [-M/2, L - M/2)) reach across the
  // padded box's faces (docs/periodic.md). A raised margin widens the band: a few rounds.
  for (int round = 0; round < 3; ++round) {
    bool raised = false;
    for (int axis = 0; axis < 3; ++axis) {
      const double cell = period[axis] / double(n[std::size_t(axis)]);
      double sparsest = 1;  // the neighbourhood's density over the mean (an upper bound of it)
      for (std::int64_t i = 0; i < n[std::size_t(axis)]; ++i) {
        const double centre = (double(i) + 0.5) * cell;
        if (centre < period[axis] - 3 * margin[std::size_t(axis)] && centre >= margin[std::size_t(axis)]) continue;
        // The slice i across the axis: the other two axes whole.
        const int u = (axis + 1) % 3, v = (axis + 2) % 3;
        for (std::int64_t a = 0; a < n[std::size_t(u)]; ++a)
          for (std::int64_t b = 0; b < n[std::size_t(v)]; ++b) {
            std::int64_t c[3];
            c[axis] = i, c[u] = a, c[v] = b;
            const double k = double(grid[std::size_t(c[0] + n[0] * (c[1] + n[1] * c[2]))]);
            // Three deviations above the count, so that the sampling noise of the mean
            // density's neighbourhoods reads as no sparser than the mean.
            sparsest = std::min(sparsest, (k + 3 * std::sqrt(k) + 3) / expected);
          }
      }
      out.sparsest[std::size_t(axis)] = std::min(out.sparsest[std::size_t(axis)], sparsest);
      const double factor = std::cbrt(1 / std::max(sparsest, 1e-12));
      if (factor <= kSlack) continue;
      const double wanted = std::min(0.5 * period[axis], out.margin[std::size_t(axis)] * factor);
      if (wanted > margin[std::size_t(axis)]) margin[std::size_t(axis)] = wanted, raised = true;
    }
    if (!raised) break;
  }
  out.margin = margin;
  return out;
}

DensityMargin margin_for_density(const std::string& points_path, std::uint64_t count,
                                 const std::array<double, 3>& period, std::array<double, 3> margin,
                                 std::uint64_t memory_bytes) {
  DensityGrid grid(count, period, memory_bytes);
  if (count > 0) {
    BinaryFile in(points_path, "rb");
    std::vector<double> xyz(3 * kChunk);
    while (const std::size_t m = in.read(xyz.data(), 3 * sizeof(double), kChunk)) grid.add(xyz.data(), m);
  }
  return std::move(grid).margin(margin);
}

}  // namespace tetstream::pipeline::periodic
