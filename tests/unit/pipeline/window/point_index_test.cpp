// The emptiness queries' building blocks: the spatial index must report every point
// of a ball (within the label range, outside the excluded slab it may skip), and the
// sampled key search must agree with a plain binary search over the sorted file.
#include "pipeline/window/point_index.hpp"
#include "pipeline/distributed/rank_cost.hpp"
#include "pipeline/window/zone_triangulator.hpp"

#include "scratch_dir.hpp"

#include <gtest/gtest.h>

#include <boost/iostreams/device/mapped_file.hpp>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace tetstream::pipeline {
namespace {

// n points sorted along `axis` as the sorted file is; coordinates on a coarse grid
// when `coarse` (many equal keys, points on node boxes' faces).
std::vector<SortedPoint> sorted_points(std::size_t n, int axis, bool coarse, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<SortedPoint> p(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (double& c : p[i].xyz) c = coarse ? std::round(u(rng) * 8) / 8 : u(rng);
    p[i].xyz[(axis + 1) % 3] *= 3;  // not a cube: the widest side varies by node
    p[i].original = i;
  }
  std::sort(p.begin(), p.end(),
            [axis](const SortedPoint& a, const SortedPoint& b) { return sorted_before(a, b, axis); });
  return p;
}

// Also far from the origin (a LiDAR-like offset, where the points' cells in their
// leaves are narrow beside the coordinates' magnitude), and with balls through a
// point (on the sphere, up to rounding).
TEST(PointIndex, CandidatesCoverEveryPointOfTheBall) {
  for (const double offset : {0.0, 1e6}) {
    for (const bool coarse : {false, true}) {
      for (const std::uint32_t block : {PointIndex::kMinBlockPoints, 1000u, 20000u}) {
        const int axis = 2;
        std::vector<SortedPoint> p = sorted_points(20000, axis, coarse, 7 + block);
        for (SortedPoint& q : p)
          for (double& x : q.xyz) x += offset;
        PointIndex index;
        index.build(records_of(p.data()), p.size(), axis, block);
        std::mt19937_64 rng(block);
        std::uniform_real_distribution<double> u(-1.2, 1.2);
        std::uniform_int_distribution<std::uint64_t> label(0, p.size());
        for (int q = 0; q < 300; ++q) {
          const double c[3] = {offset + u(rng), offset + 3 * u(rng), offset + u(rng)};
          double r = q % 10 == 0 ? 2.0 : 0.02 + 0.2 * std::abs(u(rng));
          if (q % 4 == 1) {  // through a point
            const double* x = p[std::size_t(label(rng)) % p.size()].xyz;
            r = std::sqrt((x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) +
                          (x[2] - c[2]) * (x[2] - c[2]));
          }
          std::uint64_t first = label(rng), last = label(rng);
          if (first > last) std::swap(first, last);
          ExcludedSlab exclude;
          if (q % 3 == 0) exclude = ExcludedSlab{0, offset + u(rng) - 0.3, offset + u(rng) + 0.3};
          std::set<std::uint64_t> seen;
          index.for_each_candidate(
              c, r, first, last,
              [&](std::uint64_t l) {
                EXPECT_GE(l, first);
                EXPECT_LT(l, last);
                EXPECT_TRUE(seen.insert(l).second) << "label " << l << " reported twice";
              },
              [] { return false; }, exclude);
          for (std::uint64_t l = first; l < last; ++l) {
            const double* x = p[l].xyz;
            const double d2 =
                (x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) + (x[2] - c[2]) * (x[2] - c[2]);
            const bool excluded = exclude.contains(x, x);
            if (d2 <= r * r && !excluded) {
              ASSERT_TRUE(seen.count(l)) << "point " << l << " in the ball was not reported (query " << q << ", block "
                                         << block << (coarse ? ", coarse" : "") << ", offset " << offset << ")";
            }
          }
        }
      }
    }
  }
}

// A ball's leaf cells are tested from per-axis tables (PointIndex::CoarseTable): the
// same candidates, in the same order, as the generic region test of the same ball,
// with and without an excluded slab, near the origin and far from it.
TEST(PointIndex, ABallsTablesAnswerAsTheGenericRegionTest) {
  for (const double offset : {0.0, 1e6}) {
    for (const bool coarse : {false, true}) {
      const int axis = 0;
      std::vector<SortedPoint> p = sorted_points(20000, axis, coarse, 11);
      for (SortedPoint& q : p)
        for (double& x : q.xyz) x += offset;
      PointIndex index;
      index.build(records_of(p.data()), p.size(), axis, 1000u);
      std::mt19937_64 rng(3);
      std::uniform_real_distribution<double> u(-1.2, 1.2);
      std::uniform_int_distribution<std::uint64_t> label(0, p.size());
      for (int q = 0; q < 300; ++q) {
        const double c[3] = {offset + u(rng), offset + 3 * u(rng), offset + u(rng)};
        const double r = q % 10 == 0 ? 2.0 : 0.02 + 0.3 * std::abs(u(rng));
        std::uint64_t first = label(rng), last = label(rng);
        if (first > last) std::swap(first, last);
        ExcludedSlab exclude;
        if (q % 2 == 0) exclude = ExcludedSlab{1 + q % 4 / 2, offset + u(rng) - 0.3, offset + u(rng) + 0.3};
        std::vector<std::uint64_t> tables, generic;
        index.for_each_candidate_where(
            BallRegion{c, r}, first, last, [&](std::uint64_t l) { tables.push_back(l); }, [] { return false; },
            exclude);
        index.for_each_candidate_where([&](const double* lo, const double* hi) { return box_meets_ball(lo, hi, c, r); },
                                       first, last, [&](std::uint64_t l) { generic.push_back(l); },
                                       [] { return false; }, exclude);
        ASSERT_EQ(tables, generic) << "query " << q << (coarse ? ", coarse" : "") << ", offset " << offset;
      }
    }
  }
}

// The index built in parts (the ranks of a job, each its blocks), written into one file
// and mapped, answers every query as the index built whole: the same labels in the same
// order, whatever the parts (one block, uneven parts, an empty part).
// Random balls (every tenth a huge one) over random label ranges: `other` reports the
// same candidates as `whole`, in the same order; after each query, check() holds.
template <class Check>
void expect_same_candidates(const PointIndex& whole, const PointIndex& other, std::uint64_t count, unsigned seed,
                            int queries, const std::string& what, Check&& check) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  std::uniform_int_distribution<std::uint64_t> label(0, count);
  for (int q = 0; q < queries; ++q) {
    const double c[3] = {u(rng), 3 * u(rng), u(rng)};
    const double r = q % 10 == 0 ? 2.0 : 0.05 + 0.3 * std::abs(u(rng));
    std::uint64_t first = label(rng), last = label(rng);
    if (first > last) std::swap(first, last);
    std::vector<std::uint64_t> a, b;
    whole.for_each_candidate(
        c, r, first, last, [&](std::uint64_t l) { a.push_back(l); }, [] { return false; });
    other.for_each_candidate(
        c, r, first, last, [&](std::uint64_t l) { b.push_back(l); }, [] { return false; });
    ASSERT_EQ(a, b) << "query " << q << ", " << what;
    check();
  }
}

