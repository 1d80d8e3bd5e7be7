// Generators: reproducible by seed, independent of chunking, and the documented shapes
// (io/point_generators.hpp, docs/inputs.md). A failing test prints its seed.
#include "core/error.hpp"
#include "io/point_cosmic.hpp"
#include "io/point_generators.hpp"
#include "io/point_rng.hpp"
#include "io/point_zoo.hpp"

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

const Distribution kAll[] = {Distribution::kUniform, Distribution::kBall,     Distribution::kEllipsoidShell,
                             Distribution::kMixed,   Distribution::kClusters, Distribution::kGrid,
                             Distribution::kSphere,  Distribution::kTerrain,  Distribution::kTwoPlates,
                             Distribution::kHills,   Distribution::kRoofs,    Distribution::kCanopy,
                             Distribution::kWater,   Distribution::kStrips,   Distribution::kScanLines,
                             Distribution::kSurvey,  Distribution::kIndoor,   Distribution::kCosmic};

// The airborne members of the zoo, whose tile's side follows n.
bool is_tile(Distribution d) {
  return d == Distribution::kHills || d == Distribution::kRoofs || d == Distribution::kCanopy ||
         d == Distribution::kWater || d == Distribution::kStrips || d == Distribution::kScanLines ||
         d == Distribution::kSurvey;
}

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
      if (d != Distribution::kGrid && !is_tile(d)) {
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
  for (auto [n, k] :
       {std::pair<std::uint64_t, std::uint64_t>{1, 1}, {1000, 10}, {1100, 10}, {1200, 11}, {1331, 11}, {30, 3}}) {
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

// ---- The surface zoo (io/point_zoo.hpp): each feature checked against the model ----

namespace {

struct TilePoints {
  LidarTile tile;
  std::vector<double> xyz;  // local metres: the offsets taken off
};

LidarTile::Preset preset_of(Distribution d) {
  switch (d) {
    case Distribution::kHills:
      return LidarTile::Preset::kHills;
    case Distribution::kRoofs:
      return LidarTile::Preset::kRoofs;
    case Distribution::kCanopy:
      return LidarTile::Preset::kCanopy;
    case Distribution::kWater:
      return LidarTile::Preset::kWater;
    case Distribution::kStrips:
      return LidarTile::Preset::kStrips;
    case Distribution::kScanLines:
      return LidarTile::Preset::kScanLines;
    default:
      return LidarTile::Preset::kSurvey;
  }
}

TilePoints tile_points(Distribution d, std::uint64_t n) {
  TilePoints t{LidarTile(preset_of(d), kSeed, n), gen(d, n)};
  for (std::size_t i = 0; i < t.xyz.size(); i += 3) {
    t.xyz[i] -= LidarTile::kOffsetX, t.xyz[i + 1] -= LidarTile::kOffsetY, t.xyz[i + 2] -= LidarTile::kOffsetZ;
  }
  return t;
}

// Whether (x, y, z), quantised, lies on a roof: a footprint within a centimetre of it
// and the roof's height there within 2 cm.
bool on_roof(const LidarTile& tile, double x, double y, double z) {
  for (double dx : {-0.01, 0.0, 0.01}) {
    for (double dy : {-0.01, 0.0, 0.01}) {
      LidarTile::Building b;
      if (tile.building_at(x + dx, y + dy, &b) && std::fabs(tile.roof(b, x + dx, y + dy) - z) <= 0.02) return true;
    }
  }
  return false;
}

bool deep_in_hole(const LidarTile& tile, double x, double y) {
  for (double dx : {-0.01, 0.0, 0.01})
    for (double dy : {-0.01, 0.0, 0.01})
      if (!tile.in_hole(x + dx, y + dy)) return false;
  return true;
}

}  // namespace

TEST(GeneratorsZoo, TilesAreCentimetreQuantisedInTheirSquare) {
  for (Distribution d : kAll) {
    if (!is_tile(d)) continue;
    SCOPED_TRACE(to_string(d));
    const auto t = tile_points(d, 20000);
    ASSERT_EQ(t.xyz.size(), 3u * 20000);
    EXPECT_EQ(t.tile.side(), 100.0) << "the smallest tile: 20000 points are fewer than 100 m x 100 m holds";
    const auto p = gen(d, 20000);
    for (std::size_t i = 0; i < p.size(); i += 3) {
      ASSERT_GE(t.xyz[i], -1e-6);
      ASSERT_LE(t.xyz[i], t.tile.side() + 1e-6);
      ASSERT_GE(t.xyz[i + 1], -1e-6);
      ASSERT_LE(t.xyz[i + 1], t.tile.side() + 1e-6);
      ASSERT_GT(t.xyz[i + 2], -100.0);
      ASSERT_LT(t.xyz[i + 2], 100.0);
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(p[i + c] * 100, std::round(p[i + c] * 100), 1e-3) << "centimetres";
    }
  }
  // The side follows n: 10^6 points at 0.3 m x 1 m a point need 548 m.
  EXPECT_EQ(LidarTile(LidarTile::Preset::kScanLines, kSeed, 1000000).side(), 548.0);
}

TEST(GeneratorsZoo, HillsRiseAcrossTheTile) {
  const auto t = tile_points(Distribution::kHills, 20000);
  double lo = 1e300, hi = -1e300;
  for (std::size_t i = 0; i < t.xyz.size(); i += 3) {
    ASSERT_NEAR(t.xyz[i + 2], t.tile.ground(t.xyz[i], t.xyz[i + 1]), 0.05) << "bare ground";
    lo = std::min(lo, t.xyz[i + 2]), hi = std::max(hi, t.xyz[i + 2]);
  }
  EXPECT_GT(hi - lo, 0.15 * t.tile.side());
}

// Airborne scanners rarely hit walls: every point is on the ground or on a roof.
TEST(GeneratorsZoo, RoofsWithoutWallReturns) {
  const auto t = tile_points(Distribution::kRoofs, 50000);
  std::size_t roofs = 0, ground = 0;
  std::set<double> flat_heights;
  for (std::size_t i = 0; i < t.xyz.size(); i += 3) {
    const double x = t.xyz[i], y = t.xyz[i + 1], z = t.xyz[i + 2];
    if (on_roof(t.tile, x, y, z))
      ++roofs;
    else if (std::fabs(z - t.tile.ground(x, y)) <= 0.05)
      ++ground;
    else
      ADD_FAILURE() << "a point neither on the ground nor on a roof (a wall?) at " << x << " " << y << " " << z;
  }
  EXPECT_GT(double(roofs) / 50000, 0.05);
  EXPECT_GT(double(ground) / 50000, 0.5);
  // Both kinds of roof appear.
  int flat = 0, gable = 0;
  for (std::int64_t cx = 0; cx < 3; ++cx) {
    for (std::int64_t cy = 0; cy < 3; ++cy) {
      LidarTile::Building b;
      for (std::uint64_t seed = 1; seed <= 10; ++seed) {
        if (LidarTile(LidarTile::Preset::kRoofs, seed, 20000).building(cx, cy, &b)) (b.gable ? gable : flat)++;
      }
    }
  }
  EXPECT_GT(flat, 5);
  EXPECT_GT(gable, 5);
}

TEST(GeneratorsZoo, CanopyPulsesHaveSeveralReturns) {
  const auto t = tile_points(Distribution::kCanopy, 30000);
  std::size_t multi = 0, high = 0;
  double lo = 1e300, hi = -1e300;
  for (std::size_t g = 0; g + 9 <= t.xyz.size(); g += 9) {
    const double* p = &t.xyz[g];
    // One pulse: the same y, the first return above the others, the last on the ground.
    if (p[1] == p[4] && p[1] == p[7] && p[2] >= p[5] && p[5] > p[8] + 0.5 &&
        std::fabs(p[8] - t.tile.ground(p[6], p[7])) <= 0.02)
      ++multi;
  }
  for (std::size_t i = 0; i < t.xyz.size(); i += 3) {
    const double above = t.xyz[i + 2] - t.tile.ground(t.xyz[i], t.xyz[i + 1]);
    if (above > 2) ++high, lo = std::min(lo, above), hi = std::max(hi, above);
  }
  EXPECT_GT(double(multi) / 10000, 0.25) << "pulses with three returns through a crown";
  EXPECT_GT(double(high) / 30000, 0.35) << "vegetation returns";
  EXPECT_GT(hi - lo, 10.0) << "a thick layer";
}

TEST(GeneratorsZoo, WaterAndShadowsHaveNoReturns) {
  const auto t = tile_points(Distribution::kWater, 50000);
  ASSERT_FALSE(t.tile.lakes().empty());
  for (std::size_t i = 0; i < t.xyz.size(); i += 3)
    ASSERT_FALSE(deep_in_hole(t.tile, t.xyz[i], t.xyz[i + 1])) << t.xyz[i] << " " << t.xyz[i + 1];
  // The holes are there: a fine grid over the tile finds lake and shadow cells, and
  // without them as many points would fall in them as their area's share.
  std::size_t cells = 0, lake = 0, shadow = 0;
  for (double x = 0.25; x < t.tile.side(); x += 0.5) {
    for (double y = 0.25; y < t.tile.side(); y += 0.5) {
      ++cells;
      if (!t.tile.in_hole(x, y)) continue;
      bool in_lake = false;
      for (const auto& l : t.tile.lakes()) {
        const double dx = (x - l.centre[0]) / l.radii[0], dy = (y - l.centre[1]) / l.radii[1];
        in_lake |= dx * dx + dy * dy <= 1;
      }
      (in_lake ? lake : shadow)++;
    }
  }
  EXPECT_GT(double(lake) / double(cells), 0.005);
  EXPECT_GT(shadow, 0u);
}

TEST(GeneratorsZoo, OverlappingStripsDoubleTheDensity) {
  const auto t = tile_points(Distribution::kStrips, 100000);
  ASSERT_GE(t.tile.strips(), 2);
  const double w = t.tile.strip_width(), x1 = t.tile.strip_x0(1);
  // Strip 0 alone on [0, x1), strips 0 and 1 on [x1, w).
  std::size_t single = 0, both = 0;
  for (std::size_t i = 0; i < t.xyz.size(); i += 3) {
    const double x = t.xyz[i];
    if (x > 1 && x < x1 - 1)
      ++single;
    else if (x > x1 + 1 && x < w - 1)
      ++both;
  }
  const double ratio = (double(both) / (w - x1 - 2)) / (double(single) / (x1 - 2));
  EXPECT_NEAR(ratio, 2.0, 0.15);
}

TEST(GeneratorsZoo, ScanLinesAreOneMetreApartAndDenseAlong) {
  const std::uint64_t n = 100000;
  const auto t = tile_points(Distribution::kScanLines, n);
  // Every y within 3 cm (2 cm wobble, 1 cm quantisation) of one phase modulo 1 m.
  std::map<int, std::size_t> phases;  // centimetre of the metre -> points
  for (std::size_t i = 1; i < t.xyz.size(); i += 3)
    ++phases[int(std::lround((t.xyz[i] - std::floor(t.xyz[i])) * 100)) % 100];
  std::size_t best = 0;
  int phase = 0;
  for (int c = 0; c < 100; ++c) {
    std::size_t near = 0;
    for (int k = -3; k <= 3; ++k) {
      const auto it = phases.find((c + k + 100) % 100);
      near += it == phases.end() ? 0 : it->second;
    }
    if (near > best) best = near, phase = c;
  }
  EXPECT_EQ(best, n);
  // About 0.3 m between neighbours along a line.
  std::map<long, std::vector<double>> lines;
  for (std::size_t i = 0; i < t.xyz.size(); i += 3)
    lines[std::lround(t.xyz[i + 1] - phase / 100.0)].push_back(t.xyz[i]);
  double gaps = 0, count = 0;
  for (auto& [k, xs] : lines) {
    std::sort(xs.begin(), xs.end());
    gaps += xs.back() - xs.front(), count += double(xs.size() - 1);
  }
  EXPECT_NEAR(gaps / count, 0.3, 0.03);
}

TEST(GeneratorsZoo, SurveyHasEveryFeature) {
  const auto t = tile_points(Distribution::kSurvey, 100000);
  EXPECT_GE(t.tile.strips(), 2);
  EXPECT_FALSE(t.tile.lakes().empty());
  std::size_t roofs = 0, trees = 0;
  for (std::size_t i = 0; i < t.xyz.size(); i += 3) {
    const double x = t.xyz[i], y = t.xyz[i + 1], z = t.xyz[i + 2];
    ASSERT_FALSE(deep_in_hole(t.tile, x, y));
    if (on_roof(t.tile, x, y, z))
      ++roofs;
    else if (z - t.tile.ground(x, y) > 2)
      ++trees;
  }
  EXPECT_GT(roofs, 1000u);
  EXPECT_GT(trees, 2000u);
}

// Floors, walls and ceilings at right angles: every point within the range noise of a
// face of its room; the floor's density falls with the distance from the scanner.
TEST(GeneratorsZoo, IndoorScanIsPlanesAroundScanners) {
  const auto p = gen(Distribution::kIndoor, 50000);
  const IndoorScan scan(kSeed);
  ASSERT_EQ(scan.rooms().size(), 6u);
  std::size_t near_floor = 0, far_floor = 0;
  for (std::size_t i = 0; i < p.size(); i += 3) {
    bool on_face = false;
    for (const auto& room : scan.rooms()) {
      bool inside = true;
      double face = 1e300;
      for (int c = 0; c < 3; ++c) {
        inside &= p[i + c] >= room.lo[c] - 0.003 && p[i + c] <= room.hi[c] + 0.003;
        face = std::min({face, std::fabs(p[i + c] - room.lo[c]), std::fabs(p[i + c] - room.hi[c])});
      }
      if (!inside || face > 0.003) continue;
      on_face = true;
      if (std::fabs(p[i + 2] - room.lo[2]) <= 0.003) {
        const double r = std::hypot(p[i] - room.scanner[0], p[i + 1] - room.scanner[1]);
        near_floor += r >= 0.5 && r < 1.0;
        far_floor += r >= 2.5 && r < 3.0;
      }
    }
    ASSERT_TRUE(on_face) << p[i] << " " << p[i + 1] << " " << p[i + 2];
  }
  // Per square metre (rings of areas 0.75 pi and 2.75 pi), the near ring is denser
  // (whatever walls cut the far one).
  EXPECT_GT(double(near_floor) / 0.75, 3 * double(far_floor) / 2.75);
}

TEST(Generators, CosmicIsAPeriodicWebOfHaloesFilamentsAndVoids) {
  constexpr std::uint64_t n = 200000;
  const auto p = gen(Distribution::kCosmic, n);
  const CosmicWeb web(kSeed);
  ASSERT_EQ(web.voids().size(), 40u);
  ASSERT_EQ(web.haloes().size(), 4096u);
  ASSERT_GT(web.filaments().size(), 64u);
  // Every point in the box, as a snapshot's wrapped positions are.
  for (double v : p) ASSERT_TRUE(v >= 0.0 && v < 1.0) << v;
  // The voids: their volume's share of the box (by sampling), and the points in them,
  // about 30% of the field's and filaments' share of it.
  rng::PointRng r(7, 0);
  std::uint64_t hits = 0;
  constexpr int kSamples = 200000;
  for (int s = 0; s < kSamples; ++s) {
    const double q[3] = {r.uniform(), r.uniform(), r.uniform()};
    hits += web.in_void(q);
  }
  const double void_volume = double(hits) / kSamples;
  std::uint64_t in_voids = 0;
  for (std::uint64_t i = 0; i < n; ++i) in_voids += web.in_void(&p[3 * i]);
  const double expected = 0.5 * void_volume * CosmicWeb::kVoidDensity;  // the field and filaments thinned
  EXPECT_GT(void_volume, 0.05);
  EXPECT_LT(double(in_voids) / double(n), 2.5 * expected + 0.002) << void_volume;
  // The haloes: half the points within their radii of a centre, far above the share of
  // the box the haloes fill.
  std::uint64_t in_haloes = 0;
  for (std::uint64_t i = 0; i < n; i += 20) {
    const double* q = &p[3 * i];
    const bool in = std::any_of(web.haloes().begin(), web.haloes().end(), [&](const CosmicWeb::Halo& h) {
      double d2 = 0;
      for (int k = 0; k < 3; ++k) {
        double d = std::fabs(q[k] - h.centre[k]);
        d = std::min(d, 1 - d);
        d2 += d * d;
      }
      return d2 <= h.radius * h.radius;
    });
    in_haloes += in;
  }
  EXPECT_GT(double(in_haloes) / double(n / 20), CosmicWeb::kHaloFraction * 0.98);
  // Periodic: haloes that straddle a face put points near both of its sides.
  std::uint64_t low = 0, high = 0;
  for (std::uint64_t i = 0; i < n; ++i) low += p[3 * i]<0.01, high += p[3 * i]> 0.99;
  EXPECT_GT(low, 0u);
  EXPECT_GT(high, 0u);
}
