// pipeline/hull: the cheap filters in front of the kernel (the 26 extremes' hull, its
// inscribed box, the facet planes with their error bound) must never drop a point on
// the convex hull's boundary. Reference: the kernel's triangulation of all points,
// unfiltered, whose infinite tets touch the boundary points.
#include "core/delaunay.hpp"
#include "pipeline/sort/hull.hpp"
#include "pipeline/sort/point_sort_detail.hpp"
#include "test_points.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <string>
#include <unordered_set>
#include <vector>

namespace tetstream {
namespace {

using test::Points;

std::vector<std::uint32_t> unfiltered_hull(const Points& p) {
  core::Delaunay dt;
  EXPECT_EQ(dt.build(p.data(), nullptr, test::count(p)), core::BuildStatus::kOk);
  std::vector<std::uint32_t> out;
  for (std::size_t t = 0; t < dt.num_tet_slots(); ++t) {
    if (!dt.is_alive(core::TetId(t)) || !dt.is_infinite(core::TetId(t))) continue;
    for (int i = 0; i < 4; ++i)
      if (dt.vertex(core::TetId(t), i) != core::kInfiniteVertex) out.push_back(dt.vertex(core::TetId(t), i));
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// As coordinates: of duplicate points, either copy may stand for the others.
std::vector<std::array<double, 3>> coordinates(const Points& p, const std::vector<std::uint32_t>& indices) {
  std::vector<std::array<double, 3>> out;
  for (std::uint32_t i : indices) out.push_back({p[3 * i], p[3 * i + 1], p[3 * i + 2]});
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

// With the default sample (the filter of a sample's hull applies from 65,536
// survivors on) and with a sample of 64 points, so that it filters every shape here.
void expect_same_hull(const Points& p, const std::string& what) {
  const auto expected = coordinates(p, unfiltered_hull(p));
  for (std::size_t sample : {pipeline::kHullSamplePoints, std::size_t(64)}) {
    const std::vector<std::uint32_t> got = pipeline::hull_vertex_candidates(p.data(), test::count(p), sample);
    EXPECT_TRUE(std::is_sorted(got.begin(), got.end())) << what << ", sample " << sample;
    EXPECT_EQ(coordinates(p, got), expected) << what << ", sample " << sample;
  }
}

Points shifted(Points p, double offset) {
  for (double& x : p) x += offset;
  return p;
}

TEST(HullCandidates, EqualTheKernelsHullOnEveryShape) {
  for (std::uint64_t seed = 1; seed <= 3; ++seed) {
    expect_same_hull(test::uniform_cube(20000, seed), "cube seed " + std::to_string(seed));
    expect_same_hull(test::uniform_ball(20000, seed), "ball seed " + std::to_string(seed));
    expect_same_hull(test::ellipsoid_shell(5000, seed), "shell seed " + std::to_string(seed));
    expect_same_hull(test::clusters(20000, seed), "clusters seed " + std::to_string(seed));
    expect_same_hull(test::sphere_surface(3000, seed), "sphere seed " + std::to_string(seed));
    // Coarse coordinates: many points exactly on the planes of the extremes' facets,
    // where only the exact predicate decides.
    expect_same_hull(test::coarse(20000, seed, 30), "coarse seed " + std::to_string(seed));
    // Far from the origin (LiDAR-like offsets): the planes' error bounds scale with
    // the coordinates' distances, not their magnitudes.
    expect_same_hull(shifted(test::uniform_cube(20000, seed), 1e6), "offset cube seed " + std::to_string(seed));
    expect_same_hull(shifted(test::coarse(20000, seed, 30), 5e5), "offset coarse seed " + std::to_string(seed));
  }
  // A shell large enough for the default sample's filter (most points pass the
  // extremes' filter).
  expect_same_hull(test::ellipsoid_shell(100000, 4), "shell 100000");
  // A grid: every point of the six faces is on the boundary.
  expect_same_hull(test::grid(20), "grid 20^3");
  expect_same_hull(test::coplanar_layers(5000, 4, 9, 8), "coplanar layers");
}

// A sorted run's candidates come from pieces of it, one kernel each (the sort's
// hull share): the union of the pieces' candidates holds every boundary point of the
// run, whatever the number of pieces.
TEST(HullCandidates, ARunInPiecesKeepsItsBoundaryPoints) {
  for (const std::size_t piece : {std::size_t(20000), std::size_t(4096), std::size_t(1000), std::size_t(97)}) {
    const Points p = test::uniform_cube(20000, 5);
    std::vector<pipeline::SortedPoint> run(test::count(p));
    for (std::size_t i = 0; i < run.size(); ++i) {
      std::copy_n(&p[3 * i], 3, run[i].xyz);
      run[i].original = 1000 + i;  // an original index, not the position in the run
    }
    pipeline::SortShares shares;
    shares.hull_piece_points = piece;
    shares.hull_threads = 2;
    std::vector<double> xyz;
    std::vector<std::uint64_t> hull;
    std::unordered_set<std::uint64_t> all;
    pipeline::sort_detail::sort_run_and_find_hull(run, 0, shares, xyz, hull, all);
    std::vector<std::uint32_t> got;
    for (std::uint64_t o : hull) got.push_back(std::uint32_t(o - 1000));
    const std::vector<std::uint32_t> expected = unfiltered_hull(p);
    std::sort(got.begin(), got.end());
    EXPECT_TRUE(std::includes(got.begin(), got.end(), expected.begin(), expected.end())) << "pieces of " << piece;
    EXPECT_EQ(all.size(), hull.size());
  }
}

TEST(HullCandidates, FewPointsAreAllReturned) {
  Points p;
  test::push(p, 0, 0, 0);
  test::push(p, 1, 0, 0);
  test::push(p, 0, 1, 0);
  EXPECT_EQ(pipeline::hull_vertex_candidates(p.data(), 3), (std::vector<std::uint32_t>{0, 1, 2}));
  // Coplanar: no triangulation; every point is a candidate.
  Points flat;
  for (int i = 0; i < 5; ++i)
    for (int j = 0; j < 5; ++j) test::push(flat, i, j, 0);
  EXPECT_EQ(pipeline::hull_vertex_candidates(flat.data(), 25).size(), 25u);
}

}  // namespace
}  // namespace tetstream