class SharedIndex : public testing_util::ScratchDirTest {
 protected:
  SharedIndex() : ScratchDirTest("shared-index") {}
};

TEST_F(SharedIndex, PartsInOneFileAnswerAsTheWholeIndex) {
  const int axis = 0;
  const std::vector<SortedPoint> p = sorted_points(30000, axis, false, 11);
  const std::uint32_t block = 2500;  // 12 blocks
  PointIndex whole;
  whole.build(records_of(p.data()), p.size(), axis, block);
  const std::uint64_t blocks = PointIndex::blocks_for(p.size(), block);
  ASSERT_EQ(blocks, 12u);
  for (const std::vector<std::uint64_t>& cuts :
       std::vector<std::vector<std::uint64_t>>{{0, 12}, {0, 5, 12}, {0, 1, 7, 7, 12}, {0, 4, 8, 11, 12}}) {
    std::vector<PointIndex> parts(cuts.size() - 1);
    std::vector<std::uint64_t> first_node(parts.size() + 1, 0);
    for (std::size_t r = 0; r < parts.size(); ++r) {
      parts[r].build_part(records_of(p.data()), p.size(), axis, block, cuts[r], cuts[r + 1]);
      first_node[r + 1] = first_node[r] + parts[r].part_nodes();
    }
    const std::string file = path("index");
    const PointIndex::FileLayout layout = PointIndex::file_layout(p.size(), first_node.back(), blocks);
    const int fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_TRUNC, 0644);
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::ftruncate(fd, off_t(layout.bytes)), 0);
    for (std::size_t r = parts.size(); r-- > 0;)  // in any order
      parts[r].write_part(fd, file, first_node.back(), first_node[r]);
    ::close(fd);
    boost::iostreams::mapped_file_source mapping(file);
    PointIndex shared;
    shared.attach(reinterpret_cast<const std::byte*>(mapping.data()), records_of(p.data()), p.size(), axis, block,
                  first_node.back(), 1234);
    EXPECT_EQ(shared.memory_bytes(), 1234u);
    expect_same_candidates(whole, shared, p.size(), unsigned(cuts.size()), 200, std::to_string(parts.size()) + " parts",
                           [] {});
    EXPECT_EQ(whole.leaf_spacing_quantile(0.5), shared.leaf_spacing_quantile(0.5));
    EXPECT_EQ(PointIndex::node_count_for(p.size(), block), first_node.back());
  }
}

