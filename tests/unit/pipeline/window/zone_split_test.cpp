// split_into_zones: strips of about equal size whose cuts avoid dense places.
#include "pipeline/window/zone_plan.hpp"
#include "pipeline/window/zone_triangulator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

namespace tetstream::pipeline {
namespace {

// Points sorted along x (the sort axis) in [0, 4] x [0, 1] x [0, 0.1] (y is the strip
// axis): uniform, with every `every`-th point in a cluster of width `width` around
// y = 0.5, the median. Buffers of width 0.01.
struct ClusteredSegment {
  std::vector<SortedPoint> points;
  SortedView view;
  SegmentPlan plan;

  ClusteredSegment(std::uint64_t n, std::uint64_t every, double width) {
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> unit(0, 1);
    for (std::uint64_t i = 0; i < n; ++i) {
      const double y = i % every == 0 ? 0.5 + width * (unit(rng) - 0.5) : unit(rng);
      points.push_back(SortedPoint{{4 * unit(rng), y, 0.1 * unit(rng)}, i});
    }
    std::sort(points.begin(), points.end(),
              [](const SortedPoint& a, const SortedPoint& b) { return a.xyz[0] < b.xyz[0]; });
    view.points = records_of(points.data());
    view.count = n;
    view.axis = 0;
    for (int k = 0; k < 3; ++k) view.bbox_min[k] = 0;
    view.bbox_max[0] = 4, view.bbox_max[1] = 1, view.bbox_max[2] = 0.1;
    plan.label_begin = plan.window_begin = 0;
    plan.label_end = plan.window_end = n;
    plan.buffer_width = 0.01;
  }

  // Points of the segment in a strip's own range.
  std::uint64_t own(const Zone& st) const {
    return std::uint64_t(std::count_if(points.begin(), points.end(),
                                       [&](const SortedPoint& p) { return p.xyz[1] >= st.lo && p.xyz[1] < st.hi; }));
  }
};

TEST(ZoneSplit, CutsAvoidAClusterAndStayBalanced) {
  // 5% of the points in a cluster 0.004 wide (less than the two buffers): a cut
  // through it puts all of it in both windows.
  ClusteredSegment s(200000, 20, 0.004);
  ASSERT_EQ(strip_axis(s.view), 1);
  split_into_zones(s.view, s.plan, 2);
  ASSERT_EQ(s.plan.zones.size(), 2u);
  // The median lies in the cluster; the cut moves beside it, within a tenth of a
  // zone's share (and the sample's error) of an equal split.
  for (const Zone& st : s.plan.zones) EXPECT_NEAR(double(s.own(st)), 100000.0, 12000.0);
  const double cut = s.plan.zones[0].hi;
  EXPECT_TRUE(cut < 0.498 - s.plan.buffer_width || cut > 0.502 + s.plan.buffer_width) << "cut at " << cut;
}

// A segment's zones start every other strip first, then the strips between them: each
// zone once, and (from three strips) no two neighbouring strips one after the other
// among the first half, which run side by side on two threads.
TEST(ZoneStartOrder, EveryOtherStripFirstThenTheOnesBetween) {
  EXPECT_EQ(zone_start_order(5), (std::vector<std::size_t>{0, 2, 4, 1, 3}));
  EXPECT_EQ(zone_start_order(1), (std::vector<std::size_t>{0}));
  EXPECT_TRUE(zone_start_order(0).empty());
  for (std::size_t zones = 1; zones <= 12; ++zones) {
    std::vector<std::size_t> order = zone_start_order(zones);
    const std::size_t first_half = (zones + 1) / 2;
    for (std::size_t i = 1; i < first_half; ++i) EXPECT_EQ(order[i] - order[i - 1], 2u) << zones;
    std::sort(order.begin(), order.end());
    for (std::size_t z = 0; z < zones; ++z) ASSERT_EQ(order[z], z) << zones;
  }
}

}  // namespace
}  // namespace tetstream::pipeline
