// The ball grid of a periodic keep (pipeline/periodic/ball_grid.hpp): a point is safe
// only when every cell within kReach cells of its own is occupied and inside the
// padded box; an empty cell, the box's faces and a point on a cell's face make points
// unsafe, never safe.
#include "pipeline/periodic/ball_grid.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
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
  EXPECT_DOUBLE_EQ(grid.diameter_bound(), r * kCell);
}

// Roomy: safe, and the kRoom cells around it inside the grid (cells 5..11 here).
TEST(BallGrid, RoomyOnlyWithTheRoomInsideTheBox) {
  const BallGrid grid = lattice_grid({-1, -1, -1});
  const int room = BallGrid::kRoom;
  const double middle[3] = {centre(8), centre(room), centre(16 - room)};
  EXPECT_EQ(grid.room(middle), 2);
  for (const int edge : {room - 1, 17 - room}) {
    const double near_face[3] = {centre(8), centre(edge), centre(8)};
    EXPECT_EQ(grid.room(near_face), 1) << edge;  // safe, not roomy
  }
  const double unsafe[3] = {centre(8), centre(BallGrid::kReach - 1), centre(8)};
  EXPECT_EQ(grid.room(unsafe), 0);
  EXPECT_DOUBLE_EQ(grid.radius_bound(), BallGrid::kReach * kCell / 2);
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
  EXPECT_GT(grid.diameter_bound(), BallGrid::kReach * kCell);
  EXPECT_FALSE(grid.safe(p));  // its neighbours are empty
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
