#include "io/point_generators.hpp"

#include "core/error.hpp"
#include "io/point_cosmic.hpp"
#include "io/point_rng.hpp"
#include "io/point_zoo.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace tetstream::io {

namespace {

using rng::key_for;
using rng::PointRng;

// Distinct keys for the independent uses of one seed.
constexpr std::uint64_t kPurposePoint = 0x706f696e74ULL;    // "point"
constexpr std::uint64_t kPurposeDup = 0x6475706cULL;        // "dupl"
constexpr std::uint64_t kPurposeClusters = 0x636c7573ULL;   // "clus"
constexpr std::uint64_t kPurposeTerrain = 0x74657272ULL;    // "terr"
constexpr std::uint64_t kPurposeBuildings = 0x626c6467ULL;  // "bldg"

// The terrain: a 1 km x 1 km airborne LiDAR tile (see distribution_help).
constexpr double kTileMetres = 1000, kCellMetres = 40, kFootprintMetres = 24;
constexpr double kOffsetX = 500000, kOffsetY = 4000000, kOffsetZ = 100;  // UTM-like

double terrain_ground(const double* phase, double x, double y) {
  constexpr double tau = 2 * std::numbers::pi;
  return 30 * std::sin(tau * x / 700 + phase[0]) * std::cos(tau * y / 900 + phase[1]) +
         8 * std::sin(tau * (x + y) / 230 + phase[2]) +
         1.5 * std::sin(tau * x / 57 + phase[3]) * std::sin(tau * y / 43);
}

// The building of 40 m cell (cx, cy), if any: 30% of the cells hold one, a 24 m square
// in the cell's middle with a flat roof 5 to 25 m above the ground at its centre.
bool terrain_building(std::uint64_t key, const double* phase, std::int64_t cx, std::int64_t cy, double* lo, double* hi,
                      double* roof) {
  PointRng rng(key, std::uint64_t(cx) * 1000003u + std::uint64_t(cy));
  if (!(rng.uniform() < 0.3)) return false;
  const double margin = (kCellMetres - kFootprintMetres) / 2;
  lo[0] = double(cx) * kCellMetres + margin, lo[1] = double(cy) * kCellMetres + margin;
  hi[0] = lo[0] + kFootprintMetres, hi[1] = lo[1] + kFootprintMetres;
  *roof = terrain_ground(phase, lo[0] + kFootprintMetres / 2, lo[1] + kFootprintMetres / 2) + 5 + 20 * rng.uniform();
  return true;
}

// A centimetre-quantised coordinate, as a LAS file with scale 0.01 stores it.
double centimetres(double v) { return std::round(v * 100) / 100; }

void terrain_point(PointRng& rng, std::uint64_t key_buildings, const double* phase, double* p) {
  const double kind = rng.uniform();
  double x = kTileMetres * rng.uniform(), y = kTileMetres * rng.uniform();
  double ground = terrain_ground(phase, x, y), z = ground;
  double lo[2], hi[2], roof = 0;
  const auto cx = std::int64_t(x / kCellMetres), cy = std::int64_t(y / kCellMetres);
  const bool building = terrain_building(key_buildings, phase, cx, cy, lo, hi, &roof);
  const bool inside = building && x >= lo[0] && x <= hi[0] && y >= lo[1] && y <= hi[1];
  if (kind < 0.08 && building) {
    // A wall: the point moved to the nearest side of the footprint, anywhere up to the roof.
    const double d[4] = {x - lo[0], hi[0] - x, y - lo[1], hi[1] - y};
    const int side = int(std::min_element(d, d + 4) - d);
    if (side == 0)
      x = lo[0];
    else if (side == 1)
      x = hi[0];
    else if (side == 2)
      y = lo[1];
    else
      y = hi[1];
    x = std::clamp(x, lo[0], hi[0]), y = std::clamp(y, lo[1], hi[1]);
    ground = terrain_ground(phase, x, y);
    z = ground + (roof - ground) * rng.uniform();
  } else if (inside) {
    z = roof;  // flat roofs: many coplanar points
  } else if (kind < 0.2) {
    z = ground + 15 * rng.uniform() * rng.uniform();  // vegetation returns, mostly low
  }
  p[0] = centimetres(x) + kOffsetX, p[1] = centimetres(y) + kOffsetY, p[2] = centimetres(z + kOffsetZ);
}

}  // namespace

