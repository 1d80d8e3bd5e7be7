#pragma once
// `gen --dist cosmic`: a periodic box [0, 1)^3 with what an N-body snapshot at low
// redshift has, for the periodic job (docs/periodic.md): haloes with cuspy profiles over
// three decades of mass, filaments between the nodes of a web, and voids (about a tenth
// of the volume, each up to a quarter of the box across) at about 6% of the mean density.
// Large empty balls where voids
// meet the box's faces are what make a periodic margin grow; dense haloes make windows
// uneven. Counter-based like the other generators: point i is a pure function of the
// seed and i, and the web (nodes, filaments, haloes, voids) is drawn once from the seed.
#include <cstdint>
#include <vector>

namespace tetstream::io {

namespace rng {
class PointRng;
}

class CosmicWeb {
 public:
  explicit CosmicWeb(std::uint64_t seed);

  // Point i from its own generator: one of the three components, wrapped into [0, 1).
  void point(rng::PointRng& rng, double* p) const;

  // The model, for the tests.
  struct Void {
    double centre[3], radius;
  };
  struct Halo {
    double centre[3], radius;
  };
  struct Filament {
    double from[3], to[3];  // `to` unwrapped: the shortest periodic way from `from`
  };
  static constexpr double kHaloFraction = 0.5, kFilamentFraction = 0.3;  // the rest: the field
  static constexpr double kVoidDensity = 0.3;                            // kept in a void, of the field
  const std::vector<Void>& voids() const { return voids_; }
  const std::vector<Halo>& haloes() const { return haloes_; }
  const std::vector<Filament>& filaments() const { return filaments_; }
  // Whether p (in [0, 1)^3) lies in a void, periodically.
  bool in_void(const double* p) const;

 private:
  std::vector<Void> voids_;
  std::vector<Halo> haloes_;
  std::vector<double> halo_cdf_;  // by mass
  std::vector<Filament> filaments_;
  std::vector<double> filament_cdf_;  // by length
};

}  // namespace tetstream::io
