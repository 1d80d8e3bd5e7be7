// SharedRim (pipeline/window/shared_rim.hpp): the rim tets finished zones certified, for
// the zones still running. A tet is found exactly by its four labels, forgotten once all
// its labels are below the segments still to run, and never takes the table past its
// share: a tet without room is not published (the zones check it themselves). Lookups
// from threads while another publishes and forgets see only tets that were published.
#include "pipeline/window/shared_rim.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <random>
#include <set>
#include <thread>
#include <vector>

namespace tetstream::pipeline {
namespace {

using Labels = SharedRim::Labels;

TEST(SharedRim, FindsExactlyThePublishedTets) {
  SharedRim rim(1 << 20);
  const std::vector<Labels> tets = {{1, 2, 3, 4}, {1, 2, 3, 5}, {10, 20, 30, 40}};
  EXPECT_EQ(rim.publish(tets), 3u);
  for (const Labels& t : tets) EXPECT_TRUE(rim.contains(t));
  EXPECT_FALSE(rim.contains({1, 2, 3, 6}));
  EXPECT_FALSE(rim.contains({2, 3, 4, 5}));
  EXPECT_FALSE(rim.contains({0, 2, 3, 4}));
  // Published twice (two zones finished with it): counted once.
  EXPECT_EQ(rim.publish(std::vector<Labels>{{1, 2, 3, 4}}), 0u);
  EXPECT_EQ(rim.size(), 3u);
}

// A slot keeps four 48-bit labels: every bit of each comes back (labels just below
// 2^48 - 1 and ones that differ in single bits are told apart), and a tet with a
// label past that is not published (counted as without room) nor found.
TEST(SharedRim, KeepsEveryBitOfLabelsBelowTwoToThe48) {
  SharedRim rim(1 << 20);
  const std::uint64_t top = (std::uint64_t(1) << 48) - 2;
  std::vector<Labels> tets = {{top - 3, top - 2, top - 1, top}, {0, 1, 2, top}};
  for (int b = 0; b < 47; ++b) {
    const std::uint64_t bit = std::uint64_t(1) << b;
    tets.push_back({bit, bit + 1, 2 * bit + 2, top});
    tets.push_back({1, bit + 1, top - bit, top});
  }
  std::sort(tets.begin(), tets.end());
  tets.erase(std::unique(tets.begin(), tets.end()), tets.end());
  EXPECT_EQ(rim.publish(tets), tets.size());
  std::vector<Labels> seen;
  rim.for_each_touching(0, ~std::uint64_t(0), [&](const Labels& t) { seen.push_back(t); });
  std::sort(seen.begin(), seen.end());
  EXPECT_EQ(seen, tets);
  for (Labels t : tets) {
    EXPECT_TRUE(rim.contains(t));
    t[1] ^= std::uint64_t(1) << 40;  // one bit off: another tet
    if (t[0] < t[1] && t[1] < t[2]) {
      EXPECT_FALSE(rim.contains(t));
    }
  }
  std::uint64_t no_room = 0;
  const Labels past = {1, 2, 3, std::uint64_t(1) << 48};
  EXPECT_EQ(rim.publish(std::vector<Labels>{past}, &no_room), 0u);
  EXPECT_EQ(no_room, 1u);
  EXPECT_FALSE(rim.contains(past));
}

TEST(SharedRim, ForgetsTetsWhoseLabelsAreAllBelow) {
  SharedRim rim(1 << 20);
  std::vector<Labels> tets;
  for (std::uint64_t i = 0; i < 5000; ++i) tets.push_back({i, i + 1, i + 2, i + 100});
  ASSERT_EQ(rim.publish(tets), tets.size());
  rim.forget_below(2100);  // keeps the tets whose largest label is 2100 or more
  for (const Labels& t : tets) EXPECT_EQ(rim.contains(t), t[3] >= 2100) << t[0];
  EXPECT_EQ(rim.size(), 5000u - 2000u);
  rim.forget_below(~std::uint64_t(0) >> 1);
  EXPECT_EQ(rim.size(), 0u);
  EXPECT_EQ(rim.bytes(), 0u);
  EXPECT_FALSE(rim.contains(tets.back()));
}

TEST(SharedRim, StaysWithinItsShare) {
  const std::size_t share = 64 << 10;  // 2730 slots of 24 bytes
  SharedRim rim(share);
  std::vector<Labels> tets;
  for (std::uint64_t i = 0; i < 10000; ++i) tets.push_back({4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3});
  std::uint64_t no_room = 0;
  const std::size_t published = rim.publish(tets, &no_room);
  EXPECT_GT(published, 0u);
  EXPECT_LT(published, tets.size());
  EXPECT_EQ(published + no_room, tets.size());  // the rest are counted as without room
  EXPECT_LE(rim.peak_bytes(), share);
  EXPECT_LE(rim.bytes(), share);
  std::size_t found = 0;
  for (const Labels& t : tets) found += rim.contains(t);
  EXPECT_EQ(found, published);  // what was not published is not found
  // Offered again to the full table: only those not there are counted as without room.
  std::uint64_t again = 0;
  EXPECT_EQ(rim.publish(tets, &again), 0u);
  EXPECT_EQ(again, tets.size() - published);
  // Forgetting makes room again.
  rim.forget_below(4 * 10000);
  EXPECT_EQ(rim.publish(tets), published);
}

// Forgetting most of a full table removes the tets where they lie (the table keeps
// its size) and every tet left stays reachable from its first slot, across the
// table's end too: against a std::set of what was published and not yet forgotten,
// over rounds of random tets with clusters in the probes.
TEST(SharedRim, ForgetsInPlaceAndFindsEveryTetLeft) {
  const std::size_t share = 100'000 * sizeof(Labels);  // not a power of two
  SharedRim rim(share);
  std::mt19937_64 random(7);
  std::set<Labels> expected;
  std::uint64_t floor = 0;
  for (int round = 0; round < 40; ++round) {
    std::vector<Labels> tets;
    for (int i = 0; i < 20000; ++i) {
      Labels t;
      for (auto& l : t) l = floor + random() % 200'000;
      std::sort(t.begin(), t.end());
      if (t[0] == t[1] || t[1] == t[2] || t[2] == t[3]) continue;
      tets.push_back(t);
    }
    const std::size_t before = rim.size();
    const std::size_t published = rim.publish(tets);
    ASSERT_EQ(rim.size(), before + published);
    // publish stops at the first tet without room: the ones before it are in.
    std::size_t seen = 0;
    for (const Labels& t : tets) {
      if (expected.count(t)) continue;
      if (seen == published) break;
      expected.insert(t);
      ++seen;
    }
    ASSERT_LE(rim.bytes(), share);
    floor += 40'000;
    rim.forget_below(floor);
    for (auto it = expected.begin(); it != expected.end();) it = (*it)[3] < floor ? expected.erase(it) : std::next(it);
    ASSERT_EQ(rim.size(), expected.size()) << "round " << round;
    for (const Labels& t : expected) ASSERT_TRUE(rim.contains(t)) << "round " << round;
    for (const Labels& t : tets) ASSERT_EQ(rim.contains(t), expected.count(t) == 1) << "round " << round;
  }
  // The table grew past two thirds of its share (powers of two could not) and kept
  // its size while forgetting.
  EXPECT_GT(rim.peak_bytes(), share * 4 / 5);
}

TEST(SharedRim, LookupsWhilePublishingAndForgetting) {
  SharedRim rim(8 << 20);
  std::atomic<bool> done{false};
  std::atomic<std::uint64_t> wrong{0};
  // Only tets with an even first label are ever published.
  std::thread reader([&] {
    std::uint64_t i = 0;
    while (!done.load()) {
      const std::uint64_t a = 2 * (i % 20000) + 1;
      wrong += rim.contains({a, a + 1, a + 2, a + 3});
      ++i;
    }
  });
  for (std::uint64_t round = 0; round < 50; ++round) {
    std::vector<Labels> tets;
    for (std::uint64_t i = 0; i < 2000; ++i) {
      const std::uint64_t a = 2 * (round * 2000 + i);
      tets.push_back({a, a + 1, a + 2, a + 3});
    }
    rim.publish(tets);
    rim.forget_below(2 * round * 2000);
  }
  done = true;
  reader.join();
  EXPECT_EQ(wrong.load(), 0u);
}

}  // namespace
}  // namespace tetstream::pipeline
