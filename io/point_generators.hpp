#pragma once
// Seeded synthetic point sets for `tetstream gen` and the tests: the paper's
// distributions and the ones that break weak kernels (lattices, cospherical points,
// exact duplicates).
//
// Counter-based: point i is a pure function of (options, i). Every random number of
// point i comes from splitmix64's mixer applied to (seed key, i, draw number), so any
// range [first, first + n) can be generated on any thread, in any chunking, with the
// same result, and 10^10 points need no memory beyond the caller's chunk.
// distribution_help() is the exact description of each shape (also in docs/inputs.md).
#include <array>
#include <memory>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace tetstream::io {

class LidarTile;
class IndoorScan;
class CosmicWeb;

enum class Distribution {
  kUniform,
  kBall,
  kEllipsoidShell,
  kMixed,
  kClusters,
  kGrid,
  kSphere,
  kTerrain,
  kTwoPlates,
  // The surface zoo (io/point_zoo.hpp): what real scans have, one feature at a time, then all.
  kHills,
  kRoofs,
  kCanopy,
  kWater,
  kStrips,
  kScanLines,
  kSurvey,
  kIndoor,
  // A periodic box with an N-body snapshot's haloes, filaments and voids (io/point_cosmic.hpp).
  kCosmic
};

const char* to_string(Distribution d);
Distribution parse_distribution(std::string_view name);  // throws UsageError
const char* distribution_help();

struct GeneratorOptions {
  Distribution dist = Distribution::kUniform;
  std::uint64_t n = 1000;  // grid: rounded to the nearest cube k^3
  std::uint64_t seed = 1;
  double duplicates = 0.0;                    // fraction of points that copy an earlier point, in [0, 1)
  std::array<double, 3> axes{1.0, 0.6, 0.3};  // ellipsoid-shell semi-axes
  double spread = 0.01;                       // ellipsoid-shell radial spread; mixed noise radius
  std::uint32_t clusters = 32;                // clusters: number of Gaussian clusters
  static constexpr std::uint32_t kMaxClusters = std::uint32_t(1) << 20;
  double radius = 1.0;  // sphere radius

  void validate() const;  // throws UsageError
};

class PointGenerator {
 public:
  explicit PointGenerator(const GeneratorOptions& options);

  ~PointGenerator();
  PointGenerator(const PointGenerator&);
  PointGenerator& operator=(const PointGenerator&);

  // Number of points generated: n, or k^3 for grid.
  std::uint64_t count() const { return count_; }
  // Writes points [first, first + n) as x, y, z into xyz[0 .. 3n). Thread-safe.
  void generate(std::uint64_t first, std::size_t n, double* xyz) const;
  // Whether point i is an injected duplicate, and of which earlier (non-duplicate) point.
  bool is_duplicate(std::uint64_t i, std::uint64_t* source = nullptr) const;

 private:
  void base_point(std::uint64_t i, double* p) const;  // the distribution, no duplicates

  GeneratorOptions opt_;
  std::uint64_t count_ = 0;
  std::uint64_t key_point_ = 0, key_dup_ = 0;
  // grid
  std::uint64_t k_ = 0;
  double h_ = 0;
  // ellipsoid-shell: max of the area element, for the rejection step
  double shell_gmax_ = 0;
  double terrain_phase_[4] = {0, 0, 0, 0};  // the terrain's height field, drawn from the seed
  std::uint64_t key_buildings_ = 0;         // which 40 m cells hold a building, and how high
  // clusters
  struct Cluster {
    double centre[3];
    double sigma;
  };
  std::vector<Cluster> clusters_;
  std::vector<double> cluster_cdf_;
  // the zoo
  std::shared_ptr<const LidarTile> tile_;
  std::shared_ptr<const IndoorScan> indoor_;
  std::shared_ptr<const CosmicWeb> cosmic_;
};

}  // namespace tetstream::io