const char* to_string(Distribution d) {
  switch (d) {
    case Distribution::kUniform:
      return "uniform";
    case Distribution::kBall:
      return "ball";
    case Distribution::kEllipsoidShell:
      return "ellipsoid-shell";
    case Distribution::kMixed:
      return "mixed";
    case Distribution::kClusters:
      return "clusters";
    case Distribution::kGrid:
      return "grid";
    case Distribution::kSphere:
      return "sphere";
    case Distribution::kTerrain:
      return "terrain";
    case Distribution::kTwoPlates:
      return "two-plates";
    case Distribution::kHills:
      return "hills";
    case Distribution::kRoofs:
      return "roofs";
    case Distribution::kCanopy:
      return "canopy";
    case Distribution::kWater:
      return "water";
    case Distribution::kStrips:
      return "strips";
    case Distribution::kScanLines:
      return "scan-lines";
    case Distribution::kSurvey:
      return "survey";
    case Distribution::kIndoor:
      return "indoor";
    case Distribution::kCosmic:
      return "cosmic";
  }
  return "?";
}

Distribution parse_distribution(std::string_view name) {
  for (Distribution d : {Distribution::kUniform, Distribution::kBall, Distribution::kEllipsoidShell,
                         Distribution::kMixed, Distribution::kClusters, Distribution::kGrid, Distribution::kSphere,
                         Distribution::kTerrain, Distribution::kTwoPlates, Distribution::kHills, Distribution::kRoofs,
                         Distribution::kCanopy, Distribution::kWater, Distribution::kStrips, Distribution::kScanLines,
                         Distribution::kSurvey, Distribution::kIndoor, Distribution::kCosmic}) {
    if (name == to_string(d)) return d;
  }
  if (name == "shell" || name == "ellipsoid") return Distribution::kEllipsoidShell;
  if (name == "lidar") return Distribution::kTerrain;
  if (name == "nbody") return Distribution::kCosmic;
  throw UsageError("unknown distribution '" + std::string(name) +
                   "' (expected uniform, ball, ellipsoid-shell, mixed, clusters, grid, sphere, terrain, "
                   "two-plates, hills, roofs, canopy, water, strips, scan-lines, survey, indoor or cosmic)");
}

