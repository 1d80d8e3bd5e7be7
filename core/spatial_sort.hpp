#pragma once
// Insertion order for incremental Delaunay: a biased randomized insertion order
// (BRIO, Amenta-Choi-Rote) whose rounds are each sorted along a Hilbert curve, so
// that consecutive insertions are close in space (short walks, warm caches) while
// the rounds keep the expected cavity sizes of a random order.
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::core {

// 63-bit Hilbert index of a point given as three 21-bit grid coordinates.
std::uint64_t hilbert_index_3d(std::uint32_t x, std::uint32_t y, std::uint32_t z);

// Hilbert keys of n points (xyz, 3 doubles each) on a 2^21 grid over their
// bounding cube (isotropic: one scale for all axes).
std::vector<std::uint64_t> hilbert_keys(const double* xyz, std::size_t n);

// Indices [0, n) in BRIO order: shuffled with `seed`, split into rounds of
// geometrically growing size (the last round holds about 3/4 of the points),
// each round sorted by Hilbert key. Deterministic for a given seed.
std::vector<std::uint32_t> brio_order(const double* xyz, std::size_t n, std::uint64_t seed = 0x7e75);

// Indices sorted by Hilbert key only (no rounds), e.g. for points inserted into an
// existing triangulation, where the walk benefits from locality and a random order
// gains nothing.
std::vector<std::uint32_t> hilbert_order(const double* xyz, std::size_t n);

}  // namespace tetstream::core
