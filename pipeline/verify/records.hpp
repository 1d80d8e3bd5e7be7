#pragma once
// verify's records (pipeline/verify/engine.hpp): a facet as seen so far, a boundary
// edge, an edge key, their orders, and the records a canonical tet makes. Apart from
// the engine so that the step's record builders (lower_stars.hpp) and their tests use
// the same ones.
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace tetstream::pipeline::verify_engine {

// FacetRec: one facet (triangle) as seen so far. v: its labels, sorted. x: flags in
// the top byte, a payload in the low 56 bits:
//   single  (no flag)  one tet: d is its fourth vertex, payload its ordinal; kSide set
//                      when that tet, if positively oriented, is (v0, v1, v2, d) in this
//                      order, i.e. d lies on the positive side of (v0, v1, v2);
//   kPair              two tets on opposite sides, already checked: d is the vertex on
//                      the positive side, the payload the one on the negative side;
//   kBad               already reported (repeated or overused); payload: an ordinal.
constexpr std::uint64_t kPayload = (std::uint64_t(1) << 56) - 1;
constexpr std::uint64_t kSide = std::uint64_t(1) << 56;
constexpr std::uint64_t kPair = std::uint64_t(1) << 57;
constexpr std::uint64_t kBad = std::uint64_t(1) << 58;

template <class L>
struct FacetRec {
  L v[3];
  L d;
  std::uint64_t x;
};
static_assert(sizeof(FacetRec<std::uint32_t>) == 24);

template <class L>
struct FacetLess {
  bool operator()(const FacetRec<L>& a, const FacetRec<L>& b) const {
    if (a.v[0] != b.v[0]) return a.v[0] < b.v[0];
    if (a.v[1] != b.v[1]) return a.v[1] < b.v[1];
    if (a.v[2] != b.v[2]) return a.v[2] < b.v[2];
    const std::uint64_t pa = a.x & kPayload, pb = b.x & kPayload;
    if (pa != pb) return pa < pb;
    return a.x < b.x;
  }
};

template <class L>
bool same_key(const FacetRec<L>& a, const FacetRec<L>& b) {
  return a.v[0] == b.v[0] && a.v[1] == b.v[1] && a.v[2] == b.v[2];
}

// A boundary edge of a boundary facet: u < v, w the facet's third vertex, x: kSide when
// the facet, oriented outwards, runs u -> v; payload the tet's ordinal.
template <class L>
struct HullEdgeRec {
  L u, v, w;
  std::uint64_t x;
};

template <class L>
struct HullEdgeLess {
  bool operator()(const HullEdgeRec<L>& a, const HullEdgeRec<L>& b) const {
    if (a.u != b.u) return a.u < b.u;
    if (a.v != b.v) return a.v < b.v;
    return a.x < b.x;
  }
};

// Edge keys: (u, v), u < v, ordered by u then v. 32-bit labels pack into one integer.
struct Edge64 {
  std::uint64_t u, v;
  bool operator<(const Edge64& o) const { return u != o.u ? u < o.u : v < o.v; }
  bool operator==(const Edge64& o) const = default;
};
template <class L>
using EdgeKey = std::conditional_t<sizeof(L) == 4, std::uint64_t, Edge64>;
inline std::uint64_t make_edge(std::uint32_t u, std::uint32_t v) { return std::uint64_t(u) << 32 | v; }
inline Edge64 make_edge(std::uint64_t u, std::uint64_t v) { return {u, v}; }
inline std::uint64_t edge_u(std::uint64_t e) { return e >> 32; }
inline std::uint64_t edge_u(const Edge64& e) { return e.u; }
inline std::uint64_t edge_v(std::uint64_t e) { return e & 0xFFFFFFFFu; }
inline std::uint64_t edge_v(const Edge64& e) { return e.v; }
// Edge (u, v)'s slot in a direct-mapped table of 2^bits edges (a step's builders keep
// the last edges they made there and drop the repeats, most of an edge's copies).
constexpr int kSeenBits = 14;
inline std::size_t edge_slot(std::uint64_t u, std::uint64_t v, int bits) {
  return std::size_t(((u * 0x9E3779B97F4A7C15ull) ^ v) * 0xBF58476D1CE4E5B9ull >> (64 - bits));
}

// The facet of a canonical tet s (labels sorted; parity: 1 when that order has the
// opposite orientation of the tet's) opposite s[Opp], written (others sorted, s[Opp]).
// It has the orientation of (s0..s3) times (-1)^(3-Opp), and (s0..s3) has the tet's
// times (-1)^parity; kSide when that is positive.
template <int Opp, class L>
FacetRec<L> facet_opposite(const L* s, std::uint64_t ordinal, int parity) {
  constexpr int a = Opp == 0 ? 1 : 0, b = Opp <= 1 ? 2 : 1, c = Opp <= 2 ? 3 : 2;
  return FacetRec<L>{{s[a], s[b], s[c]}, s[Opp], ordinal | (((parity + 3 - Opp) & 1) == 0 ? kSide : 0)};
}

// The four facets of a canonical tet: emit(facet, in A). A = the three through s[0]
// (keyed by the tet's smallest label), B = the fourth.
template <class L, class Emit>
void tet_facets(const L* s, std::uint64_t ordinal, int parity, Emit&& emit) {
  emit(facet_opposite<3>(s, ordinal, parity), true);
  emit(facet_opposite<2>(s, ordinal, parity), true);
  emit(facet_opposite<1>(s, ordinal, parity), true);
  emit(facet_opposite<0>(s, ordinal, parity), false);
}

// The six edges (u, v), u < v, of a canonical tet s: emit(u, v, in A).
template <class L, class Emit>
void tet_edges(const L* s, Emit&& emit) {
  emit(s[0], s[1], true), emit(s[0], s[2], true), emit(s[0], s[3], true);
  emit(s[1], s[2], false), emit(s[1], s[3], false), emit(s[2], s[3], false);
}

}  // namespace tetstream::pipeline::verify_engine
