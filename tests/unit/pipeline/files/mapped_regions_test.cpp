// MappedRegions keeps what scattered reads of a file mapping leave resident within
// its cap: measured in the process's own mapped file pages (RssFile), with reads
// that touch every page of a region, so that a region maps its 2 MiB whatever the
// folios of the page cache.
#include "pipeline/files/temp_files.hpp"

#include "core/error.hpp"

#include <gtest/gtest.h>

#include <boost/iostreams/device/mapped_file.hpp>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

namespace tetstream::pipeline {
namespace {

std::size_t rss_file_bytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("RssFile:", 0) == 0) return std::stoull(line.substr(8)) * 1024;
  return 0;
}

class MappedRegionsTest : public ::testing::Test {
 protected:
  static constexpr std::size_t kRegions = 48;
  void SetUp() override {
    path_ = (std::filesystem::temp_directory_path() / ("mapped_regions_test_" + std::to_string(::getpid()))).string();
    std::vector<char> chunk(MappedRegions::kRegionBytes, 'x');
    std::ofstream out(path_, std::ios::binary);
    for (std::size_t r = 0; r < kRegions; ++r) out.write(chunk.data(), std::streamsize(chunk.size()));
    out.close();
    mapping_.open(path_);
    ASSERT_TRUE(mapping_.is_open());
  }
  void TearDown() override {
    mapping_.close();
    std::filesystem::remove(path_);
  }
  // Reads every page of region r, after touching it.
  std::uint64_t read_region(MappedRegions& regions, std::size_t r) {
    std::uint64_t sum = 0;
    const std::size_t page = std::size_t(::sysconf(_SC_PAGESIZE));
    for (std::size_t off = 0; off < MappedRegions::kRegionBytes; off += page) {
      const char* p = mapping_.data() + r * MappedRegions::kRegionBytes + off;
      regions.touch(p);
      sum += std::uint64_t(*reinterpret_cast<const volatile char*>(p));
    }
    return sum;
  }
  std::string path_;
  boost::iostreams::mapped_file_source mapping_;
};

TEST_F(MappedRegionsTest, HoldsAtMostItsCap) {
  MappedRegions regions(mapping_.data(), mapping_.size(), 4);
  const std::size_t before = rss_file_bytes();
  std::uint64_t sum = 0;
  for (std::size_t r = 0; r < kRegions; ++r) {
    sum += read_region(regions, r);
    EXPECT_LE(regions.held(), 4u);
  }
  EXPECT_EQ(sum, kRegions * MappedRegions::kRegionBytes / std::size_t(::sysconf(_SC_PAGESIZE)) * std::uint64_t('x'));
  // Without the releases, 48 regions of 2 MiB; with them, 4 (and a region's worth
  // of slack for the test's own pages).
  EXPECT_LE(rss_file_bytes(), before + 5 * MappedRegions::kRegionBytes);
  EXPECT_EQ(regions.releases(), kRegions - 4);
  regions.release_all();
  EXPECT_EQ(regions.held(), 0u);
}

TEST_F(MappedRegionsTest, ReleasesTheLeastRecentlyRead) {
  MappedRegions regions(mapping_.data(), mapping_.size(), 3);
  read_region(regions, 0);
  read_region(regions, 1);
  read_region(regions, 2);
  read_region(regions, 0);  // 1 is now the least recently read
  read_region(regions, 3);
  EXPECT_EQ(regions.releases(), 1u);
  // 0 and 2 are held still: reading them releases nothing.
  read_region(regions, 0);
  read_region(regions, 2);
  EXPECT_EQ(regions.releases(), 1u);
  read_region(regions, 1);  // back in, in place of 3
  EXPECT_EQ(regions.releases(), 2u);
}

TEST_F(MappedRegionsTest, ThreadsShareTheCap) {
  MappedRegions regions(mapping_.data(), mapping_.size(), 6);
  const std::size_t before = rss_file_bytes();
  std::vector<std::thread> threads;
  for (int t = 0; t < 2; ++t)
    threads.emplace_back([&, t] {
      for (int pass = 0; pass < 3; ++pass)
        for (std::size_t r = std::size_t(t); r < kRegions; r += 2) read_region(regions, r);
    });
  for (auto& th : threads) th.join();
  EXPECT_LE(regions.held(), 6u);
  // A read racing with the release of its region may map pages that count again
  // only at that region's next read: a region per thread at most.
  EXPECT_LE(rss_file_bytes(), before + (6 + 2 + 1) * MappedRegions::kRegionBytes);
}

TEST_F(MappedRegionsTest, ScatteredReadsBypassTheMapping) {
  // Distinct bytes, so that a read from the wrong place shows.
  {
    std::vector<char> chunk(MappedRegions::kRegionBytes);
    std::ofstream out(path_, std::ios::binary | std::ios::in | std::ios::out);
    for (std::size_t r = 0; r < kRegions; ++r) {
      for (std::size_t i = 0; i < chunk.size(); ++i) chunk[i] = char((r * 7 + i) & 0x7F);
      out.write(chunk.data(), std::streamsize(chunk.size()));
    }
  }
  MappedRegions regions(mapping_.data(), mapping_.size(), 4, path_);
  const std::size_t before = rss_file_bytes();
  // One read a region, in every region: none is mapped.
  for (std::size_t r = 0; r < kRegions; ++r) {
    const std::size_t offset = r * MappedRegions::kRegionBytes + 4096 * (r % 7) + 5;
    char got[8];
    regions.read(mapping_.data() + offset, got, sizeof got);
    for (std::size_t i = 0; i < sizeof got; ++i)
      EXPECT_EQ(got[i], char((r * 7 + (offset % MappedRegions::kRegionBytes) + i) & 0x7F));
  }
  EXPECT_EQ(regions.held(), 0u);
  EXPECT_EQ(regions.releases(), 0u);
  EXPECT_LE(rss_file_bytes(), before + MappedRegions::kRegionBytes / 2);
  // A sweep through one region maps it after kAdmitReads reads.
  for (std::uint32_t k = 0; k < MappedRegions::kAdmitReads; ++k) {
    char got;
    regions.read(mapping_.data() + 3 * MappedRegions::kRegionBytes + 64 * k, &got, 1);
    EXPECT_EQ(got, char((3 * 7 + 64 * k) & 0x7F));
  }
  EXPECT_EQ(regions.held(), 1u);
}

TEST(MappedRegions, AMissingFileIsAnError) {
  char byte = 0;
  EXPECT_THROW(MappedRegions(&byte, 1, 1, "/nonexistent/tetstream-sorted.points"), IoError);
}

}  // namespace
}  // namespace tetstream::pipeline
