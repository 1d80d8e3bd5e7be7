// The ball grid of a periodic keep (pipeline/periodic/ball_grid.hpp): a point is safe
// only when every cell within kReach cells of its own is occupied and inside the
// padded box; an empty cell, the box's faces and a point on a cell's face make points
// unsafe, never safe; the Delaunay balls through safe points are below the bound.
#include "pipeline/periodic/ball_grid.hpp"

#include "core/delaunay.hpp"
#include "core/predicates.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <vector>

namespace tetstream::pipeline::periodic {
namespace {

// Exact in binary: the padded box is 18 cells wide, 17 of them in the grid (one left
// out for the extent's rounding): cells 0..16, safe from 4 to 12.
constexpr double kCell = 0.125;
const std::array<double, 3> kLower{-0.25, -0.25, -0.25}, kPeriod{2.0, 2.0, 2.0};

// A point at the centre of every cell of side kCell / 2 (8 a grid cell), but those in
// the grid cell `hole` (none when its coordinates are negative).
BallGrid lattice_grid(const std::array<int, 3>& hole) {
  BallGrid grid(kLower, kPeriod, kCell);
  const double step = kCell / 2;
  const int n = int((kPeriod[0] - kLower[0]) / step);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      for (int k = 0; k < n; ++k) {
        const double p[3] = {kLower[0] + (i + 0.5) * step, kLower[1] + (j + 0.5) * step, kLower[2] + (k + 0.5) * step};
        if (i / 2 == hole[0] && j / 2 == hole[1] && k / 2 == hole[2]) continue;
        grid.mark(p);
      }
    }
  }
  grid.finish();
  return grid;
}

double centre(int cell) { return kLower[0] + (cell + 0.5) * kCell; }

TEST(BallGrid, SafeOnlyWithTheReachInsideTheBox) {
  const BallGrid grid = lattice_grid({-1, -1, -1});
  const int r = BallGrid::kReach;
  const double inside[3] = {centre(r), centre(8), centre(16 - r)};
  EXPECT_TRUE(grid.safe(inside));
  for (const int edge : {r - 1, 17 - r}) {
    const double near_face[3] = {centre(8), centre(edge), centre(8)};
    EXPECT_FALSE(grid.safe(near_face)) << edge;
  }
  const double outside[3] = {kLower[0] - 0.01, centre(8), centre(8)};
  EXPECT_FALSE(grid.safe(outside));
  // On a cell's face: which cell it is in is not trusted.
  const double on_face[3] = {kLower[0] + 8 * kCell, centre(8), centre(8)};
  EXPECT_FALSE(grid.safe(on_face));
}

// The lemma on a triangulation: every Delaunay ball through a safe point has a radius
// below the bound (sqrt(3) c), and points of uniform data inside are mostly safe.
TEST(BallGrid, EveryBallThroughASafePointIsBelowTheBound) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-0.25, 2.0);
  const std::size_t n = 100000;  // about 17 points a cell of side 0.125
  std::vector<double> xyz(3 * n);
  for (double& x : xyz) x = u(rng);
  BallGrid grid(kLower, kPeriod, kCell);
  for (std::size_t i = 0; i < n; ++i) grid.mark(&xyz[3 * i]);
  grid.finish();
  core::Delaunay dt;
  ASSERT_EQ(dt.build(xyz.data(), nullptr, n), core::BuildStatus::kOk);
  std::size_t safe_tets = 0;
  double largest = 0;
  dt.for_each_finite_tet([&](const core::VertexId* v) {
    bool safe = false;
    for (int j = 0; j < 4; ++j) safe = safe || grid.safe(dt.point(v[j]));
    if (!safe) return;
    ++safe_tets;
    const core::Circumsphere s = core::circumsphere(dt.point(v[0]), dt.point(v[1]), dt.point(v[2]), dt.point(v[3]));
    largest = std::max(largest, s.radius);
    EXPECT_LT(s.radius, grid.radius_bound());
  });
  EXPECT_GT(safe_tets, 30000u);
  EXPECT_LT(largest, grid.radius_bound());
  EXPECT_DOUBLE_EQ(grid.radius_bound(), std::sqrt(3.0) * kCell * (1 + 0x1p-40));
  EXPECT_DOUBLE_EQ(grid.diameter_bound(), 2 * grid.radius_bound());
}

TEST(BallGrid, AnEmptyCellMakesItsReachUnsafe) {
  const BallGrid grid = lattice_grid({6, 6, 6});
  const int r = BallGrid::kReach;
  for (int d = -r; d <= r; ++d) {
    const double p[3] = {centre(6 + d), centre(6 - d), centre(6)};
    EXPECT_FALSE(grid.safe(p)) << d;
  }
  const double beyond[3] = {centre(6 + r + 1), centre(6), centre(6)};
  EXPECT_TRUE(grid.safe(beyond));
}

TEST(BallGrid, AGridTooLargeGetsCoarser) {
  BallGrid grid(kLower, kPeriod, kCell, 1000);
  const double p[3] = {0.5, 0.5, 0.5};
  grid.mark(p);
  grid.finish();
  EXPECT_GT(grid.diameter_bound(), 2 * std::sqrt(3.0) * kCell);
  EXPECT_FALSE(grid.safe(p));  // its neighbours are empty
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
