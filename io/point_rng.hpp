#pragma once
// The counter-based random numbers of the point generators (point_generators.cpp,
// point_zoo.cpp): every draw of point i is a pure function of (key, i, draw number).
#include <cmath>
#include <cstdint>
#include <numbers>

namespace tetstream::io::rng {

// splitmix64's finaliser: a bijection on 64-bit words with full avalanche.
inline std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

constexpr std::uint64_t kGolden = 0x9e3779b97f4a7c15ULL;

// The random numbers of one point: draw j of point i under key k is
// mix64(mix64(k ^ mix64(i)) + j * golden), splitmix64's sequence started at a
// per-point state.
class PointRng {
 public:
  PointRng(std::uint64_t key, std::uint64_t index) : state_(mix64(key ^ mix64(index + kGolden))) {}
  std::uint64_t next() { return mix64(state_ += kGolden); }
  // Uniform in [0, 1) on the 2^-53 grid.
  double uniform() { return double(next() >> 11) * 0x1p-53; }
  // Uniform in [-1, 1), exactly: 2u - 1 loses no bits.
  double symmetric() { return 2.0 * uniform() - 1.0; }
  // Standard normal (Box-Muller; u1 in (0, 1] so the log is finite).
  double normal() {
    if (have_spare_) {
      have_spare_ = false;
      return spare_;
    }
    const double u1 = 1.0 - uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * std::numbers::pi * u2);
    have_spare_ = true;
    return r * std::cos(2.0 * std::numbers::pi * u2);
  }
  // Uniform direction: a normalised Gaussian vector.
  void direction(double* d) {
    for (;;) {
      d[0] = normal(), d[1] = normal(), d[2] = normal();
      const double r = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      if (r > 1e-150) {
        d[0] /= r, d[1] /= r, d[2] /= r;
        return;
      }
    }
  }
  // Uniform in the ball of radius 1 by rejection from [-1, 1)^3: x^2 + y^2 + z^2 <= 1
  // holds exactly as computed here (acceptance 52%; 200 misses in a row has
  // probability 1e-64, after which the centre is returned).
  void in_ball(double* p) {
    for (int attempt = 0; attempt < 200; ++attempt) {
      p[0] = symmetric(), p[1] = symmetric(), p[2] = symmetric();
      if (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] <= 1.0) return;
    }
    p[0] = p[1] = p[2] = 0.0;
  }

 private:
  std::uint64_t state_;
  double spare_ = 0;
  bool have_spare_ = false;
};

inline std::uint64_t key_for(std::uint64_t seed, std::uint64_t purpose) { return mix64(mix64(seed) ^ purpose); }

}  // namespace tetstream::io::rng
