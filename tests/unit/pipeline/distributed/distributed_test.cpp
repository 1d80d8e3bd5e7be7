// The pieces of a job under MPI that need no MPI: how ranks split the labels, and how
// they stop together when one fails (pipeline/communicator.hpp,
// pipeline/run_distributed.hpp). The job itself is tested under mpirun by
// tests/cli/mpi_cli.sh.
#include "pipeline/util/communicator.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/distributed/rank_cost.hpp"
#include "pipeline/distributed/run_distributed.hpp"
#include "pipeline/files/work_dir.hpp"

#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <filesystem>

#include <chrono>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

namespace tetstream::pipeline {
namespace {

TEST(RankLabelBounds, WholeBlocksBalancedAndCoveringEveryLabel) {
  for (const auto& [count, block, ranks] : std::vector<std::tuple<std::uint64_t, std::uint64_t, int>>{
           {200000, 32768, 3}, {1000000, 4096, 7}, {10, 4096, 3}, {65536, 32768, 2}, {65537, 32768, 2}, {5, 1, 8}}) {
    SCOPED_TRACE(std::to_string(count) + " labels, blocks of " + std::to_string(block) + ", " + std::to_string(ranks));
    const std::vector<std::uint64_t> b = rank_label_bounds(count, block, ranks);
    ASSERT_EQ(b.size(), std::size_t(ranks) + 1);
    EXPECT_EQ(b.front(), 0u);
    EXPECT_EQ(b.back(), count);
    const std::uint64_t blocks = (count + block - 1) / block;
    for (int r = 0; r < ranks; ++r) {
      EXPECT_LE(b[std::size_t(r)], b[std::size_t(r) + 1]);
      // Every inner bound on a block boundary (the last one may be the count).
      if (b[std::size_t(r)] != count) {
        EXPECT_EQ(b[std::size_t(r)] % block, 0u);
      }
      // A rank has blocks/ranks or one more.
      const std::uint64_t mine =
          (std::min(b[std::size_t(r) + 1], blocks * block) - b[std::size_t(r)] + block - 1) / block;
      EXPECT_GE(mine, blocks / std::uint64_t(ranks));
      EXPECT_LE(mine, blocks / std::uint64_t(ranks) + 1);
    }
  }
}

// A resumed job's rank 0 keeps the frames it wrote (on another number of ranks, maybe
// past its share): its range ends at the block holding their end, the other ranks
// share the rest in whole blocks; frames within its share change nothing.
TEST(RankLabelBounds, RankZerosWrittenLabelsStayItsOwn) {
  const std::uint64_t count = 1000000, block = 32768;  // 31 blocks
  EXPECT_EQ(rank_label_bounds(count, block, 3, 100000), rank_label_bounds(count, block, 3));
  const std::vector<std::uint64_t> b = rank_label_bounds(count, block, 3, 500000);  // past a third
  ASSERT_EQ(b.size(), 4u);
  EXPECT_EQ(b[0], 0u);
  EXPECT_EQ(b[1], 16 * block);  // 500000 is in block 15: rank 0 ends after it
  EXPECT_EQ(b[2] % block, 0u);
  EXPECT_GT(b[2], b[1]);
  EXPECT_LT(b[2], b[3]);
  EXPECT_EQ(b[3], count);
  // Everything written: rank 0 takes every label, the others none.
  const std::vector<std::uint64_t> all = rank_label_bounds(count, block, 2, count);
  EXPECT_EQ(all, (std::vector<std::uint64_t>{0, count, count}));
  EXPECT_EQ(rank_label_bounds(count, block, 1, 500000), (std::vector<std::uint64_t>{0, count}));
}

// With the blocks' expected costs, each rank's range ends at the block boundary
// nearest its share of the cost: a range of cheap blocks is long, one of dear blocks
// short; uniform costs give the ranges of no costs; rank 0's written frames still bind.
TEST(RankLabelBounds, BalancedByTheBlocksCosts) {
  const std::uint64_t block = 1000, count = 12 * block - 17;  // 12 blocks, the last short
  const std::vector<std::uint64_t> flat(12, 5);
  for (int ranks : {1, 2, 3, 5, 12, 13})
    EXPECT_EQ(rank_label_bounds(count, block, ranks, 0, flat), rank_label_bounds(count, block, ranks)) << ranks;
  // Blocks 0-5 cost 1 each, 6-11 cost 3: a total of 24, 12 a rank on 2 ranks.
  std::vector<std::uint64_t> costs(12, 1);
  for (int i = 6; i < 12; ++i) costs[std::size_t(i)] = 3;
  EXPECT_EQ(rank_label_bounds(count, block, 2, 0, costs), (std::vector<std::uint64_t>{0, 8 * block, count}));
  // 4 ranks, 6 each: blocks 0-5 | 6-7 | 8-9 | 10-11.
  EXPECT_EQ(rank_label_bounds(count, block, 4, 0, costs),
            (std::vector<std::uint64_t>{0, 6 * block, 8 * block, 10 * block, count}));
  // Rank 0 wrote into block 8: it keeps blocks 0-8 (cost 15); ranks 1-2 share 9-11 (9).
  EXPECT_EQ(rank_label_bounds(count, block, 3, 8 * block + 1, costs),
            (std::vector<std::uint64_t>{0, 9 * block, 10 * block, count}));
  // One dear block (111 in all, 37 a rank): rank 0 stops short of it (3 is nearer 37
  // than 103), rank 1 takes it alone (103 is nearer 74 than 3), rank 2 the rest.
  std::vector<std::uint64_t> spike(12, 1);
  spike[3] = 100;
  const std::vector<std::uint64_t> b = rank_label_bounds(count, block, 3, 0, spike);
  EXPECT_EQ(b.front(), 0u);
  EXPECT_EQ(b.back(), count);
  for (std::size_t r = 0; r + 1 < b.size(); ++r) EXPECT_LE(b[r], b[r + 1]);
  EXPECT_EQ(b, (std::vector<std::uint64_t>{0, 3 * block, 4 * block, count}));
  EXPECT_THROW(rank_label_bounds(count, block, 2, 0, std::vector<std::uint64_t>(11, 1)), std::logic_error);
}

// A resume on another number of ranks removes the other ranks' work files by their
// names: each of a rank's names gives its rank; rank 0's, and names that are not work
// files (a user's "rank-1.json.bak"), give none.
TEST(WorkFileRank, EveryNameARankWritesAndNoOther) {
  for (const auto& [name, rank] : std::vector<std::pair<std::string, int>>{{"rank-1.json", 1},
                                                                           {"rank-12.tets", 12},
                                                                           {"rank-3.tets.partial", 3},
                                                                           {"rank-2-pending-7.tets", 2},
                                                                           {"rank-4.progress", 4},
                                                                           {"rank-5-points-0.run", 5},
                                                                           {"rank-5-points-0.run.hull", 5},
                                                                           {"rank-1.json.tmp", 1},
                                                                           {"state.json", -1},
                                                                           {"pending-3.tets", -1},
                                                                           {"index.shared", -1},
                                                                           {"points-0.run", -1},
                                                                           {"rank-1.json.bak", -1},
                                                                           {"rank-x.json", -1},
                                                                           {"myrank-1.json", -1}}) {
    EXPECT_EQ(work_file_rank(name), rank) << name;
    if (rank >= 0) {
      EXPECT_TRUE(is_work_file_name(name)) << name;
    }
  }
}

// A job of `codes.size()` ranks seen from `rank`: all_gather hands back every rank's
// code as given (the others' as if they had reached the same step).
class ScriptedRanks final : public Communicator {
 public:
  ScriptedRanks(int rank, std::vector<std::uint64_t> codes) : rank_(rank), codes_(std::move(codes)) {}
  int rank() const override { return rank_; }
  int size() const override { return int(codes_.size()); }
  int agree(int code) override { return code; }
  std::vector<std::uint64_t> all_gather(std::uint64_t value) override {
    std::vector<std::uint64_t> all = codes_;
    all[std::size_t(rank_)] = value;  // this rank's own, as it came out of the work
    return all;
  }
  std::string broadcast(const std::string& bytes, int) override { return bytes; }
  std::vector<std::string> gather(const std::string& bytes, int) override { return {bytes}; }
  std::vector<std::uint64_t> all_to_all(const std::vector<std::uint64_t>& to_each) override { return to_each; }
  void exchange(const void*, const std::vector<std::uint64_t>&, void*, const std::vector<std::uint64_t>&,
                std::size_t) override {}
  std::uint64_t bytes_sent() const override { return 0; }

