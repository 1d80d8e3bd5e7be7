// The first margin from the density near the faces (margin.hpp): uniform points keep the
// mean-spacing margin; a void at a face raises it by about the void's spacing over the
// mean; a void in the middle of the box, far from every face, does not. The counts
// taken in the input's pass (pad.hpp) give the margin of the wrapped file's.
#include "io/point_rng.hpp"
#include "pipeline/periodic/margin.hpp"
#include "pipeline/periodic/pad.hpp"
#include "point_files.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
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

// The grid counted while the input is read, in place or into its wrapped copy (a point
// outside the box), is the one the wrapped file gives; an input that tells no count
// before it is read (text) gets none, and the job counts the wrapped file.
TEST(PeriodicMargin, TheInputsPassCountsWhatTheWrappedFileWould) {
  io::TempDir dir;
  const double at_face[3] = {0.0, 0.5, 0.5};
  const std::string path = dir.file("p.f64");
  const std::string here = std::filesystem::path(path).parent_path().string();
  write_points(path, kPoints, at_face, 0.15, 0.125);
  const std::array<double, 3> unit = {1, 1, 1};
  const io::PointReadOptions read;
  WrappedInput in_place = write_wrapped(path, read, unit, true, here, false, kMemory);
  ASSERT_TRUE(in_place.as_is);
  ASSERT_TRUE(in_place.density.has_value());
  const DensityMargin expected = margin_for_density(path, kPoints, unit, mean_margin(), kMemory);
  EXPECT_GT(expected.margin[0], 1.6 * mean_margin()[0]);
  const DensityMargin got = std::move(*in_place.density).margin(mean_margin());
  EXPECT_EQ(got.margin, expected.margin);
  EXPECT_EQ(got.sparsest, expected.sparsest);
  EXPECT_EQ(got.cells, expected.cells);

  // The first point a period out on x: the pass in place stops there and the copy counts.
  {
    std::FILE* f = std::fopen(path.c_str(), "r+b");
    double x = 0;
    ASSERT_EQ(std::fread(&x, sizeof x, 1, f), 1u);
    x += 1;
    std::fseek(f, 0, SEEK_SET);
    std::fwrite(&x, sizeof x, 1, f);
    std::fclose(f);
  }
  WrappedInput copied = write_wrapped(path, read, unit, true, here, false, kMemory);
  ASSERT_FALSE(copied.as_is);
  ASSERT_EQ(copied.wrapped, 1u);
  ASSERT_TRUE(copied.density.has_value());
  const DensityMargin from_copy = margin_for_density(copied.path, kPoints, unit, mean_margin(), kMemory);
  EXPECT_EQ(from_copy.margin, expected.margin);  // the same points, wrapped
  EXPECT_EQ(std::move(*copied.density).margin(mean_margin()).margin, expected.margin);

  // Text: no count before the pass.
  const std::string text = dir.file("p.xyz");
  {
    std::FILE* f = std::fopen(text.c_str(), "w");
    std::fprintf(f, "0.1 0.2 0.3\n0.4 0.5 0.6\n0.7 0.8 0.9\n0.2 0.9 0.4\n");
    std::fclose(f);
  }
  const WrappedInput from_text = write_wrapped(text, read, unit, true, here, false, kMemory);
  EXPECT_EQ(from_text.count, 4u);
  EXPECT_FALSE(from_text.density.has_value());
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