// The node count a file is laid out for before any block is built (the single-process
// index on disk) is the count the build makes: full blocks, a short last block, blocks
// of a leaf or less, one point.
TEST(PointIndex, NodeCountIsKnownBeforeTheBuild) {
  const std::vector<SortedPoint> p = sorted_points(20011, 1, true, 5);
  for (std::uint64_t n : {std::uint64_t(1), std::uint64_t(48), std::uint64_t(49), std::uint64_t(97),
                          std::uint64_t(5000), std::uint64_t(20011)}) {
    for (std::uint32_t block : {8192u, 1000u, 48u, 7u}) {
      PointIndex index;
      index.build_part(records_of(p.data()), n, 1, block, 0, PointIndex::blocks_for(n, block));
      EXPECT_EQ(PointIndex::node_count_for(n, block), index.part_nodes()) << n << " points, blocks of " << block;
    }
  }
}

// An attached index whose pages are tracked by region (IndexStage::run_on_disk) answers
// as the index in memory, with no more regions held than its share, also a share of one
// region that every block's reads evict again.
TEST_F(SharedIndex, TrackedRegionsAnswerAsTheIndexInMemory) {
  const int axis = 2;
  const std::vector<SortedPoint> p = sorted_points(700000, axis, false, 17);  // a file of 3 regions
  const std::uint32_t block = 8192;
  PointIndex whole;
  whole.build(records_of(p.data()), p.size(), axis, block);
  const std::uint64_t blocks = PointIndex::blocks_for(p.size(), block);
  const std::uint64_t nodes = PointIndex::node_count_for(p.size(), block);
  PointIndex part;
  part.build_part(records_of(p.data()), p.size(), axis, block, 0, blocks);
  const std::string file = path("index");
  const PointIndex::FileLayout layout = PointIndex::file_layout(p.size(), nodes, blocks);
  const int fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_TRUNC, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::ftruncate(fd, off_t(layout.bytes)), 0);
  part.write_part(fd, file, nodes, 0);
  ::close(fd);
  boost::iostreams::mapped_file_source mapping(file);
  ASSERT_GT(mapping.size(), 2 * MappedRegions::kRegionBytes);  // several regions to juggle
  for (std::size_t share : {std::size_t(1), std::size_t(2), std::size_t(64)}) {
    MappedRegions regions(mapping.data(), mapping.size(), share);
    PointIndex tracked;
    tracked.attach(reinterpret_cast<const std::byte*>(mapping.data()), records_of(p.data()), p.size(), axis, block,
                   nodes, share * MappedRegions::kRegionBytes);
    tracked.track_regions(&regions);
    expect_same_candidates(whole, tracked, p.size(), unsigned(share), 300,
                           "a share of " + std::to_string(share) + " regions",
                           [&] { ASSERT_LE(regions.held(), share); });
    EXPECT_EQ(whole.leaf_spacing_quantile(0.9), tracked.leaf_spacing_quantile(0.9));
    EXPECT_LE(regions.held(), share);
    if (share < 4) {
      EXPECT_GT(regions.releases(), 0u) << "the share never made room";
    }
  }
}

