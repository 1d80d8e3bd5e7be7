// The first margin from the density near the faces (margin.hpp): uniform points keep the
// mean-spacing margin; a void at a face raises it by about the void's spacing over the
// mean; a void in the middle of the box, far from every face, does not.
#include "io/point_rng.hpp"
#include "pipeline/periodic/margin.hpp"
#include "point_files.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <vector>

namespace tetstream::pipeline::periodic {
namespace {

// n uniform points of [0, 1)^3, those within `radius` of `centre` (periodically) kept
// with probability `keep`, written as raw float64.
std::uint64_t write_points(const std::string& path, std::uint64_t n, const double* centre, double radius, double keep) {
  io::rng::PointRng r(42, 0);
  std::vector<double> xyz;
  while (xyz.size() < 3 * n) {
    double p[3] = {r.uniform(), r.uniform(), r.uniform()};
    double d2 = 0;
    for (int k = 0; k < 3; ++k) {
      double d = std::fabs(p[k] - centre[k]);
      d = std::min(d, 1 - d);
      d2 += d * d;
    }
    if (d2 < radius * radius && !(r.uniform() < keep)) continue;
    xyz.insert(xyz.end(), p, p + 3);
  }
  std::FILE* f = std::fopen(path.c_str(), "wb");
  std::fwrite(xyz.data(), sizeof(double), xyz.size(), f);
  std::fclose(f);
  return n;
}

constexpr std::uint64_t kPoints = 200000;
constexpr std::uint64_t kMemory = std::uint64_t(64) << 20;

// The unit box's mean-spacing margin for kPoints.
std::array<double, 3> mean_margin() {
  PeriodicOptions o;
  o.period = {1, 1, 1};
  return mean_spacing_margin(o, kPoints);
}

DensityMargin estimate(const io::TempDir& dir, const double* centre, double radius, double keep) {
  const std::string path = dir.file("p.f64");
  write_points(path, kPoints, centre, radius, keep);
  return margin_for_density(path, kPoints, {1, 1, 1}, mean_margin(), kMemory);
}

TEST(PeriodicMargin, UniformPointsKeepTheMeanSpacingMargin) {
  io::TempDir dir;
  const double nowhere[3] = {0.5, 0.5, 0.5};
  const auto mean = mean_margin();
  const DensityMargin d = estimate(dir, nowhere, 0, 1);
  EXPECT_EQ(d.margin, mean);
  for (double s : d.sparsest) EXPECT_GT(s, 1 / (kSlack * kSlack * kSlack));
  EXPECT_GT(d.cells, 1000u);
}

TEST(PeriodicMargin, AVoidAtAFaceRaisesItByItsSpacing) {
  io::TempDir dir;
  // A void of radius 0.15 across the x = 0 face, at an eighth of the mean density.
  const double at_face[3] = {0.0, 0.5, 0.5};
  const auto mean = mean_margin();
  const DensityMargin d = estimate(dir, at_face, 0.15, 0.125);
  // Twice the mean spacing inside: about twice the margin on x (the neighbourhoods'
  // noise bound and their reach over the void's edge take a little off).
  EXPECT_GT(d.margin[0], 1.6 * mean[0]);
  EXPECT_LT(d.margin[0], 2.4 * mean[0]);
  EXPECT_LT(d.sparsest[0], 0.25);
}

TEST(PeriodicMargin, AVoidFarFromTheFacesLeavesIt) {
  io::TempDir dir;
  const double middle[3] = {0.5, 0.5, 0.5};
  const DensityMargin d = estimate(dir, middle, 0.15, 0.125);
  EXPECT_EQ(d.margin, mean_margin());
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
