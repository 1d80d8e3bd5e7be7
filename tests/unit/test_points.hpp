#pragma once
// Small seeded point generators for the kernel tests (xyz as 3 doubles per point).
// Deterministic on every platform: splitmix64 and our own double/normal draws, no
// std:: distributions (their output is implementation-defined).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

namespace tetstream::test {

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : s_(seed) {}
  std::uint64_t next() {
    std::uint64_t z = (s_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  std::uint64_t below(std::uint64_t n) { return next() % n; }  // bias irrelevant here
  double normal() {
    const double u = 1.0 - uniform(), v = uniform();
    return std::sqrt(-2.0 * std::log(u)) * std::cos(6.283185307179586 * v);
  }
  template <class T>
  void shuffle(std::vector<T>& a) {
    for (std::size_t i = a.size(); i > 1; --i) std::swap(a[i - 1], a[below(i)]);
  }

 private:
  std::uint64_t s_;
};

using Points = std::vector<double>;

inline std::size_t count(const Points& p) { return p.size() / 3; }

inline void push(Points& p, double x, double y, double z) {
  p.push_back(x);
  p.push_back(y);
  p.push_back(z);
}

// Uniform in the unit cube.
inline Points uniform_cube(std::size_t n, std::uint64_t seed) {
  Rng rng(seed);
  Points p;
  p.reserve(3 * n);
  for (std::size_t i = 0; i < 3 * n; ++i) p.push_back(rng.uniform());
  return p;
}

// Uniform in the unit ball.
inline Points uniform_ball(std::size_t n, std::uint64_t seed) {
  Rng rng(seed);
  Points p;
  p.reserve(3 * n);
  while (count(p) < n) {
    const double x = rng.uniform(-1, 1), y = rng.uniform(-1, 1), z = rng.uniform(-1, 1);
    if (x * x + y * y + z * z <= 1) push(p, x, y, z);
  }
  return p;
}

// A thin ellipsoidal shell: semi-axes (1, 0.6, 0.3), radial thickness `thickness`.
inline Points ellipsoid_shell(std::size_t n, std::uint64_t seed, double thickness = 0.01) {
  Rng rng(seed);
  Points p;
  p.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    double x = rng.normal(), y = rng.normal(), z = rng.normal();
    const double len = std::sqrt(x * x + y * y + z * z);
    const double r = 1.0 - thickness * rng.uniform();
    push(p, r * x / len * 1.0, r * y / len * 0.6, r * z / len * 0.3);
  }
  return p;
}

// Gaussian clusters (sigma 0.02) around `k` uniform centres in the unit cube.
inline Points clusters(std::size_t n, std::uint64_t seed, std::size_t k = 20) {
  Rng rng(seed);
  Points centres = uniform_cube(k, seed ^ 0xC1u);
  Points p;
  p.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t c = rng.below(k);
    push(p, centres[3 * c] + 0.02 * rng.normal(), centres[3 * c + 1] + 0.02 * rng.normal(),
         centres[3 * c + 2] + 0.02 * rng.normal());
  }
  return p;
}

// The integer lattice {0..k-1}^3 scaled by `spacing`, in x-fastest order.
inline Points grid(std::size_t k, double spacing = 1.0) {
  Points p;
  p.reserve(3 * k * k * k);
  for (std::size_t z = 0; z < k; ++z)
    for (std::size_t y = 0; y < k; ++y)
      for (std::size_t x = 0; x < k; ++x) push(p, spacing * double(x), spacing * double(y), spacing * double(z));
  return p;
}

// Random directions, normalised (cospherical up to rounding).
inline Points sphere_surface(std::size_t n, std::uint64_t seed, double radius = 1.0) {
  Rng rng(seed);
  Points p;
  p.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = rng.normal(), y = rng.normal(), z = rng.normal();
    const double len = std::sqrt(x * x + y * y + z * z);
    push(p, radius * x / len, radius * y / len, radius * z / len);
  }
  return p;
}

// Every integer point with x^2 + y^2 + z^2 = r2: exactly cospherical.
inline Points integer_sphere(long r2) {
  Points p;
  const long r = long(std::sqrt(double(r2))) + 1;
  for (long x = -r; x <= r; ++x)
    for (long y = -r; y <= r; ++y)
      for (long z = -r; z <= r; ++z)
        if (x * x + y * y + z * z == r2) push(p, double(x), double(y), double(z));
  return p;
}

// `n` points on the planes z = 0, 1, ..., layers-1; x, y uniform in [0, 1), or on
// the integer grid {0..coarse-1}^2 when coarse > 0.
inline Points coplanar_layers(std::size_t n, std::size_t layers, std::uint64_t seed, int coarse = 0) {
  Rng rng(seed);
  Points p;
  p.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const double z = double(rng.below(layers));
    if (coarse > 0)
      push(p, double(rng.below(coarse)), double(rng.below(coarse)), z);
    else
      push(p, rng.uniform(), rng.uniform(), z);
  }
  return p;
}

// `n` points of the integer cube {0..m}^3 (heavy rounding: duplicates, coplanar and
// cospherical subsets everywhere), each coordinate multiplied by `scale`.
inline Points coarse(std::size_t n, std::uint64_t seed, int m = 4, double scale = 1.0) {
  Rng rng(seed);
  Points p;
  p.reserve(3 * n);
  for (std::size_t i = 0; i < 3 * n; ++i) p.push_back(scale * double(rng.below(std::uint64_t(m) + 1)));
  return p;
}

// `distinct` uniform points, each repeated 1..max_copies times, shuffled.
inline Points with_duplicates(std::size_t distinct, std::size_t max_copies, std::uint64_t seed) {
  Rng rng(seed);
  const Points base = uniform_cube(distinct, seed ^ 0xD0u);
  std::vector<std::size_t> idx;
  for (std::size_t i = 0; i < distinct; ++i)
    for (std::size_t c = 0, copies = 1 + rng.below(max_copies); c < copies; ++c) idx.push_back(i);
  rng.shuffle(idx);
  Points p;
  p.reserve(3 * idx.size());
  for (std::size_t i : idx) push(p, base[3 * i], base[3 * i + 1], base[3 * i + 2]);
  return p;
}

// Distinct, non-sequential labels (a seeded permutation of spread-out values).
inline std::vector<std::uint64_t> shuffled_labels(std::size_t n, std::uint64_t seed) {
  std::vector<std::uint64_t> l(n);
  for (std::size_t i = 0; i < n; ++i) l[i] = 1000 + 7 * std::uint64_t(i);
  Rng rng(seed);
  rng.shuffle(l);
  return l;
}

}  // namespace tetstream::test
