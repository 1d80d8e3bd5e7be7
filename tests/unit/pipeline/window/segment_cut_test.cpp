// cut_segments: the segments a plan becomes once their windows are measured. A cut
// whose windows fit the share with room to spare takes one segment fewer while the
// measured windows still fit (a plan's segment count is a ceiling, and the shrinking
// of a cut over the share takes a fifth at least); a fixed plan is kept as it is.
#include "pipeline/window/zone_plan.hpp"
#include "pipeline/window/point_index.hpp"
#include "pipeline/window/zone_triangulator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

namespace tetstream::pipeline {
namespace {

// n points uniform in [0, 4] x [0, 1] x [0, 1], sorted along x.
struct SortedUniform {
  std::vector<SortedPoint> points;
  SortedView view;

  explicit SortedUniform(std::uint64_t n) {
    std::mt19937_64 rng(23);
    std::uniform_real_distribution<double> unit(0, 1);
    for (std::uint64_t i = 0; i < n; ++i) points.push_back(SortedPoint{{4 * unit(rng), unit(rng), unit(rng)}, i});
    std::sort(points.begin(), points.end(),
              [](const SortedPoint& a, const SortedPoint& b) { return a.xyz[0] < b.xyz[0]; });
    view.points = records_of(points.data());
    view.count = n;
    view.axis = 0;
    for (int k = 0; k < 3; ++k) view.bbox_min[k] = 0, view.bbox_max[k] = k == 0 ? 4 : 1;
    view.sample_keys();
  }

  // The cut of segments of `segment_points`, measured and kept as it is.
  SegmentCut fixed_cut(std::uint64_t segment_points) const {
    ZonePlan plan;
    plan.segment_points = segment_points;
    plan.buffer_width = 0.01;
    plan.fixed = true;
    return cut_segments(view, plan, 0, 1);
  }
};

TEST(SegmentCut, AFittingCutTakesFewerSegmentsWhileTheyFit) {
  SortedUniform u(100000);
  const SegmentCut ten = u.fixed_cut(10000), eight = u.fixed_cut(12500), seven = u.fixed_cut(14286);
  ASSERT_EQ(ten.plans.size(), 10u);
  ASSERT_EQ(eight.plans.size(), 8u);
  ASSERT_EQ(seven.plans.size(), 7u);
  ASSERT_LT(ten.window_bytes, eight.window_bytes);
  ASSERT_LT(eight.window_bytes, seven.window_bytes);

  // A share that holds 8 segments' windows but not 7: a plan of 10 grows to 8.
  ZonePlan plan;
  plan.segment_points = 10000;
  plan.buffer_width = 0.01;
  plan.available = (eight.window_bytes + seven.window_bytes) / 2;
  const SegmentCut grown = cut_segments(u.view, plan, 0, 1);
  EXPECT_EQ(grown.plans.size(), 8u);
  EXPECT_LE(grown.window_bytes, plan.available);
  EXPECT_EQ(grown.plans.front().label_begin, 0u);
  EXPECT_EQ(grown.plans.back().label_end, 100000u);

  // A share that holds 10 segments' windows and not 9: kept at 10.
  plan.available = ten.window_bytes * 1.01;
  EXPECT_EQ(cut_segments(u.view, plan, 0, 1).plans.size(), 10u);

  // A fixed plan (--zone-points, --zones) is never grown.
  plan.available = seven.window_bytes * 2;
  plan.fixed = true;
  EXPECT_EQ(cut_segments(u.view, plan, 0, 1).plans.size(), 10u);

  // A rank's part of the labels grows within its part: [50000, 100000) in 5 segments
  // of 10000 becomes 4 of 12500 under the share that holds 8 of the whole.
  plan.fixed = false;
  plan.available = (eight.window_bytes + seven.window_bytes) / 2;
  const SegmentCut part = cut_segments(u.view, plan, 50000, 1);
  EXPECT_EQ(part.plans.size(), 4u);
  EXPECT_EQ(part.plans.front().label_begin, 50000u);
  EXPECT_EQ(part.plans.back().label_end, 100000u);
}

// A cut a little over the share with the plan's buffers takes one segment more with
// them rather than each segment's local buffers (thinner, and their queries cost more
// than a segment's buffers: uniform points at --memory 128M, 175,017 queries in 10
// segments against 201,763 in 9 with local buffers, the same tets).
TEST(SegmentCut, ALittleOverTheShareTakesASegmentMoreBeforeLocalBuffers) {
  SortedUniform u(100000);
  PointIndex index;
  index.build(u.view.points, u.view.count, 0, PointIndex::kMinBlockPoints);
  u.view.index = &index;
  ZonePlan plan;
  plan.segment_points = 12500;
  plan.buffer_width = 0.15;  // thicker than 1.5 of the points' spacings (~0.05): local buffers are thinner
  plan.buffer_spacings = 1.5;
  plan.fixed = true;
  const SegmentCut eight = cut_segments(u.view, plan, 0, 1);
  ASSERT_EQ(eight.plans.size(), 8u);
  plan.fixed = false;
  plan.available = eight.window_bytes * 0.995;
  const SegmentCut cut = cut_segments(u.view, plan, 0, 1);
  EXPECT_EQ(cut.plans.size(), 9u);
  EXPECT_LE(cut.window_bytes, plan.available);
  for (const SegmentPlan& p : cut.plans) EXPECT_EQ(p.buffer_width, plan.buffer_width);

  // Far over the share: the segments shrink until they fit, as before.
  plan.available = eight.window_bytes * 0.7;
  const SegmentCut smaller = cut_segments(u.view, plan, 0, 1);
  EXPECT_LE(smaller.window_bytes, plan.available);
  EXPECT_GT(smaller.plans.size(), 9u);
}

}  // namespace
}  // namespace tetstream::pipeline
