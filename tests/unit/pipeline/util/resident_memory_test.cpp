// peak_resident_bytes: the kernel's high-water mark of the resident set, which run
// --json reports and the triangulation compares with the budget. Pages touched count;
// the peak never falls when they are freed.
#include "pipeline/util/resident_memory.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <memory>

namespace tetstream::pipeline {
namespace {

TEST(ResidentMemory, ThePeakCountsTouchedPagesAndStaysWhenTheyAreFreed) {
  const std::uint64_t before = peak_resident_bytes();
  ASSERT_GT(before, 0u) << "getrusage gave no peak";
  constexpr std::size_t kBytes = std::size_t(96) << 20;  // more than the test binary holds
  {
    auto block = std::make_unique<char[]>(kBytes);
    std::memset(block.get(), 1, kBytes);  // every page resident
    volatile char sink = block[kBytes - 1];
    (void)sink;
    EXPECT_GE(peak_resident_bytes(), kBytes);
  }
  const std::uint64_t after = peak_resident_bytes();
  EXPECT_GE(after, kBytes);
  EXPECT_GE(after, before);
}

}  // namespace
}  // namespace tetstream::pipeline
