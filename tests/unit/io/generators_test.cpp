// Generators: reproducible by seed, independent of chunking, and the documented shapes
// (io/point_generators.hpp, docs/inputs.md). A failing test prints its seed.
#include "core/error.hpp"
#include "io/point_generators.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <set>
#include <tuple>
#include <vector>

using namespace tetstream;
using namespace tetstream::io;

namespace {

constexpr std::uint64_t kSeed = 20240611;

std::vector<double> gen(Distribution d, std::uint64_t n, std::uint64_t seed = kSeed, double dup = 0.0) {
  GeneratorOptions o;
  o.dist = d, o.n = n, o.seed = seed, o.duplicates = dup;
  PointGenerator g(o);
  std::vector<double> xyz(3 * g.count());
  g.generate(0, g.count(), xyz.data());
  return xyz;
}

const Distribution kAll[] = {Distribution::kUniform,  Distribution::kBall, Distribution::kEllipsoidShell,
                             Distribution::kMixed,    Distribution::kClusters, Distribution::kGrid,
                             Distribution::kSphere,   Distribution::kTerrain, Distribution::kTwoPlates};

}  // namespace

TEST(Generators, ReproducibleBySeedAndIndependentOfChunking) {
  for (Distribution d : kAll) {
    for (double dup : {0.0, 0.3}) {
      SCOPED_TRACE(std::string(to_string(d)) + " duplicates " + std::to_string(dup) + " seed " + std::to_string(kSeed));
      const auto a = gen(d, 5000, kSeed, dup);
      EXPECT_EQ(a, gen(d, 5000, kSeed, dup));
      if (d != Distribution::kGrid) {
        EXPECT_NE(a, gen(d, 5000, kSeed + 1, dup));
      }
      // Uneven chunks, generated back to front: same points.
      GeneratorOptions o;
      o.dist = d, o.n = 5000, o.seed = kSeed, o.duplicates = dup;
      PointGenerator g(o);
      std::vector<double> b(a.size());
      std::vector<std::pair<std::uint64_t, std::size_t>> chunks;
      for (std::uint64_t i = 0, k = 1; i < g.count(); i += k, k = k * 3 % 1000 + 1)
        chunks.push_back({i, std::min<std::uint64_t>(k, g.count() - i)});
      std::reverse(chunks.begin(), chunks.end());
      for (auto [first, n] : chunks) g.generate(first, n, b.data() + 3 * first);
      EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(double)), 0);
      // A prefix of a longer run is the shorter run (point i does not depend on n).
      if (d != Distribution::kGrid) {
        const auto longer = gen(d, 7000, kSeed, dup);
        EXPECT_TRUE(std::equal(a.begin(), a.end(), longer.begin()));
      }
      for (double v : a) ASSERT_TRUE(std::isfinite(v));
    }
  }
}

TEST(Generators, UniformInUnitCube) {
  const auto p = gen(Distribution::kUniform, 20000);
  double mean = 0;
  for (double v : p) {
    ASSERT_GE(v, 0.0);
    ASSERT_LT(v, 1.0);
    mean += v;
  }
  EXPECT_NEAR(mean / double(p.size()), 0.5, 0.01);
}

TEST(Generators, BallIsInsideTheUnitBall) {
  const auto p = gen(Distribution::kBall, 20000);
  double max_r2 = 0;
  for (std::size_t i = 0; i < p.size(); i += 3) {
    const double r2 = p[i] * p[i] + p[i + 1] * p[i + 1] + p[i + 2] * p[i + 2];
    ASSERT_LE(r2, 1.0) << "point " << i / 3 << " seed " << kSeed;
    ASSERT_LE(std::sqrt(r2), 1.0);
    max_r2 = std::max(max_r2, r2);
  }
  EXPECT_GT(max_r2, 0.99);  // and fills it
}

