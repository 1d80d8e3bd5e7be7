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

constexpr int kBrioBits = 10;  // 3 x 10 = 30 bits of key: fits the high word of an item

// Stable LSD radix sort of [first, last) by bits 32..61 (the key of an item), one
// byte per pass; scratch holds at least last - first items.
void radix_sort_by_high_word(std::uint64_t* first, std::uint64_t* last, std::uint64_t* scratch) {
  const std::size_t n = std::size_t(last - first);
  std::uint64_t* src = first;
  std::uint64_t* dst = scratch;
  for (int shift = 32; shift < 64; shift += 8) {
    std::size_t count[257] = {};
    for (std::size_t i = 0; i < n; ++i) ++count[((src[i] >> shift) & 0xFF) + 1];
    for (int b = 0; b < 256; ++b) count[b + 1] += count[b];
    for (std::size_t i = 0; i < n; ++i) dst[count[(src[i] >> shift) & 0xFF]++] = src[i];
    std::swap(src, dst);
  }
  // Four passes: the result is back in first.
}

// Sorts indices by key (ties by index). The keys are gathered next to the indices
// first, so the sort compares contiguous pairs instead of looking up key[a] and
// key[b] at random on every comparison.
void sort_by_key(std::uint32_t* first, std::uint32_t* last, const std::vector<std::uint64_t>& key) {
  struct Item {
    std::uint64_t key;
    std::uint32_t index;
  };
  std::vector<Item> items(std::size_t(last - first));
  for (std::size_t i = 0; i < items.size(); ++i) items[i] = {key[first[i]], first[i]};
  std::sort(items.begin(), items.end(),
            [](const Item& a, const Item& b) { return a.key != b.key ? a.key < b.key : a.index < b.index; });
  for (std::size_t i = 0; i < items.size(); ++i) first[i] = items[i].index;
}

}  // namespace

// Skilling's transform ("Programming the Hilbert curve", 2004): turn the axes into
// the "transposed" Hilbert index by undoing the excess rotations and reflections
// level by level, Gray-decode across axes, then interleave the bits (x most
// significant at each level). Written without branches (the bits of random points
// are coin flips, so the branchy form mispredicted about half the time): each step
// computes both outcomes and selects one with a mask.
namespace {

// The transform on the low `bits` bits of each axis (1 <= bits <= 21): the Hilbert
// index of the curve of that order, 3 * bits bits wide.
std::uint64_t hilbert_index_bits(std::uint32_t x, std::uint32_t y, std::uint32_t z, int bits) {
  std::uint32_t X[3] = {x, y, z};
  for (int level = bits - 1; level > 0; --level) {
    const std::uint32_t p = (1u << level) - 1;
    for (int i = 0; i < 3; ++i) {
      // set: X[0] ^= p (reflect); clear: swap the low bits of X[0] and X[i].
      const std::uint32_t set = 0u - ((X[i] >> level) & 1u);
      const std::uint32_t t = (X[0] ^ X[i]) & p & ~set;
      X[0] ^= (p & set) | t;
      if (i != 0) X[i] ^= t;  // (for i = 0, t is 0)
    }
  }
  X[1] ^= X[0];
  X[2] ^= X[1];
  std::uint32_t t = 0;
  for (int level = bits - 1; level > 0; --level) t ^= ((1u << level) - 1) & (0u - ((X[2] >> level) & 1u));
  for (auto& xi : X) xi ^= t;
  return spread_bits_3(X[0]) << 2 | spread_bits_3(X[1]) << 1 | spread_bits_3(X[2]);
}

// Grid coordinates of the points on a 2^bits grid over their bounding cube.
template <class F>
void for_each_grid_point(const double* xyz, std::size_t n, int bits, F&& f) {
  if (n == 0) return;
  double lo[3] = {xyz[0], xyz[1], xyz[2]}, hi[3] = {xyz[0], xyz[1], xyz[2]};
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], xyz[3 * i + k]);
      hi[k] = std::max(hi[k], xyz[3 * i + k]);
    }
  // Everything is measured in units of the largest magnitude's power of two (an exact
  // scaling wherever it matters), so that the extent cannot overflow (coordinates near
  // +-DBL_MAX) and the scale cannot (subnormal extents); a rounding here only moves a
  // point to a neighbouring cell, which changes the order, never the triangulation.
  double big = 0;
  for (int k = 0; k < 3; ++k) big = std::max({big, std::fabs(lo[k]), std::fabs(hi[k])});
  const double unit = big > 0 && std::isfinite(big) ? std::ldexp(1.0, std::min(-std::ilogb(big), 1000)) : 1.0;
  double origin[3];
  for (int k = 0; k < 3; ++k) origin[k] = lo[k] * unit;
  const double extent = std::max({hi[0] * unit - origin[0], hi[1] * unit - origin[1], hi[2] * unit - origin[2]});
  const double cells = double(1u << bits);
  const double scale = extent > 0 && std::isfinite((cells - 1) / extent) ? (cells - 1) / extent : 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    std::uint32_t c[3];
    for (int k = 0; k < 3; ++k) {
      const double g = (xyz[3 * i + k] * unit - origin[k]) * scale;
      c[k] = g > 0 ? std::uint32_t(std::min(g, cells - 1)) : 0;  // NaN (non-finite input) -> 0
    }
    f(i, c);
  }
}

}  // namespace

std::uint64_t hilbert_index_3d(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return hilbert_index_bits(x, y, z, kHilbertBits);
}

std::vector<std::uint64_t> hilbert_keys(const double* xyz, std::size_t n) {
  std::vector<std::uint64_t> key(n);
  for_each_grid_point(xyz, n, kHilbertBits,
                      [&](std::size_t i, const std::uint32_t* c) { key[i] = hilbert_index_3d(c[0], c[1], c[2]); });
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
  // Items (key << 32 | index), the key a Hilbert index of order kBrioBits: 2^30 cells
  // separate any point set a kernel can hold, and the coarser key halves the cost of
  // the transform and fits the radix sort below.
  std::vector<std::uint64_t> item(n);
  for_each_grid_point(xyz, n, kBrioBits, [&](std::size_t i, const std::uint32_t* c) {
    item[i] = hilbert_index_bits(c[0], c[1], c[2], kBrioBits) << 32 | std::uint64_t(i);
  });
  // Fisher-Yates with a seeded generator: the order, hence the kernel's work, is
  // reproducible; the triangulation itself does not depend on the order.
  std::uint64_t state = seed;
  for (std::size_t i = n; i > 1; --i) {
    const std::size_t j = splitmix64(state) % i;
    std::swap(item[i - 1], item[j]);
  }
  // Rounds: [0, n/4^k) ... the last round [n/4, n) holds 3/4 of the points; each is
  // sorted by key (stable: equal keys keep their shuffled order).
  constexpr std::size_t kSmallestRound = 64;
  std::vector<std::uint64_t> scratch(n > kSmallestRound ? n - n / 4 : n);  // the largest round
  std::size_t end = n;
  while (end > 0) {
    const std::size_t begin = end > kSmallestRound ? end / 4 : 0;
    radix_sort_by_high_word(item.data() + begin, item.data() + end, scratch.data());
    end = begin;
  }
  std::vector<std::uint32_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = std::uint32_t(item[i]);
  return order;
}

}  // namespace tetstream::core