const char* distribution_help() {
  return "Distributions (point i depends only on --seed and i, and on --n for the zoo's tiles;\n"
         "any chunking or thread count gives the same file):\n"
         "  uniform          x, y, z uniform in [0, 1) (multiples of 2^-53).\n"
         "  ball             uniform in the unit ball centred at 0: x^2+y^2+z^2 <= 1 exactly\n"
         "                   (rejection sampling from [-1, 1)^3).\n"
         "  ellipsoid-shell  area-uniform on the ellipsoid centred at 0 with semi-axes --axes a,b,c\n"
         "                   (default 1,0.6,0.3), each point scaled radially by a factor uniform in\n"
         "                   [1 - s, 1 + s], s = --spread (default 0.01): (x/a)^2+(y/b)^2+(z/c)^2\n"
         "                   lies in [(1-s)^2, (1+s)^2].\n"
         "  mixed            the paper's mixed patterns in the unit cube, one third each (by a\n"
         "                   random draw): a line from (0.05,0.05,0.05) to (0.95,0.95,0.95); the\n"
         "                   ellipsoid surface centred at (0.5,0.5,0.5) with semi-axes\n"
         "                   (0.45,0.3,0.2); a helix of radius 0.4 around the vertical line through\n"
         "                   (0.5,0.5), z from 0.05 to 0.95, 5 turns. Each point is moved by a\n"
         "                   uniform offset in a ball of radius --spread (default 0.01, 1% of the\n"
         "                   box).\n"
         "  clusters         --clusters K (default 32) Gaussian clusters: centres uniform in\n"
         "                   [0.1, 0.9]^3, standard deviations log-uniform in [0.001, 0.05],\n"
         "                   weights uniform in [0.1, 1.1] (normalised); all drawn from the seed.\n"
         "  grid             the regular lattice (ix, iy, iz) * h, 0 <= i < k, h = 2^-ceil(log2 k),\n"
         "                   coordinates exact in [0, 1); --n is rounded to the nearest cube k^3;\n"
         "                   x varies fastest. Degenerate: many cospherical and coplanar points.\n"
         "  sphere           on the sphere of radius --radius (default 1) centred at 0: normalised\n"
         "                   Gaussian vectors, so |p| = r up to rounding (within 1e-15 r).\n"
         "  terrain          (alias lidar) an airborne LiDAR tile of 1 km x 1 km: a height field of\n"
         "                   hills (about +-40 m) with 24 m square buildings in 30% of the 40 m\n"
         "                   cells (flat roofs 5-25 m up), 8% of the points on their walls and 12%\n"
         "                   vegetation returns up to 15 m above the ground; UTM-like offsets\n"
         "                   (x + 500000, y + 4000000, z + 100) and 1 cm quantisation, as a LAS\n"
         "                   file with scale 0.01 holds them. A surface: most tets are flat.\n"
         "  two-plates       two parallel plates, z = 0.25 and z = 0.75 (one point in two on each),\n"
         "                   x, y uniform in [0, 1), z jittered uniformly by +-0.1 * --spread.\n"
         "The surface zoo: airborne tiles with what real surveys have, x + 500000, y + 5000000,\n"
         "z + 200, 1 cm quantisation; the square's side follows --n (about 3.3 points a square\n"
         "metre under one flight strip, at least 100 m), so point i depends on --n too:\n"
         "  hills            bare ground of steep hills as wide as the tile (+-12% of its side):\n"
         "                   the hull spans the valleys, long edges under it.\n"
         "  roofs            gentle ground, buildings on 35% of the 40 m cells, 10-28 m footprints,\n"
         "                   half flat roofs 4-20 m up, half gable roofs (25-40 degrees); no wall\n"
         "                   returns, as airborne scanners rarely hit walls.\n"
         "  canopy           gentle ground under a forest (a tree in 85% of the 8 m cells, crowns\n"
         "                   2-4.5 m in radius, 6-22 m tall): a pulse that meets a crown gives three\n"
         "                   points (first return near the top, one inside the crown, the ground)\n"
         "                   along its slanted path: a thick layer of vegetation.\n"
         "  water            lakes and the scan shadows beyond buildings' +x walls: holes with no\n"
         "                   returns; buildings on 20% of the cells.\n"
         "  strips           overlapping flight strips along y (30% of a strip's width shared with\n"
         "                   the next: bands of double density), on scan lines.\n"
         "  scan-lines       points on lines across the flight direction, 1 m apart (+-2 cm), about\n"
         "                   0.3 m apart along a line.\n"
         "  survey           all of it: hills, flat and gable roofs without walls, trees with multiple\n"
         "                   returns, lakes and shadows, overlapping strips, scan lines.\n"
         "  indoor           a terrestrial scan of 3 x 2 closed rooms (5-9 m x 4-7 m, one ceiling\n"
         "                   height 2.6-3.2 m, walls 0.2 m thick), a scanner 1.5 m up in each:\n"
         "                   points on floors, walls and ceilings meeting at right angles, their\n"
         "                   density falling with the square of the distance to the scanner; 2 mm\n"
         "                   range noise, millimetre quantisation, local coordinates.\n"
         "A periodic box, for --periodic 1:\n"
         "  cosmic           (alias nbody) [0, 1)^3 as an N-body snapshot at low redshift has it,\n"
         "                   every point wrapped into the box: half the points in 4096 haloes\n"
         "                   (masses over three decades, dn/dm ~ m^-1.9, radius 0.004 m^(1/3), a\n"
         "                   cusp: r = R u^2), 60% of them on filaments; 30% along the filaments\n"
         "                   that join each of 64 nodes to its 3 nearest (Gaussian cross-section of\n"
         "                   0.004); 20% uniform; 40 voids clear of the nodes, radii 0.04-0.12,\n"
         "                   keep 30% of the filaments' and the field's points. The web is\n"
         "                   drawn from the seed.\n"
         "--duplicates F: each point i > 0 is, with probability F, an exact copy of point\n"
         "floor(v * i) for a uniform v (resolved to an original point), so about F * n points\n"
         "repeat an earlier one.\n";
}

void GeneratorOptions::validate() const {
  if (n == 0) throw UsageError("--n must be at least 1");
  if (!(duplicates >= 0.0 && duplicates < 1.0)) throw UsageError("--duplicates must be in [0, 1)");
  for (double a : axes) {
    if (!(a > 0.0 && std::isfinite(a))) throw UsageError("--axes must be three positive numbers");
  }
  if (!(spread >= 0.0 && spread < 0.5)) throw UsageError("--spread must be in [0, 0.5)");
  if (clusters == 0) throw UsageError("--clusters must be at least 1");
  // The clusters are held in memory (about 64 bytes each, and a table to draw them):
  // bounded so that a typo cannot take the machine's memory.
  if (clusters > kMaxClusters)
    throw UsageError("--clusters " + std::to_string(clusters) + " is more than the " + std::to_string(kMaxClusters) +
                     " this generator holds");
  if (!(radius > 0.0 && std::isfinite(radius))) throw UsageError("--radius must be positive");
}