TEST(Generators, EllipsoidShellRadialSpread) {
  GeneratorOptions o;
  o.dist = Distribution::kEllipsoidShell, o.n = 20000, o.seed = kSeed;
  o.axes = {2.0, 1.0, 0.5};
  o.spread = 0.01;
  PointGenerator g(o);
  std::vector<double> p(3 * o.n);
  g.generate(0, o.n, p.data());
  double lo = 2, hi = 0, ext[3] = {0, 0, 0};
  for (std::size_t i = 0; i < p.size(); i += 3) {
    const double x = p[i] / 2.0, y = p[i + 1] / 1.0, z = p[i + 2] / 0.5;
    const double s = std::sqrt(x * x + y * y + z * z);
    lo = std::min(lo, s), hi = std::max(hi, s);
    for (int c = 0; c < 3; ++c) ext[c] = std::max(ext[c], std::fabs(p[i + c]));
  }
  EXPECT_GE(lo, 0.99 - 1e-12);
  EXPECT_LE(hi, 1.01 + 1e-12);
  EXPECT_LT(lo, 0.992);  // the spread is used
  EXPECT_GT(hi, 1.008);
  EXPECT_GT(ext[0], 1.95);  // the axes are used
  EXPECT_GT(ext[1], 0.95);
  EXPECT_GT(ext[2], 0.45);
  // Area-uniform: the ends of the long axis (|x| > 1.8, where the surface is small)
  // get few points; a direction-uniform sampler would put ~10% there.
  std::size_t ends = 0;
  for (std::size_t i = 0; i < p.size(); i += 3) ends += std::fabs(p[i]) > 1.8;
  EXPECT_LT(double(ends) / double(o.n), 0.06);
}

TEST(Generators, SphereIsCosphericalUpToRounding) {
  for (double r : {1.0, 3.5}) {
    GeneratorOptions o;
    o.dist = Distribution::kSphere, o.n = 20000, o.seed = kSeed, o.radius = r;
    PointGenerator g(o);
    std::vector<double> p(3 * o.n);
    g.generate(0, o.n, p.data());
    for (std::size_t i = 0; i < p.size(); i += 3) {
      const double norm = std::sqrt(p[i] * p[i] + p[i + 1] * p[i + 1] + p[i + 2] * p[i + 2]);
      ASSERT_NEAR(norm, r, 1e-15 * r) << "point " << i / 3 << " seed " << kSeed;
    }
  }
}

TEST(Generators, GridIsAnExactLattice) {
  GeneratorOptions o;
  o.dist = Distribution::kGrid, o.seed = kSeed;
  for (auto [n, k] : {std::pair<std::uint64_t, std::uint64_t>{1, 1}, {1000, 10}, {1100, 10}, {1200, 11}, {1331, 11}, {30, 3}}) {
    o.n = n;
    EXPECT_EQ(PointGenerator(o).count(), k * k * k) << "n " << n;
  }
  o.n = 1000;
  PointGenerator g(o);
  std::vector<double> p(3 * g.count());
  g.generate(0, g.count(), p.data());
  const double h = 1.0 / 16;  // k = 10 -> 2^-ceil(log2 10)
  std::set<std::tuple<long, long, long>> seen;
  for (std::size_t i = 0; i < p.size(); i += 3) {
    long idx[3];
    for (int c = 0; c < 3; ++c) {
      const double q = p[i + c] / h;
      ASSERT_EQ(q, std::floor(q)) << "not on the lattice";
      ASSERT_GE(q, 0.0);
      ASSERT_LT(q, 10.0);
      idx[c] = long(q);
    }
    seen.insert({idx[0], idx[1], idx[2]});
  }
  EXPECT_EQ(seen.size(), 1000u);  // every lattice point once
}

TEST(Generators, DuplicatesFraction) {
  const std::uint64_t n = 50000;
  for (Distribution d : {Distribution::kUniform, Distribution::kSphere}) {
    for (double f : {0.0, 0.1, 0.5}) {
      const auto p = gen(d, n, kSeed, f);
      std::set<std::tuple<double, double, double>> seen;
      std::size_t repeats = 0;
      for (std::size_t i = 0; i < p.size(); i += 3) repeats += !seen.insert({p[i], p[i + 1], p[i + 2]}).second;
      const double sigma = std::sqrt(double(n) * f * (1 - f));
      EXPECT_NEAR(double(repeats), f * double(n), 6 * sigma + 1) << to_string(d) << " F " << f << " seed " << kSeed;
    }
  }
  // is_duplicate names an earlier original with the same coordinates.
  GeneratorOptions o;
  o.n = 1000, o.seed = kSeed, o.duplicates = 0.4;
  PointGenerator g(o);
  std::vector<double> p(3 * o.n);
  g.generate(0, o.n, p.data());
  for (std::uint64_t i = 0; i < o.n; ++i) {
    std::uint64_t src = i;
    if (g.is_duplicate(i, &src)) {
      ASSERT_LT(src, i);
      EXPECT_FALSE(g.is_duplicate(src));
      EXPECT_TRUE(std::equal(&p[3 * i], &p[3 * i + 3], &p[3 * src]));
    }
  }
}

