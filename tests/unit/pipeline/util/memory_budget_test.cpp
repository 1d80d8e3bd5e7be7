// The memory ledger (pipeline/memory_budget.hpp): a phase's shares never exceed the
// ceiling, and a small input takes little of a large budget.
#include "pipeline/util/memory_budget.hpp"

#include "core/error.hpp"
#include "pipeline/run/run.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

namespace tetstream::pipeline {
namespace {

constexpr std::uint64_t kMiB = std::uint64_t(1) << 20;

TEST(MemoryBudget, PhasesNeverExceedTheCeiling) {
  for (std::uint64_t ceiling :
       {32 * kMiB, 48 * kMiB, 64 * kMiB, 96 * kMiB, 128 * kMiB, 1024 * kMiB, 16384 * kMiB, kMiB << 20}) {
    for (std::uint64_t points : {std::uint64_t(4), std::uint64_t(1000), std::uint64_t(100000), std::uint64_t(10000000),
                                 std::uint64_t(1000000000), std::uint64_t(100000000000)}) {
      for (int threads : {1, 2, 16, 256}) {
        SCOPED_TRACE("ceiling " + std::to_string(ceiling >> 20) + " MiB, " + std::to_string(points) + " points, " +
                     std::to_string(threads) + " threads");
        MemoryBudget budget(ceiling, points, threads, 16);
        budget.plan_sort();
        EXPECT_LE(budget.phase_total("sort"), ceiling);
        for (double index_per_point : {0.0, 4.0, 12.0}) {
          const TriangulateShares t = budget.plan_triangulate(std::uint64_t(index_per_point * double(points)));
          // A budget whose windows get nothing is refused by the plan; otherwise the
          // phase, its reserve included, fits.
          if (t.window_bytes > 0) {
            EXPECT_LE(budget.phase_total("triangulate"), ceiling);
          }
          EXPECT_GE(t.encoders, 1);
          EXPECT_LE(t.encoders, 16);
        }
      }
    }
  }
}

// The keep step of a periodic job: its phase fits the ceiling whenever it is planned,
// and a label map that cannot fit is refused with the --memory that would do.
TEST(MemoryBudget, TheKeepPhaseFitsOrIsRefused) {
  for (std::uint64_t ceiling : {32 * kMiB, 64 * kMiB, 1024 * kMiB}) {
    for (std::uint64_t map : {std::uint64_t(0), 4 * kMiB, 400 * kMiB, 2048 * kMiB}) {
      for (std::uint64_t frames : {kMiB, 40 * kMiB}) {
        SCOPED_TRACE("ceiling " + std::to_string(ceiling >> 20) + " MiB, map " + std::to_string(map >> 20) +
                     " MiB, frames " + std::to_string(frames >> 20) + " MiB");
        MemoryBudget budget(ceiling, 1000, 2, 2);
        if (budget.runtime_bytes() + map + frames + 4 * kMiB > ceiling) {
          try {
            budget.plan_keep(map, frames);
            ADD_FAILURE() << "not refused";
          } catch (const UsageError& e) {
            EXPECT_NE(std::string(e.what()).find("at least --memory"), std::string::npos) << e.what();
          }
          continue;
        }
        const KeepShares k = budget.plan_keep(map, frames);
        EXPECT_GE(k.sort_bytes, 4 * kMiB);
        EXPECT_LE(k.sort_bytes, std::max(ceiling / 4, 4 * kMiB));
        EXPECT_LE(budget.phase_total("keep"), ceiling);
      }
    }
  }
}

TEST(MemoryBudget, SmallInputsTakeLittleOfALargeBudget) {
  for (std::uint64_t ceiling : {1024 * kMiB, kMiB << 20}) {
    MemoryBudget budget(ceiling, 1000, 2, 16);
    const SortShares sort = budget.plan_sort();
    EXPECT_LE(sort.run_points, std::size_t(1) << 16);  // one read chunk
    EXPECT_LE(sort.merge_bytes, kMiB);
    const TriangulateShares t = budget.plan_triangulate(16 * 1000, 480.0 * 1000);
    EXPECT_LT(t.writer_bytes, 2 * kMiB);  // 8,000 tets at most in flight, not 2^18-tet frames
    EXPECT_LE(t.query_page_bytes, 1000 * 32 + 2 * kMiB);
    // Everything but the fixed reserve is what 1,000 points need.
    // (The query pages' one 2 MiB region and the writer's few frames dominate.)
    EXPECT_LT(budget.phase_total("triangulate") - budget.runtime_bytes(), 8 * kMiB);
    EXPECT_LT(budget.phase_total("sort") - budget.runtime_bytes(), 4 * kMiB);
  }
}

// The shared rim's table: a large budget gives it room beyond the old 32nd of the rest
// (at 1G and 10^7 points the old rule gave 27.3 MiB, and on surfaces the zones after a
// full table proved its tets again), and a small one keeps its query pages (at 64M
// taking them for the table made `hills` 10% slower).
TEST(MemoryBudget, TheRimTableGrowsWithTheBudgetAndSmallBudgetsKeepTheirQueryPages) {
  {
    MemoryBudget budget(1024 * kMiB, 10000000, 2, 2);
    budget.plan_sort();
    const TriangulateShares t = budget.plan_triangulate(80000000);
    EXPECT_GE(t.shared_rim_bytes, 64 * kMiB);
    EXPECT_GE(t.query_page_bytes, 64 * kMiB);
    EXPECT_LE(budget.phase_total("triangulate"), 1024 * kMiB);
  }
  {
    MemoryBudget budget(64 * kMiB, 1000000, 2, 2);
    budget.plan_sort();
    const TriangulateShares t = budget.plan_triangulate(8000000);
    EXPECT_GE(t.query_page_bytes, 64 * kMiB / 8 - 64 * kMiB / 32);
    EXPECT_LE(t.shared_rim_bytes, 64 * kMiB / 32);
    EXPECT_LE(budget.phase_total("triangulate"), 64 * kMiB);
  }
}

TEST(MemoryBudget, SharesAreNamedOncePerPhase) {
  MemoryBudget budget(256 * kMiB, 1000000, 2, 2);
  budget.plan_sort();
  budget.plan_triangulate(12000000);
  budget.plan_triangulate(12000000, 1e6);  // planned again: replaced, not added
  int windows = 0;
  for (const MemoryBudget::Share& s : budget.shares())
    if (s.phase == "triangulate" && s.name == "windows") {
      ++windows;
      EXPECT_EQ(s.bytes, 1000000u);
    }
  EXPECT_EQ(windows, 1);
  EXPECT_LE(budget.phase_total("triangulate"), 256 * kMiB);
}

TEST(MemoryBudget, WriterFramesFollowTheOutput) {
  // Frames of 2^18 tets: a small output has one small frame in flight, a large one
  // 2 * encoders + 1 full frames.
  const std::uint64_t small = MemoryBudget::writer_bytes_for(1, 1000, 1 << 18);
  const std::uint64_t large = MemoryBudget::writer_bytes_for(4, 100000000, 1 << 18);
  EXPECT_LT(small, 200000u);
  EXPECT_GE(large, std::uint64_t((9 * 32 + 4 * 40) * (1 << 18)));
  EXPECT_EQ(MemoryBudget::encoders_for(64 * kMiB, 16), 1);
  EXPECT_EQ(MemoryBudget::encoders_for(kMiB << 20, 16), 16);
  EXPECT_EQ(MemoryBudget::encoders_for(kMiB << 10, 16), 4);  // 1G: one per 256 MiB
  EXPECT_EQ(MemoryBudget::encoders_for(kMiB << 20, 2), 2);
}

TEST(MemoryBudget, FramesAndTheFileBufferShrinkWithTheBudget) {
  // Frames of a 1024th of the budget in tets, powers of two from 2^12 to 2^18: a
  // small budget is not taken by the writer (2^18-tet frames were 37 MiB in flight,
  // more than all of --memory 32M), and from 256M up the frames are the largest.
  EXPECT_EQ(MemoryBudget::frame_tets_for(kMiB), kSmallestFrameTets);
  EXPECT_EQ(MemoryBudget::frame_tets_for(32 * kMiB), std::size_t(1) << 15);
  EXPECT_EQ(MemoryBudget::frame_tets_for(64 * kMiB), std::size_t(1) << 16);
  EXPECT_EQ(MemoryBudget::frame_tets_for(100 * kMiB), std::size_t(1) << 16);
  EXPECT_EQ(MemoryBudget::frame_tets_for(256 * kMiB), kFrameTets);
  EXPECT_EQ(MemoryBudget::frame_tets_for(kMiB << 20), kFrameTets);
  for (std::uint64_t ceiling : {32 * kMiB, 64 * kMiB, 256 * kMiB, 1024 * kMiB}) {
    MemoryBudget budget(ceiling, 1000000, 2, 16);
    const TriangulateShares t = budget.plan_triangulate(4000000);
    EXPECT_LE(t.writer_bytes, ceiling / 6) << (ceiling >> 20) << " MiB";
    EXPECT_LE(t.file_buffer_bytes, t.writer_bytes);
    EXPECT_GE(t.file_buffer_bytes, std::size_t(64) << 10);
  }
}

// --memory as people write it: every unit binary, any case, with or without B / iB.
// `run --index auto`: the index goes to disk when in memory it would take more than
// an eighth of the budget, and only when the share its file keeps resident is smaller
// than it (under 512M the share's 32 MiB floor is the larger one).
TEST(MemoryBudget, TheIndexGoesToDiskOnlyWhereItWouldHoldLess) {
  constexpr std::uint64_t M = std::uint64_t(1) << 20, G = std::uint64_t(1) << 30;
  EXPECT_EQ(index_disk_share(100 * M), 32 * M);
  EXPECT_EQ(index_disk_share(8 * G), G / 2);
  // 10^9 points at 8G: 7.5 GB in memory, half a gigabyte on disk.
  EXPECT_TRUE(index_crowds_budget(1000000000, 8 * G));
  EXPECT_FALSE(index_crowds_budget(1000000000, 64 * G));  // an eighth of 64G holds it
  // 3 M points at 100M: 22.5 MB in memory, over an eighth but under the 32 MiB share.
  EXPECT_FALSE(index_crowds_budget(3000000, 100 * M));
  // 10^7 points at 210M: 75 MB, over both.
  EXPECT_TRUE(index_crowds_budget(10000000, 210 * M));
  RunOptions o;
  o.memory_bytes = 100 * M;
  EXPECT_FALSE(o.index_on_disk(3000000));
  o.index = RunOptions::IndexPlacement::kDisk;
  EXPECT_TRUE(o.index_on_disk(3000000));  // asked for: as asked
}

TEST(MemorySize, ParsedAsPeopleWriteIt) {
  EXPECT_EQ(parse_memory_size("512M"), 512 * kMiB);
  EXPECT_EQ(parse_memory_size("512m"), 512 * kMiB);
  EXPECT_EQ(parse_memory_size("512MB"), 512 * kMiB);
  EXPECT_EQ(parse_memory_size("512MiB"), 512 * kMiB);
  EXPECT_EQ(parse_memory_size("512mb"), 512 * kMiB);
  EXPECT_EQ(parse_memory_size("1g"), 1024 * kMiB);
  EXPECT_EQ(parse_memory_size("1GiB"), 1024 * kMiB);
  EXPECT_EQ(parse_memory_size("1.5G"), 1536 * kMiB);
  EXPECT_EQ(parse_memory_size("4096K"), 4 * kMiB);
  EXPECT_EQ(parse_memory_size("2T"), 2 * (kMiB << 20));
  EXPECT_EQ(parse_memory_size("100000"), 100000u);
  for (const char* bad : {"", "G", "12Q", "-1G", "0", "nan", "inf", "1e30T", "5 G", "1.5GG"})
    EXPECT_THROW(parse_memory_size(bad), UsageError) << bad;
}

}  // namespace
}  // namespace tetstream::pipeline
