#pragma once
// Sorting a few 64-bit keys without branches on the comparisons (the frame codec's
// groups, the periodic keep's): Batcher's odd-even merge sort of N (a power of two)
// values, a fixed sequence of compare-exchanges whose pairs are computed at compile
// time, much faster than a comparison sort on the small, randomly ordered lists of a
// group (whose branches no predictor guesses).
#include "core/compiler.hpp"

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <utility>

namespace tetstream::core {

namespace detail {
template <std::size_t N>
constexpr std::size_t network_size() {
  std::size_t c = 0;
  for (std::size_t p = 1; p < N; p <<= 1)
    for (std::size_t k = p; k >= 1; k >>= 1)
      for (std::size_t j = k % p; j + k < N; j += 2 * k)
        for (std::size_t i = 0; i < std::min(k, N - j - k); ++i) c += (i + j) / (2 * p) == (i + j + k) / (2 * p);
  return c;
}

template <std::size_t N>
constexpr auto network_pairs() {
  std::array<std::array<std::uint8_t, 2>, network_size<N>()> pairs{};
  std::size_t c = 0;
  for (std::size_t p = 1; p < N; p <<= 1)
    for (std::size_t k = p; k >= 1; k >>= 1)
      for (std::size_t j = k % p; j + k < N; j += 2 * k)
        for (std::size_t i = 0; i < std::min(k, N - j - k); ++i)
          if ((i + j) / (2 * p) == (i + j + k) / (2 * p)) pairs[c++] = {std::uint8_t(i + j), std::uint8_t(i + j + k)};
  return pairs;
}

template <std::size_t N, std::size_t... I>
TS_FORCE_INLINE void sorting_network(std::uint64_t* v, std::index_sequence<I...>) {
  // Unrolled with constant indices, so the values stay in registers.
  static constexpr auto kPairs = network_pairs<N>();
  auto cx = [](std::uint64_t& x, std::uint64_t& y) {
    const std::uint64_t a = x, b = y;
    x = std::min(a, b), y = std::max(a, b);
  };
  (cx(v[kPairs[I][0]], v[kPairs[I][1]]), ...);
}

template <std::size_t N>
TS_FORCE_INLINE void sorting_network(std::uint64_t* v) {
  sorting_network<N>(v, std::make_index_sequence<network_size<N>()>());
}

template <std::size_t N>
inline void sort_padded(std::uint64_t* v, std::size_t n) {
  std::uint64_t a[N];
  std::copy(v, v + n, a);
  std::fill(a + n, a + N, std::numeric_limits<std::uint64_t>::max());
  sorting_network<N>(a);
  std::copy(a, a + n, v);
}

}  // namespace detail

// Sorts v[0, n) ascending: a network for n <= 16, std::sort above.
inline void sort_small(std::uint64_t* v, std::size_t n) {
  if (n <= 1) return;
  if (n <= 4) return detail::sort_padded<4>(v, n);
  if (n <= 8) return detail::sort_padded<8>(v, n);
  if (n <= 16) return detail::sort_padded<16>(v, n);
  std::sort(v, v + n);
}

}  // namespace tetstream::core
