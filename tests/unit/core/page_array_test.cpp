// core::PageArray (core/page_array.hpp): grows without losing elements, and hands
// back the pages past what is asked for, which then read as zero.
#include "core/page_array.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <string>

namespace tetstream::core {
namespace {

struct Quad {
  std::uint32_t v[4];
  std::uint32_t n[4];
};

// Resident anonymous memory of this process, in KiB (RssAnon in /proc/self/status).
long rss_anon_kib() {
  std::ifstream in("/proc/self/status");
  std::string key;
  long value = -1;
  while (in >> key) {
    if (key == "RssAnon:") {
      in >> value;
      return value;
    }
    std::getline(in, key);
  }
  return -1;
}

TEST(PageArray, GrowsWithoutLosingElements) {
  PageArray<Quad> a;
  EXPECT_TRUE(a.empty());
  constexpr std::uint32_t kCount = 300000;  // ~9 MiB: several growths past 2 MiB steps
  for (std::uint32_t i = 0; i < kCount; ++i) {
    Quad& q = a.emplace_back();
    for (int k = 0; k < 4; ++k) EXPECT_EQ(q.v[k] | q.n[k], 0u) << "a new element is value-initialised";
    q.v[0] = i, q.n[3] = ~i;
  }
  ASSERT_EQ(a.size(), kCount);
  EXPECT_GE(a.capacity(), a.size());
  EXPECT_EQ(a.mapped_bytes() % (std::size_t(1) << 21), 0u);
  for (std::uint32_t i = 0; i < kCount; ++i) {
    ASSERT_EQ(a[i].v[0], i);
    ASSERT_EQ(a[i].n[3], ~i);
  }
  PageArray<Quad> b = std::move(a);
  EXPECT_EQ(b.size(), kCount);
  EXPECT_EQ(b[kCount - 1].v[0], kCount - 1);
  EXPECT_EQ(a.size(), 0u);  // NOLINT(bugprone-use-after-move): moved-from is empty by contract
}

TEST(PageArray, ReleasedPagesReadAsZeroAndLeaveTheResidentSet) {
  PageArray<std::uint64_t> a;
  constexpr std::size_t kCount = std::size_t(64) << 17;  // 64 MiB of elements
  a.reserve(kCount);
  for (std::size_t i = 0; i < kCount; ++i) a.push_back(i + 1);
  const long full = rss_anon_kib();
  a.clear();
  a.release_beyond(1000);
  const long released = rss_anon_kib();
  if (full > 0 && released > 0) {
    EXPECT_LT(released, full - 48 * 1024) << "RssAnon " << full << " KiB -> " << released << " KiB";
  }
  // The mapping is kept, the first elements too (within the kept huge page), the rest reads zero.
  EXPECT_EQ(a.capacity(), kCount);
  a.reserve(kCount);
  const std::uint64_t* p = a.data();
  EXPECT_EQ(p[999], 1000u);
  EXPECT_EQ(p[kCount - 1], 0u);
  EXPECT_EQ(p[kCount / 2], 0u);
}

TEST(PageArray, AssignFills) {
  PageArray<int> a;
  a.assign(5, 7);
  ASSERT_EQ(a.size(), 5u);
  for (int x : a) EXPECT_EQ(x, 7);
  a.assign(2, -1);
  ASSERT_EQ(a.size(), 2u);
  EXPECT_EQ(a[0], -1);
}

}  // namespace
}  // namespace tetstream::core
