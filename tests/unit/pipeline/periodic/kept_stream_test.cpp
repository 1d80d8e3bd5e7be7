// The keep step's order (docs/periodic.md, "Write"). Its sort (tet_records.hpp:
// radix_sort_kept, a radix sort on the smallest label, then each group by insertion or,
// when large, std::sort) orders the kept tets exactly as KeptTetLess does, the order the
// external sort merges by: groups of one to a few hundred tets, both parities, labels
// up to the bit width. Its stream (kept_stream.hpp) writes frames of tets that come
// out of order, each with a frontier, in the stored order: through its buffer, through
// the external sort when the buffer outgrows its share (the fallback), with the tets
// written last deferred; and refuses a tet that a wrong frontier let pass.
#include "pipeline/periodic/kept_stream.hpp"
#include "pipeline/periodic/tet_records.hpp"
#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>
#include <stdexcept>
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

class KeptStreamTest : public testing_util::ScratchDirTest {
 protected:
  KeptStreamTest() : ScratchDirTest("kept-stream") {}

  // The tets in frames as the padded job's would come: frame k after frontier F_{k-1}
  // (no tet of it below), most tets in the frame whose frontier passes them, some a
  // frame or two earlier (they wait), and those from `deferred` on in the first frames.
  struct Frames {
    std::vector<std::vector<KeptTet>> frames;
    std::vector<std::uint64_t> frontier;  // after each frame
  };
  static Frames frames_of(const std::vector<KeptTet>& sorted, std::uint64_t deferred, std::uint32_t seed) {
    std::mt19937_64 rng(seed);
    Frames f;
    const std::size_t count = 40;
    f.frames.resize(count);
    for (std::size_t k = 0; k < count; ++k) f.frontier.push_back(k + 1 == count ? ~0ull : deferred * (k + 1) / count);
    for (const KeptTet& t : sorted) {
      std::size_t k = 0;
      if (t.v[0] >= deferred) {
        k = rng() % 3;
      } else {
        // Its frame: the first whose frontier passes it (it is written after it), or,
        // now and then, one of the two before (it waits in the buffer).
        while (k + 1 < count && f.frontier[k] <= t.v[0]) ++k;
        if (rng() % 5 == 0) k -= std::min<std::size_t>(k, rng() % 3);
      }
      f.frames[k].push_back(t);
    }
    for (auto& fr : f.frames) std::shuffle(fr.begin(), fr.end(), rng);
    return f;
  }

  std::vector<KeptTet> stream(const Frames& f, std::uint64_t deferred, std::size_t buffer_bytes, int label_bits,
                              bool& spilled) {
    ExternalSorter<KeptTet, KeptTetLess> sorter(sort_options(std::size_t(1) << 16, dir_.string(), "kept-test"));
    sorter.set_run_sort([label_bits](KeptTet* d, std::size_t n) { radix_sort_kept(d, n, label_bits); });
    std::vector<KeptTet> out;
    KeptStream s([&out](std::span<const KeptTet> t) { out.insert(out.end(), t.begin(), t.end()); }, deferred,
                 buffer_bytes, sorter, label_bits);
    for (std::size_t k = 0; k < f.frames.size(); ++k) s.add(f.frames[k], f.frontier[k]);
    s.finish();
    spilled = s.spilled();
    return out;
  }
};

TEST_F(KeptStreamTest, WritesTheStoredOrderThroughTheBufferAndThroughTheFallback) {
  const int label_bits = 20;
  std::vector<KeptTet> all = random_tets(6000, label_bits, 5);
  std::sort(all.begin(), all.end(), KeptTetLess{});
  all.erase(std::unique(all.begin(), all.end(),
                        [](const KeptTet& a, const KeptTet& b) { return std::memcmp(&a, &b, sizeof a) == 0; }),
            all.end());
  const std::uint64_t deferred = (std::uint64_t(1) << label_bits) * 9 / 10;
  const Frames f = frames_of(all, deferred, 6);
  for (const std::size_t buffer_bytes : {std::size_t(64) << 20, std::size_t(4096)}) {
    SCOPED_TRACE(buffer_bytes);
    bool spilled = false;
    const std::vector<KeptTet> out = stream(f, deferred, buffer_bytes, label_bits, spilled);
    EXPECT_EQ(spilled, buffer_bytes < 8192);  // the fallback ran where its share was small
    ASSERT_EQ(out.size(), all.size());
    EXPECT_EQ(std::memcmp(out.data(), all.data(), all.size() * sizeof(KeptTet)), 0);
  }
}

TEST_F(KeptStreamTest, RefusesATetAWrongFrontierLetPass) {
  const int label_bits = 16;
  std::vector<KeptTet> all = random_tets(500, label_bits, 8);
  std::sort(all.begin(), all.end(), KeptTetLess{});
  ExternalSorter<KeptTet, KeptTetLess> sorter(sort_options(std::size_t(1) << 16, dir_.string(), "kept-wrong"));
  std::size_t written = 0;
  KeptStream s([&written](std::span<const KeptTet> t) { written += t.size(); }, ~0ull, std::size_t(64) << 20, sorter,
               label_bits);
  const std::size_t half = all.size() / 2;
  // The second half first, with a frontier past all of it: then the first half.
  s.add(std::span<const KeptTet>(all).subspan(half), ~0ull);
  EXPECT_THROW(s.add(std::span<const KeptTet>(all).first(half), ~0ull), std::logic_error);
  EXPECT_EQ(written, all.size() - half);
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
