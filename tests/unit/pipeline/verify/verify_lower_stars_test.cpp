// A step's records by lower stars (pipeline/verify/lower_stars.hpp) against the same
// records sorted whole: every facet of every good tet in FacetLess order, every edge
// once in order, with the filters verify applies (a later rank's keys, the sample), on
// steps whose records reach past the span (long tets), repeat a tet (ties broken by
// ordinal), hold broken tets and lower stars of more than a few dozen records.
#include "pipeline/verify/lower_stars.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <random>
#include <vector>

namespace tetstream::pipeline::verify_engine {
namespace {

struct Step {
  std::vector<std::uint32_t> canon;  // 4 sorted labels a tet, by smallest label
  std::vector<std::uint8_t> flags;   // bit 0 parity, bit 1 broken
};

// n tets with smallest labels in [base, base + mins); the others mostly within `reach`
// of it, one in `far_every` up to 2^24 beyond. Every `repeat_every`-th tet repeats the one
// before (with the other parity), every `broken_every`-th is broken.
Step random_step(std::size_t n, std::uint32_t base, std::uint32_t mins, std::uint32_t reach, std::size_t far_every,
                 std::size_t repeat_every, std::size_t broken_every, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<std::array<std::uint32_t, 5>> tets;  // labels, flags
  for (std::size_t i = 0; i < n; ++i) {
    if (repeat_every && i % repeat_every == repeat_every - 1 && !tets.empty()) {
      auto t = tets.back();
      t[4] ^= 1;
      tets.push_back(t);
      continue;
    }
    const std::uint32_t s0 = base + std::uint32_t(rng() % mins);
    std::array<std::uint32_t, 3> up;
    for (;;) {
      for (auto& v : up) {
        const bool far = far_every && rng() % far_every == 0;
        v = s0 + 1 + std::uint32_t(rng() % (far ? (1u << 24) : reach));
      }
      std::sort(up.begin(), up.end());
      if (up[0] != up[1] && up[1] != up[2]) break;
    }
    const std::uint32_t broken = broken_every && rng() % broken_every == 0 ? 2 : 0;
    tets.push_back({s0, up[0], up[1], up[2], std::uint32_t(rng() & 1) | broken});
  }
  // By smallest label; broken tets stay where they fall (they make no records).
  std::stable_sort(tets.begin(), tets.end(), [](const auto& a, const auto& b) { return a[0] < b[0]; });
  Step s;
  for (const auto& t : tets) {
    s.canon.insert(s.canon.end(), t.begin(), t.begin() + 4);
    s.flags.push_back(std::uint8_t(t[4]));
  }
  return s;
}

template <class KeepFacet, class KeepKey>
void expect_same_records(const Step& s, std::uint64_t first_ordinal, std::size_t span, const KeepFacet& keep_facet,
                         const KeepKey& keep_key, bool edges, LowerStarScratch<std::uint32_t>& w) {
  using Facet = FacetRec<std::uint32_t>;
  const std::size_t n = s.flags.size();
  std::uint64_t base = ~0ull;
  for (std::size_t i = 0; i < n; ++i)
    if (!(s.flags[i] & 2)) base = std::min<std::uint64_t>(base, s.canon[4 * i]);
  std::vector<Facet> want_f;
  std::vector<std::uint64_t> want_e;
  for (std::size_t i = 0; i < n; ++i) {
    if (s.flags[i] & 2) continue;
    const std::uint32_t* t = s.canon.data() + 4 * i;
    tet_facets(t, first_ordinal + i, s.flags[i] & 1, [&](const Facet& f, bool) {
      if (keep_facet(f)) want_f.push_back(f);
    });
    if (edges)
      tet_edges(t, [&](std::uint32_t u, std::uint32_t v, bool) {
        if (keep_key(u)) want_e.push_back(make_edge(u, v));
      });
  }
  std::sort(want_f.begin(), want_f.end(), FacetLess<std::uint32_t>());
  std::sort(want_e.begin(), want_e.end());
  want_e.erase(std::unique(want_e.begin(), want_e.end()), want_e.end());

  std::vector<Facet> got_f(3, Facet{});  // stale contents are replaced
  std::vector<std::uint64_t> got_e(5, 7);
  lower_star_records(s.canon.data(), s.flags.data(), n, first_ordinal, base, span, keep_facet, keep_key, edges, w,
                     got_f, got_e);
  ASSERT_EQ(got_f.size(), want_f.size());
  for (std::size_t i = 0; i < want_f.size(); ++i) {
    const Facet &g = got_f[i], &e = want_f[i];
    ASSERT_TRUE(g.v[0] == e.v[0] && g.v[1] == e.v[1] && g.v[2] == e.v[2] && g.d == e.d && g.x == e.x)
        << "facet " << i << ": (" << g.v[0] << ' ' << g.v[1] << ' ' << g.v[2] << " | " << g.d << ") instead of ("
        << e.v[0] << ' ' << e.v[1] << ' ' << e.v[2] << " | " << e.d << ")";
  }
  EXPECT_EQ(got_e, want_e);
}

auto all_facets = [](const FacetRec<std::uint32_t>&) { return true; };
auto all_keys = [](std::uint32_t) { return true; };

TEST(VerifyLowerStars, MatchAFullSort) {
  LowerStarScratch<std::uint32_t> w;  // reused: every step must start clean
  for (std::uint32_t seed = 1; seed <= 6; ++seed) {
    SCOPED_TRACE(seed);
    const Step s = random_step(4000, 1000 * seed, 1000, 600, 50, 0, 0, seed);
    // A span that holds most keys, then one that holds only the smallest labels.
    expect_same_records(s, 77, std::size_t(1) << 12, all_facets, all_keys, true, w);
    expect_same_records(s, 0, 1000, all_facets, all_keys, true, w);
  }
}

TEST(VerifyLowerStars, RepeatedAndBrokenTetsAndLargeStars) {
  LowerStarScratch<std::uint32_t> w;
  // Repeats tie on every key of a tet: the ordinals order them. Few smallest labels
  // make lower stars of hundreds of records (sorted as records past 32).
  expect_same_records(random_step(3000, 5, 750, 400, 30, 7, 11, 9), 1 << 20, std::size_t(1) << 16, all_facets, all_keys,
                      true, w);
  expect_same_records(random_step(3000, 5, 10, 60, 0, 3, 0, 10), 0, std::size_t(1) << 16, all_facets, all_keys, true,
                      w);
  const Step tiny = random_step(8, 3, 2, 5, 0, 0, 0, 11);
  expect_same_records(tiny, 0, std::size_t(1) << 16, all_facets, all_keys, true, w);
}

TEST(VerifyLowerStars, FiltersAndNoEdges) {
  LowerStarScratch<std::uint32_t> w;
  const Step s = random_step(4000, 100, 1000, 500, 40, 13, 17, 12);
  const std::uint32_t upper = 100 + 600;  // a later rank owns the keys from here
  expect_same_records(
      s, 5, std::size_t(1) << 12, [&](const FacetRec<std::uint32_t>& f) { return f.v[0] < upper; },
      [&](std::uint32_t u) { return u < upper; }, true, w);
  // The sample: a facet kept by a hash of its labels, no edges.
  expect_same_records(
      s, 5, std::size_t(1) << 12,
      [](const FacetRec<std::uint32_t>& f) { return (f.v[0] * 31 + f.v[1] * 7 + f.v[2]) % 3 == 0; }, all_keys, false,
      w);
}

}  // namespace
}  // namespace tetstream::pipeline::verify_engine
