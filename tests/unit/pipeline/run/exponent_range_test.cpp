// Every finite double, exactly: the out-of-core pipeline against the in-core kernel,
// and verify's verdict, across the whole exponent range of binary64 (issue 16, item 2).
//
// The pipeline's floating-point shortcuts (the index's float boxes, the range test's
// circumsphere, the hull's facet planes, the window's spacing and buffers) are only
// filters in front of exact predicates. Each case here puts coordinates where one of
// them would overflow, underflow or lose every bit: point sets scaled by 2^k from the
// subnormals to just below DBL_MAX, one far outlier next to a unit cube, a tiny cube
// next to a unit point, coordinates whose exponents are drawn at random over the whole
// range. Each must give the kernel's exact triangulation with many segments and zones,
// and verify must accept it.
#include "core/delaunay.hpp"
#include "io/point_generators.hpp"
#include "io/point_writer.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/run/run.hpp"
#include "pipeline/verify/verify.hpp"
#include "scratch_dir.hpp"
#include "tet_sets.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <filesystem>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include <unistd.h>

namespace tetstream {
namespace {

using testing_util::Quad;

class ExponentRangeTest : public testing_util::ScratchDirTest {
 protected:
  ExponentRangeTest() : ScratchDirTest("exponent-test") {}

  static std::vector<double> generated(io::Distribution d, std::uint64_t n, std::uint64_t seed) {
    return testing_util::generated_points(d, n, seed);
  }

  // Runs the pipeline on xyz with many small segments (and zones when asked), compares
  // its tets with the in-core kernel's on the container's own points, and verifies it.
  void expect_exact(const std::vector<double>& xyz, const std::string& what, std::uint64_t zone_points = 700,
                    int zones = 1) {
    SCOPED_TRACE(what);
    const std::string input = (dir_ / "points.f64").string();
    const std::string output = (dir_ / "out.tets").string();
    std::filesystem::remove(input);
    std::filesystem::remove(output);
    testing_util::write_points_file(input, xyz);
    pipeline::RunOptions o;
    o.threads = 2;
    o.zones = zones;
    o.input = input;
    o.output = output;
    o.segment_points = zone_points;
    o.memory_bytes = std::uint64_t(256) << 20;
    o.progress = false;
    o.checkpoint = false;
    const pipeline::RunSummary summary = pipeline::run_job(o);
    EXPECT_GE(summary.segments, 2u);

    const std::vector<Quad> ours = testing_util::container_quads(output);
    const std::vector<Quad> ref = testing_util::incore_quads(output);
    ASSERT_FALSE(ref.empty()) << "the in-core kernel failed";
    std::vector<Quad> missing, extra;
    std::set_difference(ref.begin(), ref.end(), ours.begin(), ours.end(), std::back_inserter(missing));
    std::set_difference(ours.begin(), ours.end(), ref.begin(), ref.end(), std::back_inserter(extra));
    EXPECT_EQ(missing.size(), 0u) << "tets of the in-core triangulation missing from the output";
    EXPECT_EQ(extra.size(), 0u) << "tets in the output that the in-core triangulation lacks";
    EXPECT_EQ(ours.size(), summary.tets);

    pipeline::VerifyOptions v;
    v.progress = false;
    v.tmpdir = dir_.string();
    io::TetReader reader(output);
    const pipeline::VerifyReport report = pipeline::verify(pipeline::ContainerSource(reader), v);
    EXPECT_TRUE(report.ok()) << report.summary();
  }
};

// Unit-scale sets scaled by 2^k: exact (a power of two) until the values reach the
// subnormals, where they round (the input is then whatever doubles result).
TEST_F(ExponentRangeTest, ScaledByPowersOfTwo) {
  const std::vector<double> base = generated(io::Distribution::kUniform, 1200, 11);
  for (int k : {-1070, -1060, -1022, -1000, -700, -300, -150, -101, -60,  0,
                60,    101,   128,   129,   130,  200,  280,  600,  1000, 1022}) {
    std::vector<double> xyz(base);
    for (double& c : xyz) c = std::ldexp(c, k);
    expect_exact(xyz, "uniform scaled by 2^" + std::to_string(k));
  }
}

TEST_F(ExponentRangeTest, SurfacesAndGridsScaled) {
  for (int k : {-1040, -500, 140, 900, 1020}) {
    for (io::Distribution d : {io::Distribution::kClusters, io::Distribution::kGrid, io::Distribution::kSphere}) {
      std::vector<double> xyz = generated(d, d == io::Distribution::kGrid ? 9 * 9 * 9 : 1000, 5);
      for (double& c : xyz) c = std::ldexp(c, k);
      expect_exact(xyz, std::string(io::to_string(d)) + " scaled by 2^" + std::to_string(k), 250, 3);
    }
  }
}

// One point far from a unit cube (the float boxes overflowed above FLT_MAX).
TEST_F(ExponentRangeTest, FarOutliers) {
  const std::vector<double> base = generated(io::Distribution::kUniform, 1200, 12);
  for (double far : {3e38, 4e38, 1e103, 1e200, 1e300, DBL_MAX, -DBL_MAX}) {
    for (int axis = 0; axis < 3; ++axis) {
      std::vector<double> xyz(base);
      const double p[3] = {axis == 0 ? far : 0.5, axis == 1 ? far : 0.5, axis == 2 ? far : 0.5};
      xyz.insert(xyz.end(), p, p + 3);
      expect_exact(xyz, "outlier " + std::to_string(far) + " on axis " + std::to_string(axis), 250);
    }
  }
  // Both ends of the range at once: every difference overflows.
  std::vector<double> xyz(base);
  for (double& c : xyz) c = std::ldexp(c - 0.5, 1020);
  const double ends[6] = {DBL_MAX, 0, 0, -DBL_MAX, 0, 0};
  xyz.insert(xyz.end(), ends, ends + 6);
  expect_exact(xyz, "+-DBL_MAX with a cloud of 2^1020", 250);
}

// A cloud of tiny coordinates next to a point at unit distance: the tiny cloud's
// squared distances underflow in double.
TEST_F(ExponentRangeTest, TinyCloudBesideAUnitPoint) {
  const std::vector<double> base = generated(io::Distribution::kUniform, 1200, 13);
  for (int k : {-200, -600, -1000}) {
    std::vector<double> xyz(base);
    for (double& c : xyz) c = std::ldexp(c, k);
    const double unit[3] = {1.0, 0.25, 0.5};
    xyz.insert(xyz.end(), unit, unit + 3);
    expect_exact(xyz, "cloud of 2^" + std::to_string(k) + " and one unit point", 250, 2);
  }
}

// Coordinates with random signs and exponents over the whole range: no scale fits.
TEST_F(ExponentRangeTest, RandomExponents) {
  std::mt19937_64 rng(16);
  std::uniform_int_distribution<int> exponent(-1074, 1023);
  std::uniform_real_distribution<double> mantissa(1.0, 2.0);
  // (The full range is slow: every predicate needs the widest exact integers, about
  // 2,100 bits a coordinate, so the sets are small.)
  for (int spread : {60, 400, 2097}) {
    std::vector<double> xyz(3 * std::size_t(spread > 100 ? 300 : 1000));
    for (double& c : xyz) {
      const int e = std::clamp(exponent(rng) % spread, -1074, 1023);
      c = std::ldexp(mantissa(rng), std::min(e, 1022)) * (rng() & 1 ? 1 : -1);
    }
    expect_exact(xyz, "random exponents within " + std::to_string(spread), 80, 2);
  }
}

}  // namespace
}  // namespace tetstream
