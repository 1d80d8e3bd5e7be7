#include "core/spatial_sort.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace tetstream::core {

namespace {

constexpr int kHilbertBits = 21;  // 3 x 21 = 63 bits of key

// Spreads the low 21 bits of x so that bit i lands on bit 3i.
std::uint64_t spread_bits_3(std::uint64_t x) {
  x &= 0x1FFFFF;
  x = (x | x << 32) & 0x1F00000000FFFFULL;
  x = (x | x << 16) & 0x1F0000FF0000FFULL;
  x = (x | x << 8) & 0x100F00F00F00F00FULL;
  x = (x | x << 4) & 0x10C30C30C30C30C3ULL;
  x = (x | x << 2) & 0x1249249249249249ULL;
  return x;
}

// splitmix64: a small, well-mixed counter-based generator for the shuffle.
std::uint64_t splitmix64(std::uint64_t& state) {
  std::uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

void sort_by_key(std::uint32_t* first, std::uint32_t* last, const std::vector<std::uint64_t>& key) {
  std::sort(first, last, [&key](std::uint32_t a, std::uint32_t b) { return key[a] < key[b]; });
}

}  // namespace

// Skilling's transform ("Programming the Hilbert curve", 2004): turn the axes into
// the "transposed" Hilbert index by undoing the excess rotations and reflections
// level by level, Gray-decode across axes, then interleave the bits (x most
// significant at each level).
std::uint64_t hilbert_index_3d(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  std::uint32_t X[3] = {x, y, z};
  const std::uint32_t top = 1u << (kHilbertBits - 1);
  for (std::uint32_t q = top; q > 1; q >>= 1) {
    const std::uint32_t p = q - 1;
    for (int i = 0; i < 3; ++i) {
      if (X[i] & q) {
        X[0] ^= p;  // reflect
      } else {      // swap the low bits of X[0] and X[i]
        const std::uint32_t t = (X[0] ^ X[i]) & p;
        X[0] ^= t;
        X[i] ^= t;
      }
    }
  }
  X[1] ^= X[0];
  X[2] ^= X[1];
  std::uint32_t t = 0;
  for (std::uint32_t q = top; q > 1; q >>= 1)
    if (X[2] & q) t ^= q - 1;
  for (auto& xi : X) xi ^= t;
  return spread_bits_3(X[0]) << 2 | spread_bits_3(X[1]) << 1 | spread_bits_3(X[2]);
}

std::vector<std::uint64_t> hilbert_keys(const double* xyz, std::size_t n) {
  std::vector<std::uint64_t> key(n);
  if (n == 0) return key;
  double lo[3] = {xyz[0], xyz[1], xyz[2]}, hi[3] = {xyz[0], xyz[1], xyz[2]};
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], xyz[3 * i + k]);
      hi[k] = std::max(hi[k], xyz[3 * i + k]);
    }
  const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  const double cells = double(1u << kHilbertBits);
  const double scale = extent > 0 ? (cells - 1) / extent : 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    std::uint32_t c[3];
    for (int k = 0; k < 3; ++k) {
      const double g = (xyz[3 * i + k] - lo[k]) * scale;
      c[k] = std::uint32_t(std::clamp(g, 0.0, cells - 1));
    }
    key[i] = hilbert_index_3d(c[0], c[1], c[2]);
  }
  return key;
}

std::vector<std::uint32_t> hilbert_order(const double* xyz, std::size_t n) {
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  const auto key = hilbert_keys(xyz, n);
  sort_by_key(order.data(), order.data() + n, key);
  return order;
}

std::vector<std::uint32_t> brio_order(const double* xyz, std::size_t n, std::uint64_t seed) {
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  // Fisher-Yates with a seeded generator: the order, hence the kernel's work, is
  // reproducible; the triangulation itself does not depend on the order.
  std::uint64_t state = seed;
  for (std::size_t i = n; i > 1; --i) {
    const std::size_t j = splitmix64(state) % i;
    std::swap(order[i - 1], order[j]);
  }
  const auto key = hilbert_keys(xyz, n);
  // Rounds: [0, n/4^k) ... the last round [n/4, n) holds 3/4 of the points.
  constexpr std::size_t kSmallestRound = 64;
  std::size_t end = n;
  while (end > 0) {
    const std::size_t begin = end > kSmallestRound ? end / 4 : 0;
    sort_by_key(order.data() + begin, order.data() + end, key);
    end = begin;
  }
  return order;
}

}  // namespace tetstream::core
