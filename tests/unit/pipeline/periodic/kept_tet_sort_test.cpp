// The keep step's run sort (pipeline/periodic/tet_records.hpp: radix_sort_kept, a radix
// sort on the smallest label, then each group by insertion or, when large, std::sort)
// orders the kept tets exactly as KeptTetLess does, the order the external sort merges
// by: groups of one to a few hundred tets, both parities, labels up to the bit width.
#include "pipeline/periodic/tet_records.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <vector>

namespace tetstream::pipeline::periodic {
namespace {

std::vector<KeptTet> random_tets(std::size_t groups, int label_bits, std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  const std::uint64_t top = (std::uint64_t(1) << label_bits) - 1;
  std::vector<KeptTet> out;
  for (std::size_t g = 0; g < groups; ++g) {
    const std::uint64_t m = rng() % (top - 4);
    // Mostly lower stars of a few tets, now and then a large one (a lattice's corner).
    const std::size_t size = g % 97 == 0 ? 40 + rng() % 300 : 1 + rng() % 12;
    for (std::size_t i = 0; i < size; ++i) {
      KeptTet t{};
      t.v[0] = m;
      t.v[1] = m + 1 + rng() % std::min<std::uint64_t>(top - m - 3, 50);
      t.v[2] = t.v[1] + 1 + rng() % 20;
      t.v[3] = t.v[1] + 1 + rng() % 20;
      if (t.v[2] == t.v[3]) ++t.v[3];
      if (t.v[2] > top || t.v[3] > top) continue;
      if (rng() & 1) std::swap(t.v[2], t.v[3]);
      t.code = std::uint16_t(rng() % 27);
      out.push_back(t);
    }
  }
  std::shuffle(out.begin(), out.end(), rng);
  return out;
}

TEST(KeptTetSort, RadixSortOrdersAsTheStoredOrder) {
  for (int label_bits : {12, 20, 31}) {
    SCOPED_TRACE(label_bits);
    std::vector<KeptTet> a = random_tets(3000, label_bits, std::uint32_t(label_bits));
    std::vector<KeptTet> b = a;
    radix_sort_kept(a.data(), a.size(), label_bits);
    std::stable_sort(b.begin(), b.end(), KeptTetLess{});
    ASSERT_EQ(a.size(), b.size());
    EXPECT_GT(a.size(), 15000u);
    EXPECT_TRUE(std::is_sorted(a.begin(), a.end(), KeptTetLess{}));
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(KeptTet)), 0);
  }
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