PointGenerator::~PointGenerator() = default;
PointGenerator::PointGenerator(const PointGenerator&) = default;
PointGenerator& PointGenerator::operator=(const PointGenerator&) = default;

PointGenerator::PointGenerator(const GeneratorOptions& options) : opt_(options) {
  opt_.validate();
  key_point_ = key_for(opt_.seed, kPurposePoint);
  key_dup_ = key_for(opt_.seed, kPurposeDup);
  count_ = opt_.n;
  switch (opt_.dist) {
    case Distribution::kGrid: {
      auto k = static_cast<std::uint64_t>(std::llround(std::cbrt(double(opt_.n))));
      // cbrt of a huge n may be off by one: take the k whose cube is nearest n.
      auto dist = [&](std::uint64_t c) {
        const double cube = double(c) * double(c) * double(c);
        return std::fabs(cube - double(opt_.n));
      };
      while (k > 1 && dist(k - 1) < dist(k)) --k;
      while (dist(k + 1) < dist(k)) ++k;
      k_ = std::max<std::uint64_t>(k, 1);
      if (k_ > 2097151) throw UsageError("--n too large for a grid (k^3 must fit in 64 bits)");
      count_ = k_ * k_ * k_;
      int e = 0;
      while ((std::uint64_t(1) << e) < k_) ++e;
      h_ = std::ldexp(1.0, -e);
      break;
    }
    case Distribution::kEllipsoidShell: {
      const double a = opt_.axes[0], b = opt_.axes[1], c = opt_.axes[2];
      shell_gmax_ = std::max({b * c, a * c, a * b});
      break;
    }
    case Distribution::kClusters: {
      PointRng rng(key_for(opt_.seed, kPurposeClusters), 0);
      double total = 0;
      for (std::uint32_t i = 0; i < opt_.clusters; ++i) {
        Cluster cl;
        for (double& x : cl.centre) x = 0.1 + 0.8 * rng.uniform();
        cl.sigma = 0.001 * std::pow(50.0, rng.uniform());
        clusters_.push_back(cl);
        total += 0.1 + rng.uniform();
        cluster_cdf_.push_back(total);
      }
      for (double& w : cluster_cdf_) w /= total;
      cluster_cdf_.back() = 1.0;
      break;
    }
    case Distribution::kTerrain: {
      PointRng rng(key_for(opt_.seed, kPurposeTerrain), 0);
      for (double& ph : terrain_phase_) ph = 2 * std::numbers::pi * rng.uniform();
      key_buildings_ = key_for(opt_.seed, kPurposeBuildings);
      break;
    }
    case Distribution::kHills:
      tile_ = std::make_shared<LidarTile>(LidarTile::Preset::kHills, opt_.seed, opt_.n);
      break;
    case Distribution::kRoofs:
      tile_ = std::make_shared<LidarTile>(LidarTile::Preset::kRoofs, opt_.seed, opt_.n);
      break;
    case Distribution::kCanopy:
      tile_ = std::make_shared<LidarTile>(LidarTile::Preset::kCanopy, opt_.seed, opt_.n);
      break;
    case Distribution::kWater:
      tile_ = std::make_shared<LidarTile>(LidarTile::Preset::kWater, opt_.seed, opt_.n);
      break;
    case Distribution::kStrips:
      tile_ = std::make_shared<LidarTile>(LidarTile::Preset::kStrips, opt_.seed, opt_.n);
      break;
    case Distribution::kScanLines:
      tile_ = std::make_shared<LidarTile>(LidarTile::Preset::kScanLines, opt_.seed, opt_.n);
      break;
    case Distribution::kSurvey:
      tile_ = std::make_shared<LidarTile>(LidarTile::Preset::kSurvey, opt_.seed, opt_.n);
      break;
    case Distribution::kIndoor:
      indoor_ = std::make_shared<IndoorScan>(opt_.seed);
      break;
    case Distribution::kCosmic:
      cosmic_ = std::make_shared<CosmicWeb>(opt_.seed);
      break;
    default:
      break;
  }
}

