// Container version 2's label order (pipeline/write/label_order.hpp, docs/format.md §3.4):
// brick_permutation against the order written out the slow, obvious way from the
// format's text (one comparison sort on (column's curve position, cell, sort order)),
// on uniform, clustered, grid, flat and one-point bricks; and LabelOrder's lookups
// (the window of bricks as it slides, far labels) against the file itself.
#include "io/tet_container.hpp"
#include "pipeline/write/label_order.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <random>
#include <string>
#include <tuple>
#include <vector>

namespace tetstream::pipeline {
namespace {

// format.md §3.4's curve: the position of cell (x, y) along the Hilbert curve of a
// side x side grid, in the orientation the format pins.
std::uint64_t curve_position(std::uint64_t side, std::uint64_t x, std::uint64_t y) {
  std::uint64_t d = 0;
  for (std::uint64_t s = side / 2; s > 0; s /= 2) {
    const std::uint64_t rx = (x & s) ? 1 : 0, ry = (y & s) ? 1 : 0;
    d += s * s * ((3 * rx) ^ ry);
    if (ry == 0) {
      if (rx == 1) x = s - 1 - x, y = s - 1 - y;
      std::swap(x, y);
    }
  }
  return d;
}

std::uint64_t interleave(std::uint64_t a, std::uint64_t u, std::uint64_t v, int levels) {
  std::uint64_t code = 0;
  for (int i = 0; i < levels; ++i)
    code |= ((a >> i) & 1) << (3 * i) | ((u >> i) & 1) << (3 * i + 1) | ((v >> i) & 1) << (3 * i + 2);
  return code;
}

// The order of §3.4, point by point, then one sort: new_of_old[i] is the position of
// the i-th point (in the sort's order).
std::vector<std::uint32_t> reference_order(const std::vector<double>& xyz, int axis) {
  const std::size_t n = xyz.size() / 3;
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  const auto c = [&](std::size_t i, int k) { return xyz[3 * i + std::size_t(k)]; };
  std::array<double, 3> lo{}, hi{};
  for (int k = 0; k < 3; ++k) {
    lo[std::size_t(k)] = hi[std::size_t(k)] = c(0, k);
    for (std::size_t i = 1; i < n; ++i)
      lo[std::size_t(k)] = std::min(lo[std::size_t(k)], c(i, k)),
      hi[std::size_t(k)] = std::max(hi[std::size_t(k)], c(i, k));
  }
  const double t = hi[std::size_t(axis)] - lo[std::size_t(axis)];
  double h = std::max(t, std::max(hi[std::size_t(u)] - lo[std::size_t(u)], hi[std::size_t(v)] - lo[std::size_t(v)]) *
                             std::ldexp(1.0, -20));
  if (h == 0) h = 1;
  const auto column = [&](double x, double origin) {
    return std::uint64_t(std::clamp(std::floor((x - origin) / h), 0.0, std::ldexp(1.0, 21) - 1));
  };
  const std::uint64_t reach =
      std::max(column(hi[std::size_t(u)], lo[std::size_t(u)]), column(hi[std::size_t(v)], lo[std::size_t(v)]));
  std::uint64_t side = 1;
  while (side <= reach) side *= 2;
  std::vector<std::uint64_t> pos(n);
  for (std::size_t i = 0; i < n; ++i)
    pos[i] = curve_position(side, column(c(i, u), lo[std::size_t(u)]), column(c(i, v), lo[std::size_t(v)]));
  std::vector<std::uint64_t> distinct(pos);
  std::sort(distinct.begin(), distinct.end());
  const double per_column = double(n) / double(std::unique(distinct.begin(), distinct.end()) - distinct.begin());
  int k = 0;
  while (k < 10 && 2 * std::pow(8.0, k) < per_column) ++k;
  const double cells = std::ldexp(1.0, k);
  const auto cell = [&](double f) { return std::uint64_t(std::clamp(std::floor(f * cells), 0.0, cells - 1)); };
  const auto frac = [](double x) { return x - std::floor(x); };
  std::vector<std::tuple<std::uint64_t, std::uint64_t, std::size_t>> keys(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double fa = t > 0 ? (c(i, axis) - lo[std::size_t(axis)]) / t : 0.0;
    const std::uint64_t code = interleave(cell(fa), cell(frac((c(i, u) - lo[std::size_t(u)]) / h)),
                                          cell(frac((c(i, v) - lo[std::size_t(v)]) / h)), k);
    keys[i] = {pos[i], code, i};
  }
  std::sort(keys.begin(), keys.end());
  std::vector<std::uint32_t> new_of_old(n);
  for (std::size_t r = 0; r < n; ++r) new_of_old[std::get<2>(keys[r])] = std::uint32_t(r);
  return new_of_old;
}

// The points in the sort's order along `axis` (coordinates compared from it on).
std::vector<double> sorted_along(std::vector<double> xyz, int axis) {
  const std::size_t n = xyz.size() / 3;
  std::vector<std::array<double, 3>> p(n);
  for (std::size_t i = 0; i < n; ++i)
    p[i] = {xyz[3 * i + std::size_t(axis)], xyz[3 * i + std::size_t((axis + 1) % 3)],
            xyz[3 * i + std::size_t((axis + 2) % 3)]};
  std::sort(p.begin(), p.end());
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) xyz[3 * i + std::size_t((axis + k) % 3)] = p[i][std::size_t(k)];
  return xyz;
}

void expect_reference(const std::vector<double>& xyz, int axis, const std::string& what) {
  SCOPED_TRACE(what);
  const std::vector<double> sorted = sorted_along(xyz, axis);
  std::vector<std::uint32_t> ours;
  brick_permutation(sorted.data(), sorted.size() / 3, axis, ours);
  const std::vector<std::uint32_t> ref = reference_order(sorted, axis);
  ASSERT_EQ(ours.size(), ref.size());
  std::size_t differ = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) differ += ours[i] != ref[i];
  EXPECT_EQ(differ, 0u) << "of " << ref.size() << " points";
}