 private:
  int rank_;
  std::vector<std::uint64_t> codes_;
};

TEST(Together, TheLowestFailingRankSpeaksAndEveryRankStopsWithItsCode) {
  const auto input = [] { throw InputError("in.f64: byte 24: not a number"); };
  const auto fine = [] {};
  // Every rank went well: nothing thrown.
  ScriptedRanks all_well(1, {0, 0, 0});
  EXPECT_NO_THROW(together(all_well, fine));
  // Rank 1 fails alone: it rethrows its own error; ranks 0 and 2 stop with its code.
  ScriptedRanks failing(1, {0, 0, 0});
  EXPECT_THROW(together(failing, input), InputError);
  for (int r : {0, 2}) {
    ScriptedRanks other(r, {0, 1, 0});
    try {
      together(other, fine);
      ADD_FAILURE() << "rank " << r << " went on";
    } catch (const PeerFailed& e) {
      EXPECT_EQ(e.code(), ExitCode::kBadInput);
    }
  }
  // Ranks 1 and 2 both fail (the same bad option everywhere, say): only rank 1's
  // error is rethrown; rank 2 stops quietly with rank 1's code.
  ScriptedRanks second(2, {0, 2, 0});
  try {
    together(second, [] { throw UsageError("bad"); });
    ADD_FAILURE() << "rank 2 went on";
  } catch (const PeerFailed& e) {
    EXPECT_EQ(e.code(), ExitCode::kUsage);
  }
  // An exception that is not one of ours counts as an I/O failure (exit 3).
  ScriptedRanks odd(0, {0, 0});
  EXPECT_THROW(together(odd, [] { throw std::runtime_error("odd"); }), std::runtime_error);
  ScriptedRanks after_odd(1, {3, 0});
  try {
    together(after_odd, fine);
  } catch (const PeerFailed& e) {
    EXPECT_EQ(e.code(), ExitCode::kIoFailure);
  }
}

// One progress line for a job: each rank's count goes through its file (from its first
// label on), and rank 0's line adds them to its own; a rank not started yet (no file)
// counts nothing.
class SharedProgress : public testing_util::ScratchDirTest {
 protected:
  SharedProgress() : ScratchDirTest("shared-progress") {}
};

TEST_F(SharedProgress, RankZeroCountsEveryRanksWork) {
  Progress rank1("triangulating", "points", 3000, false), rank2("triangulating", "points", 3000, false);
  rank1.add(1000);  // its first label: not its work
  rank1.share_to(path("rank-1.progress"), 1000);
  rank1.add(400);
  rank1.finish();  // the final count is always written
  Progress rank0("triangulating", "points", 3000, false);
  rank0.add(250);
  rank0.add_shared({path("rank-1.progress"), path("rank-2.progress")});
  EXPECT_EQ(rank0.done_with_shared(), 250u + 400u);
  EXPECT_EQ(rank0.done(), 250u);  // its own count is its own
  rank2.add(2000);
  rank2.share_to(path("rank-2.progress"), 2000);  // shares at once (0 done since its base)
  rank2.add(300);
  rank2.finish();
  // Read at most once a second: the next line sees rank 2's count.
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  EXPECT_EQ(rank0.done_with_shared(), 250u + 400u + 300u);
}

}  // namespace
}  // namespace tetstream::pipeline