// The expected cost: a point of a (slightly jittered) plane costs several times a
// point of a solid cube, whose pilot tets have balls of their neighbours' size; the
// units' sums add up to the range's whole, whatever the unit.
TEST(RankCost, FlatTetsMakeAPointDearer) {
  const std::size_t n = 40000;
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<SortedPoint> p(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = u(rng), y = u(rng), z = u(rng);
    p[i].xyz[0] = x, p[i].xyz[1] = y, p[i].xyz[2] = x < 0 ? 0.25 + 1e-4 * z : z;  // a plane, then a cube
    p[i].original = i;
  }
  std::sort(p.begin(), p.end(), [](const SortedPoint& a, const SortedPoint& b) { return sorted_before(a, b, 0); });
  const std::size_t plane =
      std::size_t(std::count_if(p.begin(), p.end(), [](const SortedPoint& q) { return q.xyz[0] < 0; }));
  PointIndex index;
  const PointRecords records = records_of(p.data());
  index.build(records, p.size(), 0, 4096);
  const std::vector<double> whole = expected_cost(index, records, 0, n, n);
  ASSERT_EQ(whole.size(), 1u);
  // Whole blocks of each side (a block that straddles x = 0 is left out).
  const std::uint64_t bp = index.block_points(), flat_end = plane / bp * bp, solid_begin = (plane + bp - 1) / bp * bp;
  const double flat = expected_cost(index, records, 0, flat_end, flat_end)[0] / double(flat_end);
  const double solid = expected_cost(index, records, solid_begin, n, n - solid_begin)[0] / double(n - solid_begin);
  EXPECT_GT(flat, 1.7 * solid);  // (2.59 and 1.38 as built)
  EXPECT_LT(solid, 1.5);
  for (std::uint64_t unit : {1000u, 4096u, 7777u}) {
    const std::vector<double> parts = expected_cost(index, records, 0, n, unit);
    EXPECT_EQ(parts.size(), (n + unit - 1) / unit);
    double sum = 0;
    for (double c : parts) sum += c;
    EXPECT_NEAR(sum, whole[0], 1e-9 * whole[0]) << unit;
  }
  EXPECT_EQ(expected_cost(index, records, 100, 300, 1000).size(), 1u);
}

TEST(PointIndex, BlockPointsFollowTheSlabDensity) {
  // 10^7 points in a unit cube: a spacing is 1/215, a slab of 8 spacings 372k points,
  // capped at the largest block.
  EXPECT_EQ(PointIndex::block_points_for(10'000'000, 1.0, 1.0), PointIndex::kMaxBlockPoints);
  EXPECT_EQ(PointIndex::block_points_for(1000, 1.0, 1.0), PointIndex::kMinBlockPoints);
  // Degenerate boxes fall back to the largest block, never divide by zero.
  EXPECT_EQ(PointIndex::block_points_for(10'000'000, 0.0, 0.0), PointIndex::kMaxBlockPoints);
}

TEST(SortedView, SampledSearchMatchesBinarySearch) {
  for (const bool coarse : {false, true}) {
    for (const std::size_t n :
         {std::size_t(1), std::size_t(127), std::size_t(128), std::size_t(129), std::size_t(5000)}) {
      const std::vector<SortedPoint> p = sorted_points(n, 0, coarse, unsigned(n));
      SortedView view;
      view.points = records_of(p.data());
      view.count = p.size();
      view.axis = 0;
      std::vector<double> keys;
      for (const SortedPoint& s : p) keys.push_back(s.xyz[0]);
      std::vector<double> probes = keys;
      for (double x : {-5.0, 5.0, 0.0, 1.0 / 16, 0.5 + 1e-12}) probes.push_back(x);
      for (const bool sampled : {false, true}) {
        if (sampled) view.sample_keys();
        for (double x : probes) {
          ASSERT_EQ(view.lower_bound(x), std::uint64_t(std::lower_bound(keys.begin(), keys.end(), x) - keys.begin()))
              << "n " << n << " x " << x << (sampled ? " sampled" : "");
          ASSERT_EQ(view.upper_bound(x), std::uint64_t(std::upper_bound(keys.begin(), keys.end(), x) - keys.begin()))
              << "n " << n << " x " << x << (sampled ? " sampled" : "");
        }
      }
    }
  }
}

}  // namespace
}  // namespace tetstream::pipeline