std::vector<double> uniform(std::size_t n, std::uint64_t seed, std::array<double, 3> scale) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> d(0.0, 1.0);
  std::vector<double> xyz(3 * n);
  for (std::size_t i = 0; i < xyz.size(); ++i) xyz[i] = d(rng) * scale[i % 3];
  return xyz;
}

TEST(BrickPermutation, MatchesTheFormatsOrder) {
  // A slab of a uniform cube (as a brick of 2 N^(2/3) points is: thin along the axis).
  expect_reference(uniform(32768, 1, {0.02, 1.0, 1.0}), 0, "uniform slab, axis x");
  expect_reference(uniform(32768, 2, {1.0, 0.03, 1.0}), 1, "uniform slab, axis y");
  expect_reference(uniform(4096, 3, {1.0, 1.0, 0.5}), 2, "a thick brick, axis z");
  // Clusters: many points a column, deeper Morton levels.
  std::vector<double> clusters;
  std::mt19937_64 rng(4);
  std::normal_distribution<double> g(0.0, 0.002);
  for (int c = 0; c < 8; ++c)
    for (int i = 0; i < 4000; ++i)
      clusters.insert(clusters.end(), {0.01 + g(rng), 0.1 * c + g(rng), 0.5 + 0.05 * c + g(rng)});
  expect_reference(clusters, 0, "clusters");
  // A grid: ties everywhere but in the sort's order.
  std::vector<double> grid;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 40; ++j)
      for (int k = 0; k < 40; ++k) grid.insert(grid.end(), {double(i), double(j), double(k)});
  expect_reference(grid, 0, "grid");
  // Flat along the axis (thickness 0: the cells from the cross-section), and along all.
  std::vector<double> flat = uniform(5000, 5, {0.0, 1.0, 1.0});
  expect_reference(flat, 0, "flat along the axis");
  std::vector<double> line = uniform(3000, 6, {0.0, 0.0, 1.0});
  expect_reference(line, 0, "points on a line");
  expect_reference({0.5, 0.25, 0.125}, 0, "one point");
  // Huge and tiny magnitudes.
  std::vector<double> far = uniform(8192, 7, {1e-3, 1.0, 1.0});
  for (double& x : far) x = x * 1e300;
  expect_reference(far, 0, "scaled by 1e300");
}

class LabelOrderTest : public testing_util::ScratchDirTest {
 protected:
  LabelOrderTest() : ScratchDirTest("label-order-test") {}
};

TEST_F(LabelOrderTest, LookupsAgreeWithTheFile) {
  // 300,000 points: bricks of 2^14 labels, 19 bricks, the last one short.
  const std::uint64_t n = 300000, brick = io::brick_labels(n);
  ASSERT_EQ(brick, 16384u);
  const std::vector<double> xyz = sorted_along(uniform(std::size_t(n), 8, {1.0, 1.0, 1.0}), 0);
  const std::string file = path("order.u32");
  write_label_order(
      file, n, 0, [&](std::uint64_t first, std::size_t k, double* out) { std::copy_n(&xyz[3 * first], 3 * k, out); },
      2);
  // Each brick's permutation as brick_permutation gives it, brick by brick.
  std::vector<std::uint64_t> expect(n);
  std::vector<std::uint32_t> perm;
  for (std::uint64_t first = 0; first < n; first += brick) {
    const std::size_t k = std::size_t(std::min(brick, n - first));
    brick_permutation(&xyz[3 * first], k, 0, perm);
    std::vector<bool> seen(k);
    for (std::size_t i = 0; i < k; ++i) {
      ASSERT_LT(perm[i], k);
      EXPECT_FALSE(seen[perm[i]]) << "not a permutation";
      seen[perm[i]] = true;
      expect[first + i] = first + perm[i];
    }
  }
  LabelOrder order(file, n);
  std::mt19937_64 rng(9);
  const std::uint64_t bricks = (n + brick - 1) / brick;
  std::size_t checked = 0;
  for (std::uint64_t b = 0; b < bricks; b += 1 + b % 3) {  // steps of 1 to 3 bricks
    order.keep_from(b);
    // Labels in the window (this brick and the next two), and far ones above it.
    for (int i = 0; i < 2000; ++i) {
      const std::uint64_t in = std::min(n - 1, b * brick + rng() % (3 * brick));
      const std::uint64_t any = b * brick + rng() % (n - b * brick);
      ASSERT_EQ(order(in), expect[in]) << "label " << in << " with the window at brick " << b;
      ASSERT_EQ(order(any), expect[any]) << "label " << any << " with the window at brick " << b;
      checked += 2;
    }
  }
  EXPECT_GT(checked, 20000u);
  std::vector<std::uint32_t> last;
  order.read_brick(bricks - 1, last);
  EXPECT_EQ(last.size(), n - (bricks - 1) * brick);
}

}  // namespace
}  // namespace tetstream::pipeline
