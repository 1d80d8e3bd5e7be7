// The zone keep's stored form (zone_keep.hpp): the rotation by a sorting network and
// the offsets' code (a constant for interior tets) give, for every order in which a
// zone may hand a tet's vertices, the stored form that the keep step after an MPI job
// computes its own way (tet_records.hpp, stored_form: a table of the even rotations);
// and both refuse a tet with two vertices of one periodic label.
#include "pipeline/periodic/keep_parts.hpp"
#include "pipeline/periodic/zone_keep.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <vector>

namespace tetstream::pipeline::periodic {
namespace {

// The zone keep's way: rotate the vertices, then the form of the rotated code words.
bool zone_form(const std::uint64_t c[4], KeptTet& out) {
  int order[4] = {0, 1, 2, 3};
  if (!rotate_stored(order, c)) return false;
  const std::uint64_t rc[4] = {c[order[0]], c[order[1]], c[order[2]], c[order[3]]};
  out = kept_tet_of(rc);
  return true;
}

bool same(const KeptTet& a, const KeptTet& b) { return std::memcmp(&a, &b, sizeof a) == 0; }

TEST(ZoneKeep, TheRotationAndOffsetsAreTheStoredFormInEveryVertexOrder) {
  std::mt19937_64 rng(11);
  int interior = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    // Labels close together (as a tet's are) or far apart (up to 40 bits); offsets at
    // random, none on a quarter of the tets (the box's interior).
    std::uint64_t code[4];
    const std::uint64_t base = rng() % (std::uint64_t(1) << 40);
    const bool close = trial % 2 == 0, no_offsets = trial % 4 == 1;
    for (int j = 0; j < 4; ++j) {
      const std::uint64_t label = close ? base + rng() % 50 : rng() % (std::uint64_t(1) << 40);
      const std::uint64_t bits = no_offsets ? 0 : rng() % 8;
      code[j] = label << 4 | bits;
    }
    int perm[4] = {0, 1, 2, 3};
    do {
      const std::uint64_t c[4] = {code[perm[0]], code[perm[1]], code[perm[2]], code[perm[3]]};
      KeptTet expected{}, got{};
      const bool ok = stored_form_of(c, expected);
      ASSERT_EQ(zone_form(c, got), ok) << "trial " << trial;
      if (!ok) continue;
      ASSERT_TRUE(same(got, expected)) << "trial " << trial << ": labels " << got.v[0] << " " << got.v[1] << " "
                                       << got.v[2] << " " << got.v[3] << " code " << got.code << ", expected "
                                       << expected.v[0] << " " << expected.v[1] << " " << expected.v[2] << " "
                                       << expected.v[3] << " code " << expected.code;
      interior += ((c[0] | c[1] | c[2] | c[3]) & 7) == 0;  // kept_tet_of's constant path
    } while (std::next_permutation(perm, perm + 4));
  }
  EXPECT_GT(interior, 24 * 400);  // the tets without offsets took it
}

TEST(ZoneKeep, TwoVerticesOfOneLabelAreRefused) {
  // A tet across a whole period: two images of one point.
  for (int twin = 1; twin < 4; ++twin) {
    std::uint64_t c[4] = {10 << 4, 20 << 4, 30 << 4 | 1, 40 << 4 | 2};
    c[twin] = (10 << 4) | 4;
    int order[4] = {0, 1, 2, 3};
    KeptTet t{};
    EXPECT_FALSE(rotate_stored(order, c));
    EXPECT_FALSE(stored_form_of(c, t));
  }
}

// A group's order is the stored order whatever the tets' arrival: groups whose labels
// lie near m (one word a tet, sorted by the network), far from it, larger than the
// words' index holds, and with two copies of one tet (the same labels, other offsets).
TEST(ZoneKeep, AGroupComesOutInTheStoredOrder) {
  std::mt19937_64 rng(11);
  const KeptTetLess less;
  const std::uint64_t m = 1000;
  for (int trial = 0; trial < 400; ++trial) {
    const std::size_t n = trial < 300 ? 1 + rng() % 16 : std::size_t(1 + rng() % 90);
    const bool far = trial % 5 == 1;  // a label past 2^19 from m
    std::vector<KeptTet> forms(n);
    for (std::size_t i = 0; i < n; ++i) {
      KeptTet& f = forms[i];
      f = KeptTet{};
      std::uint64_t l[3];
      for (auto& x : l) x = m + 1 + rng() % (trial % 2 ? 40 : 600000);  // many ties on a and lo
      if (far && i == n / 2) l[2] = m + (std::uint64_t(1) << 19) + rng() % 5;
      std::sort(l, l + 3);
      if (l[0] == l[1] || l[1] == l[2]) l[1] = l[0] + 1, l[2] = std::max(l[2], l[1] + 1);
      f.v[0] = m, f.v[1] = l[0];
      const bool odd = rng() % 2;
      f.v[2] = odd ? l[2] : l[1], f.v[3] = odd ? l[1] : l[2];
      f.code = std::uint16_t(rng() % 19683);
      f.pad[0] = std::uint8_t(i);  // its arrival
    }
    if (trial % 7 == 3 && n > 2) {
      forms[n - 1] = forms[0];  // a second copy: same labels, its own offsets
      forms[n - 1].code = std::uint16_t(forms[0].code ^ 1);
      forms[n - 1].pad[0] = std::uint8_t(n - 1);
    }
    KeptGroup g;
    for (const KeptTet& f : forms) {
      g.next().form = f;
      g.settle();
    }
    g.put_in_order();
    std::stable_sort(forms.begin(), forms.end(), less);
    ASSERT_EQ(g.order.size(), n);
    for (std::size_t i = 0; i < n; ++i)
      ASSERT_TRUE(same(g.entries[g.order[i]].form, forms[i])) << "trial " << trial << ", place " << i << " of " << n;
  }
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