TEST(Generators, MixedPatternsStayNearTheirShapes) {
  const auto p = gen(Distribution::kMixed, 30000);
  std::size_t on_line = 0;
  for (std::size_t i = 0; i < p.size(); i += 3) {
    for (int c = 0; c < 3; ++c) {
      ASSERT_GE(p[i + c], 0.04 - 1e-12);
      ASSERT_LE(p[i + c], 0.96 + 1e-12);
    }
    // Distance to the diagonal line x = y = z.
    const double m = (p[i] + p[i + 1] + p[i + 2]) / 3;
    const double d2 = (p[i] - m) * (p[i] - m) + (p[i + 1] - m) * (p[i + 1] - m) + (p[i + 2] - m) * (p[i + 2] - m);
    on_line += d2 <= 0.01 * 0.01 + 1e-12;
  }
  EXPECT_NEAR(double(on_line) / 30000.0, 1.0 / 3.0, 0.02);
}

TEST(Generators, ClustersAreReproducibleAndBounded) {
  const auto p = gen(Distribution::kClusters, 20000);
  for (double v : p) {
    ASSERT_GT(v, -0.3);
    ASSERT_LT(v, 1.3);
  }
}

// The LiDAR-like tile: UTM-like offsets, centimetre quantisation, a 1 km square, and
// its classes (flat roofs: many points at one height; walls: points that share x or y).
TEST(Generators, TerrainIsALidarTile) {
  const auto p = gen(Distribution::kTerrain, 50000);
  std::map<std::pair<int, int>, std::map<double, int>> cell_heights;  // 40 m cell -> height -> points
  for (std::size_t i = 0; i < p.size(); i += 3) {
    const double x = p[i] - 500000, y = p[i + 1] - 4000000, z = p[i + 2] - 100;
    ASSERT_GE(x, 0.0);
    ASSERT_LE(x, 1000.0);
    ASSERT_GE(y, 0.0);
    ASSERT_LE(y, 1000.0);
    ASSERT_LT(std::fabs(z), 70.0) << "height field of +-40 m, roofs and trees up to 25 m above it";
    for (double v : {x, y, p[i + 2]}) ASSERT_NEAR(v * 100, std::round(v * 100), 1e-4) << "centimetres";
    ++cell_heights[{int(x / 40), int(y / 40)}][p[i + 2]];
  }
  // Flat roofs: about 30% of the 625 cells hold ~29 points at one height, which the
  // smooth, centimetre-quantised ground (about 80 points a cell over metres of
  // relief) does not.
  int roofs = 0;
  for (const auto& [cell, heights] : cell_heights) {
    int most = 0;
    for (const auto& [z, count] : heights) most = std::max(most, count);
    roofs += most >= 10;
  }
  EXPECT_GT(roofs, 120);
  EXPECT_LT(roofs, 260);
}

TEST(Generators, TwoPlatesAreThin) {
  const auto p = gen(Distribution::kTwoPlates, 20000);
  std::size_t low = 0;
  for (std::size_t i = 0; i < p.size(); i += 3) {
    const double z = p[i + 2];
    ASSERT_TRUE(std::fabs(z - 0.25) <= 0.001 || std::fabs(z - 0.75) <= 0.001) << z;
    low += z < 0.5;
  }
  EXPECT_NEAR(double(low) / 20000, 0.5, 0.02);
}

TEST(Generators, OptionsAreValidated) {
  GeneratorOptions o;
  o.n = 0;
  EXPECT_THROW(o.validate(), UsageError);
  o.n = 10;
  o.duplicates = 1.0;
  EXPECT_THROW(o.validate(), UsageError);
  o.duplicates = 0;
  o.axes = {1, 0, 1};
  EXPECT_THROW(o.validate(), UsageError);
  EXPECT_THROW(parse_distribution("gaussian"), UsageError);
  EXPECT_EQ(parse_distribution("ellipsoid-shell"), Distribution::kEllipsoidShell);
}