void PointGenerator::base_point(std::uint64_t i, double* p) const {
  PointRng rng(key_point_, i);
  switch (opt_.dist) {
    case Distribution::kUniform:
      p[0] = rng.uniform(), p[1] = rng.uniform(), p[2] = rng.uniform();
      return;
    case Distribution::kBall:
      rng.in_ball(p);
      return;
    case Distribution::kSphere: {
      rng.direction(p);
      if (opt_.radius != 1.0) p[0] *= opt_.radius, p[1] *= opt_.radius, p[2] *= opt_.radius;
      return;
    }
    case Distribution::kEllipsoidShell: {
      const double a = opt_.axes[0], b = opt_.axes[1], c = opt_.axes[2];
      double d[3];
      // Area-uniform: accept direction d with probability (area element at d) / max.
      for (int attempt = 0; attempt < 1000; ++attempt) {
        rng.direction(d);
        const double g = std::sqrt((b * c * d[0]) * (b * c * d[0]) + (a * c * d[1]) * (a * c * d[1]) +
                                   (a * b * d[2]) * (a * b * d[2]));
        if (rng.uniform() * shell_gmax_ <= g) break;
      }
      const double s = 1.0 + opt_.spread * rng.symmetric();
      p[0] = s * a * d[0], p[1] = s * b * d[1], p[2] = s * c * d[2];
      return;
    }
    case Distribution::kMixed: {
      const double pattern = rng.uniform();
      const double t = rng.uniform();
      if (pattern < 1.0 / 3.0) {  // line
        p[0] = p[1] = p[2] = 0.05 + 0.9 * t;
      } else if (pattern < 2.0 / 3.0) {  // ellipsoid surface (direction-uniform)
        double d[3];
        rng.direction(d);
        p[0] = 0.5 + 0.45 * d[0], p[1] = 0.5 + 0.3 * d[1], p[2] = 0.5 + 0.2 * d[2];
      } else {  // helix
        const double angle = 2.0 * std::numbers::pi * 5.0 * t;
        p[0] = 0.5 + 0.4 * std::cos(angle), p[1] = 0.5 + 0.4 * std::sin(angle), p[2] = 0.05 + 0.9 * t;
      }
      double noise[3];
      rng.in_ball(noise);
      for (int c = 0; c < 3; ++c) p[c] += opt_.spread * noise[c];
      return;
    }
    case Distribution::kClusters: {
      const double u = rng.uniform();
      const auto it = std::upper_bound(cluster_cdf_.begin(), cluster_cdf_.end(), u);
      const Cluster& cl = clusters_[std::min<std::size_t>(it - cluster_cdf_.begin(), clusters_.size() - 1)];
      for (int c = 0; c < 3; ++c) p[c] = cl.centre[c] + cl.sigma * rng.normal();
      return;
    }
    case Distribution::kTerrain:
      terrain_point(rng, key_buildings_, terrain_phase_, p);
      return;
    case Distribution::kTwoPlates: {
      const double plate = rng.uniform() < 0.5 ? 0.25 : 0.75;
      p[0] = rng.uniform(), p[1] = rng.uniform(), p[2] = plate + 0.1 * opt_.spread * rng.symmetric();
      return;
    }
    case Distribution::kHills:
    case Distribution::kRoofs:
    case Distribution::kCanopy:
    case Distribution::kWater:
    case Distribution::kStrips:
    case Distribution::kScanLines:
    case Distribution::kSurvey:
      tile_->point(i, p);
      return;
    case Distribution::kIndoor:
      indoor_->point(i, p);
      return;
    case Distribution::kCosmic:
      cosmic_->point(rng, p);
      return;
    case Distribution::kGrid: {
      const std::uint64_t ix = i % k_, iy = (i / k_) % k_, iz = i / (k_ * k_);
      p[0] = double(ix) * h_, p[1] = double(iy) * h_, p[2] = double(iz) * h_;
      return;
    }
  }
}

bool PointGenerator::is_duplicate(std::uint64_t i, std::uint64_t* source) const {
  if (opt_.duplicates <= 0.0 || i == 0) return false;
  std::uint64_t j = i;
  bool dup = false;
  // Follow copies of copies back to an original; each step goes to a smaller index.
  for (;;) {
    if (j == 0) break;
    PointRng rng(key_dup_, j);
    if (!(rng.uniform() < opt_.duplicates)) break;
    dup = true;
    j = std::min<std::uint64_t>(static_cast<std::uint64_t>(rng.uniform() * double(j)), j - 1);
  }
  if (source) *source = j;
  return dup;
}

void PointGenerator::generate(std::uint64_t first, std::size_t n, double* xyz) const {
  for (std::size_t k = 0; k < n; ++k) {
    std::uint64_t i = first + k, src = i;
    if (opt_.duplicates > 0.0) is_duplicate(i, &src);
    base_point(src, xyz + 3 * k);
  }
}

}  // namespace tetstream::io
