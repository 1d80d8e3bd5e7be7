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

// The zone keep hands each group (one m) in any order: the frames' offsets still come in
// the stored order of their tets (the order the codec stores the labels in), for groups
// whose tets all have one code (left as they came) and groups with several, including
// two copies of one tet (the same labels, other offsets), and across frame cuts.
TEST(ZoneKeep, TheFramesOffsetsFollowTheStoredOrderWhateverTheGroupsOrder) {
  std::mt19937_64 rng(11);
  const KeptTetLess less;
  std::vector<KeptTet> sorted;
  for (std::uint64_t m = 1000; m < 1400; ++m) {
    const std::size_t n = 1 + rng() % 16;
    const bool one_code = m % 3 != 0;
    std::vector<KeptTet> group(n);
    for (std::size_t i = 0; i < n; ++i) {
      KeptTet& f = group[i];
      f = KeptTet{};
      std::uint64_t l[3];
      for (auto& x : l) x = m + 1 + rng() % (m % 2 ? 40 : 600000);  // many ties on a and lo
      std::sort(l, l + 3);
      if (l[0] == l[1] || l[1] == l[2]) l[1] = l[0] + 1, l[2] = std::max(l[2], l[1] + 1);
      f.v[0] = m, f.v[1] = l[0];
      const bool odd = rng() % 2;
      f.v[2] = odd ? l[2] : l[1], f.v[3] = odd ? l[1] : l[2];
      f.code = one_code ? kNoOffsets : std::uint16_t(rng() % 19683);
    }
    if (m % 7 == 3 && n > 2) {
      group[n - 1] = group[0];  // a second copy: same labels, its own offsets
      group[n - 1].code = std::uint16_t(group[0].code ^ 1);
    }
    std::sort(group.begin(), group.end(), less);
    sorted.insert(sorted.end(), group.begin(), group.end());
  }
  // The same tets with each group shuffled.
  std::vector<KeptTet> shuffled = sorted;
  for (std::size_t i = 0; i < shuffled.size();) {
    std::size_t j = i;
    while (j < shuffled.size() && shuffled[j].v[0] == shuffled[i].v[0]) ++j;
    std::shuffle(shuffled.begin() + std::ptrdiff_t(i), shuffled.begin() + std::ptrdiff_t(j), rng);
    i = j;
  }
  ASSERT_FALSE(std::equal(shuffled.begin(), shuffled.end(), sorted.begin(), same));
  struct Frames {
    std::vector<std::vector<std::uint64_t>> labels;
    std::vector<std::vector<std::uint16_t>> codes;
  };
  const auto feed = [](const std::vector<KeptTet>& tets) {
    Frames out;
    FrameFeeder feeder(
        [&out](std::vector<std::uint64_t>& l, std::vector<std::uint16_t>& c) {
          out.labels.push_back(l);
          out.codes.push_back(c);
        },
        100);
    for (const KeptTet& t : tets) feeder.add_one(t);
    feeder.flush();
    return out;
  };
  const Frames got = feed(shuffled), expected = feed(sorted);
  ASSERT_EQ(got.codes, expected.codes);
  ASSERT_GT(got.codes.size(), 10u);
  // Each frame's labels: the same tets, group by group (as the codec reads them).
  ASSERT_EQ(got.labels.size(), expected.labels.size());
  for (std::size_t f = 0; f < got.labels.size(); ++f) {
    const auto tets_of = [](const std::vector<std::uint64_t>& l) {
      std::vector<std::array<std::uint64_t, 4>> t(l.size() / 4);
      for (std::size_t i = 0; i < t.size(); ++i) std::copy(&l[4 * i], &l[4 * i] + 4, t[i].begin());
      std::sort(t.begin(), t.end());
      return t;
    };
    ASSERT_EQ(tets_of(got.labels[f]), tets_of(expected.labels[f])) << "frame " << f;
    ASSERT_EQ(got.labels[f][0], expected.labels[f][0]) << "frame " << f;
  }
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
