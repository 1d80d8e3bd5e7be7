// The parallel k-way merge (pipeline/files/parallel_merge.hpp) and the external sort's
// merge in rounds on 1 to 4 threads: the same records in the same order as the
// sequential merge, ties (many duplicates) in run order.
#include "pipeline/files/external_sort.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <span>
#include <vector>

namespace tetstream::pipeline {
namespace {

using testing_util::ScratchDirTest;

// Compared by key alone; `tag` says where a record came from, so a tie out of order shows.
struct Rec {
  std::uint32_t key;
  std::uint32_t tag;
  bool operator==(const Rec&) const = default;
};
struct ByKey {
  bool operator()(const Rec& a, const Rec& b) const { return a.key < b.key; }
};

// `k` runs, each sorted by key (stably: ties keep their tags' order), keys from a
// small range so that most records have duplicates in several runs.
std::vector<std::vector<Rec>> random_runs(std::mt19937& rng, std::size_t k, std::size_t most, std::uint32_t keys) {
  std::vector<std::vector<Rec>> runs(k);
  std::uint32_t tag = 0;
  for (auto& run : runs) {
    run.resize(std::uniform_int_distribution<std::size_t>(0, most)(rng));
    for (Rec& r : run) r = {std::uniform_int_distribution<std::uint32_t>(0, keys)(rng), tag++};
    std::stable_sort(run.begin(), run.end(), ByKey{});
  }
  return runs;
}

// What every merge must give: the runs concatenated in order, stably sorted by key.
std::vector<Rec> expected(const std::vector<std::vector<Rec>>& runs) {
  std::vector<Rec> all;
  for (const auto& r : runs) all.insert(all.end(), r.begin(), r.end());
  std::stable_sort(all.begin(), all.end(), ByKey{});
  return all;
}

TEST(ParallelMerge, SpansEqualTheSequentialMergeOnOneToFourThreads) {
  for (std::uint32_t seed = 1; seed <= 40; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    std::mt19937 rng(seed);
    const std::size_t k = 1 + seed % 7;
    const auto runs = random_runs(rng, k, seed % 3 == 0 ? 40 : 20000, seed % 2 ? 50 : 1000000);
    std::vector<std::span<const Rec>> in;
    for (const auto& r : runs) in.emplace_back(r);
    const std::vector<Rec> want = expected(runs);
    for (int threads = 1; threads <= 4; ++threads) {
      std::vector<Rec> got(want.size());
      detail::parallel_merge_spans(in, got.data(), ByKey{}, threads);
      EXPECT_EQ(got, want) << threads << " threads";
    }
  }
}

class ParallelExternalMerge : public ScratchDirTest {
 protected:
  ParallelExternalMerge() : ScratchDirTest("parallel_merge") {}
};

TEST_F(ParallelExternalMerge, InRoundsEqualsTheSequentialMerge) {
  const int saved = omp_get_max_threads();
  for (std::uint32_t seed = 1; seed <= 12; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    std::mt19937 rng(seed);
    auto runs = random_runs(rng, 2 + seed % 9, 30000, seed % 2 ? 100 : 1u << 30);
    const std::vector<Rec> want = expected(runs);
    for (int threads = 1; threads <= 4; ++threads) {
      omp_set_num_threads(threads);
      // A small budget: windows of a few hundred records, many rounds, and for some
      // seeds intermediate passes (fan-in below the run count).
      ExternalSortOptions options;
      options.memory_bytes = (seed % 3 == 0 ? 4 : 64) << 10;
      options.min_block_bytes = 512;
      options.batch_records = 1000;
      options.dir = path("");
      // Appended piece by piece: GCC 12's -Wrestrict misreads the chained operator+.
      options.name = "s";
      options.name += std::to_string(seed);
      options.name += "t";
      options.name += std::to_string(threads);
      options.give_back_runs = seed % 2 == 0;
      ExternalSorter<Rec, ByKey> sorter(options);
      for (auto& r : runs) sorter.push_sorted_run(std::span<Rec>(r));
      std::vector<Rec> got;
      sorter.merge([&](std::span<const Rec> batch) {
        EXPECT_LE(batch.size(), 1000u);
        got.insert(got.end(), batch.begin(), batch.end());
      });
      EXPECT_EQ(got, want) << threads << " threads";
    }
  }
  omp_set_num_threads(saved);
}

}  // namespace
}  // namespace tetstream::pipeline
