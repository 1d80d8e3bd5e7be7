// The pure parts of a distributed verify: how the frames and labels are shared
// (pipeline/verify/split.hpp), the exact sum of the volumes
// (pipeline/verify/exact_sum.hpp), and records exchanged between ranks
// (pipeline::exchange_records, over threads: thread_ranks.hpp).
#include "pipeline/util/communicator.hpp"
#include "pipeline/verify/exact_sum.hpp"
#include "pipeline/verify/split.hpp"
#include "thread_ranks.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace tetstream {
namespace {

using pipeline::split_frames;
using pipeline::verify_engine::ExactSum;

TEST(VerifySplit, BalancesTetsAndCutsWhereTheLabelChanges) {
  // Ten frames of 100 tets; frames 4 and 5 share their smallest label.
  const std::vector<std::uint64_t> mins = {0, 10, 20, 30, 40, 40, 60, 70, 80, 90};
  const std::vector<std::uint64_t> tets(10, 100);
  const auto one = split_frames(mins, tets, 1);
  EXPECT_EQ(one.first, (std::vector<std::size_t>{0, 10}));
  EXPECT_EQ(one.owner(0), 0);
  EXPECT_EQ(one.owner(1u << 30), 0);
  const auto two = split_frames(mins, tets, 2);
  // Half the tets before frame 5, but frame 5 shares frame 4's label: cut at 6.
  EXPECT_EQ(two.first, (std::vector<std::size_t>{0, 6, 10}));
  EXPECT_EQ(two.low[1], 60u);
  EXPECT_EQ(two.owner(59), 0);
  EXPECT_EQ(two.owner(60), 1);
  EXPECT_EQ(two.owner(1000), 1);
  const auto five = split_frames(mins, tets, 5);
  EXPECT_EQ(five.first, (std::vector<std::size_t>{0, 2, 4, 6, 8, 10}));
  for (int r = 0; r < 5; ++r) EXPECT_EQ(five.owner(five.low[std::size_t(r)] + 1), r);
}

TEST(VerifySplit, MoreRanksThanLabelsLeavesSomeWithout) {
  // One label for every frame: one rank takes them all; the others own nothing.
  const auto s = split_frames({7, 7, 7}, {5, 5, 5}, 3);
  EXPECT_EQ(s.first, (std::vector<std::size_t>{0, 3, 3, 3}));
  for (std::uint64_t l : {0ull, 7ull, 100ull}) EXPECT_EQ(s.owner(l), 0);
  // No frames at all.
  const auto none = split_frames({}, {}, 2);
  EXPECT_EQ(none.owner(5), 0);
  // Two frames, three ranks: rank 1 gets one (the middle rank may stay empty).
  const auto t = split_frames({0, 50}, {10, 10}, 3);
  EXPECT_EQ(t.first.back(), 2u);
  EXPECT_EQ(t.owner(49), t.owner(0));
  EXPECT_NE(t.owner(50), t.owner(0));
}

TEST(ExactSum, OrderDoesNotChangeTheBits) {
  std::mt19937_64 g(3);
  std::vector<long double> terms;
  for (int i = 0; i < 20000; ++i) {
    const double m = std::ldexp(double(g() >> 11), -53);
    const long double x = std::ldexp(static_cast<long double>(m), int(g() % 200) - 100) * ((g() & 1) ? 1 : -1);
    terms.push_back(i % 7 ? static_cast<long double>(double(x)) : x);
  }
  terms.push_back(1e300L * 1e300L);  // beyond any double
  terms.push_back(-1e300L * 1e300L);
  ExactSum a, b, c1, c2;
  for (long double x : terms) a.add(x);
  std::shuffle(terms.begin(), terms.end(), g);
  for (long double x : terms) b.add(x);
  for (std::size_t i = 0; i < terms.size(); ++i) (i % 3 ? c1 : c2).add(terms[i]);
  c2.add(c1);
  EXPECT_EQ(a.value(), b.value());
  EXPECT_EQ(a.value(), c2.value());
  EXPECT_EQ(ExactSum::from_bytes(a.bytes()).value(), a.value());
}

TEST(ExactSum, IsExact) {
  ExactSum s;
  s.add(1e300L);
  s.add(1.0L);
  s.add(-1e300L);
  EXPECT_EQ(s.value(), 1.0L);  // a rounded sum gives 0
  ExactSum t;
  t.add(std::ldexp(1.0L, -16440));  // a subnormal long double
  t.add(std::ldexp(1.0, -1074));    // the smallest double
  t.add(-std::ldexp(1.0, -1074));
  EXPECT_EQ(t.value(), std::ldexp(1.0L, -16440));
  ExactSum u;
  u.add(-2.5);
  u.add(0.25);
  EXPECT_EQ(u.value(), -2.25L);
  EXPECT_EQ(ExactSum().value(), 0.0L);
}

TEST(ExchangeRecords, EveryRanksRecordsByRank) {
  for (int k : {1, 2, 3}) {
    std::vector<std::vector<std::uint64_t>> got(static_cast<std::size_t>(k));
    test::run_ranks(k, [&](pipeline::Communicator& comm) {
      // Rank r sends rank q the values 1000 r + 10 q + i, i < r + q.
      std::vector<std::vector<std::uint64_t>> to(static_cast<std::size_t>(k));
      for (int q = 0; q < k; ++q)
        for (int i = 0; i < comm.rank() + q; ++i)
          to[std::size_t(q)].push_back(std::uint64_t(1000 * comm.rank() + 10 * q + i));
      got[std::size_t(comm.rank())] = pipeline::exchange_records(comm, to);
    });
    for (int q = 0; q < k; ++q) {
      std::vector<std::uint64_t> want;
      for (int r = 0; r < k; ++r)
        for (int i = 0; i < r + q; ++i) want.push_back(std::uint64_t(1000 * r + 10 * q + i));
      EXPECT_EQ(got[std::size_t(q)], want) << k << " ranks, rank " << q;
    }
  }
}

}  // namespace
}  // namespace tetstream
