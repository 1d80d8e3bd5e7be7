// The sort's duplicate filter (pipeline/sort/point_sort_detail.hpp) on 1 to 4 threads:
// the same records kept, the same hull candidates' labels and counts as on one thread,
// whatever the batches, with runs of duplicates across batch and slice boundaries.
#include "pipeline/sort/point_sort_detail.hpp"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <random>
#include <unordered_set>
#include <vector>

namespace tetstream::pipeline {
namespace {

using Rec = PointRecord<double, std::uint32_t>;

// Sorted records from a coarse grid (most points repeated, some many times), and a
// random tenth of the originals as hull candidates.
std::vector<Rec> sorted_with_duplicates(std::mt19937& rng, std::size_t n, std::unordered_set<std::uint64_t>& hull) {
  std::vector<Rec> recs(n);
  std::uniform_int_distribution<int> cell(0, 30);
  for (std::size_t i = 0; i < n; ++i) {
    const double p[3] = {double(cell(rng)), double(cell(rng) % 4), 0.5};
    recs[i].set(p, i);
    if (rng() % 10 == 0) hull.insert(i);
  }
  std::sort(recs.begin(), recs.end(), [](const Rec& a, const Rec& b) { return record_before(a, b, 0); });
  return recs;
}

struct Filtered {
  std::vector<Rec> kept;
  std::vector<std::uint64_t> hull;
  std::uint64_t count = 0, duplicates = 0;
};

Filtered filter_in_batches(const std::vector<Rec>& recs, const std::unordered_set<std::uint64_t>& hull,
                           std::size_t batch) {
  sort_detail::DuplicateFilter<Rec> filter(hull);
  Filtered f;
  SortedPoints result;
  std::vector<Rec> kept;
  for (std::size_t i = 0; i < recs.size(); i += batch) {
    filter.filter(std::span<const Rec>(recs.data() + i, std::min(batch, recs.size() - i)), kept, f.hull, result);
    f.kept.insert(f.kept.end(), kept.begin(), kept.end());
  }
  std::sort(f.hull.begin(), f.hull.end());
  f.count = result.count, f.duplicates = result.duplicates;
  return f;
}

// The filter as the merge did it before it ran on threads: one record at a time.
Filtered reference(const std::vector<Rec>& recs, const std::unordered_set<std::uint64_t>& hull) {
  Filtered f;
  for (const Rec& p : recs) {
    const bool candidate = hull.count(p.original()) != 0;
    if (!f.kept.empty() && p.coord(0) == f.kept.back().coord(0) && p.coord(1) == f.kept.back().coord(1) &&
        p.coord(2) == f.kept.back().coord(2)) {
      ++f.duplicates;
      if (candidate) f.hull.push_back(f.count - 1);
      continue;
    }
    if (candidate) f.hull.push_back(f.count);
    f.kept.push_back(p);
    ++f.count;
  }
  std::sort(f.hull.begin(), f.hull.end());
  return f;
}

bool same_bytes(const std::vector<Rec>& a, const std::vector<Rec>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Rec)) == 0;
}

TEST(DuplicateFilter, EqualsOneThreadOnOneToFourThreads) {
  const int saved = omp_get_max_threads();
  for (std::uint32_t seed = 1; seed <= 4; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    std::mt19937 rng(seed);
    std::unordered_set<std::uint64_t> hull;
    const std::vector<Rec> recs = sorted_with_duplicates(rng, 100000, hull);
    omp_set_num_threads(1);
    const Filtered want = filter_in_batches(recs, hull, recs.size());
    const Filtered ref = reference(recs, hull);
    EXPECT_TRUE(same_bytes(want.kept, ref.kept));
    EXPECT_EQ(want.hull, ref.hull);
    EXPECT_EQ(want.count + want.duplicates, recs.size());
    EXPECT_LT(want.count, recs.size() / 10);  // mostly duplicates
    for (int threads = 1; threads <= 4; ++threads)
      for (std::size_t batch : {std::size_t(1) << 14, std::size_t(40000), recs.size()}) {
        omp_set_num_threads(threads);
        const Filtered got = filter_in_batches(recs, hull, batch);
        EXPECT_TRUE(same_bytes(got.kept, want.kept)) << threads << " threads, batches of " << batch;
        EXPECT_EQ(got.hull, want.hull) << threads << " threads, batches of " << batch;
        EXPECT_EQ(got.count, want.count);
        EXPECT_EQ(got.duplicates, want.duplicates);
      }
  }
  omp_set_num_threads(saved);
}

}  // namespace
}  // namespace tetstream::pipeline
