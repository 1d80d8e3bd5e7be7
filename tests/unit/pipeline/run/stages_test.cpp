// Each stage of `run` alone (pipeline/stage.hpp), on a tiny job built in code: the
// sort's file is sorted and complete and its record lets a resumed sort skip the work,
// the index stage's hull is the in-core kernel's, the triangulation's tets are the
// in-core kernel's, and the write stage's container holds the tets it was handed.
#include "core/delaunay.hpp"
#include "io/output_file.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/run/stage.hpp"
#include "pipeline/run/stage_index.hpp"
#include "pipeline/run/stage_sort.hpp"
#include "pipeline/run/stage_triangulate.hpp"
#include "pipeline/run/stage_write.hpp"
#include "scratch_dir.hpp"
#include "tet_sets.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace tetstream::pipeline {
namespace {

using testing_util::Quad;
constexpr std::uint64_t kPoints = 3000;
constexpr std::uint64_t kMiB = std::uint64_t(1) << 20;

// The tets of the in-core kernel over points in label order, as a kernel's output
// array (4 labels a tet, positively oriented).
std::vector<std::array<std::uint64_t, 4>> incore_tets(const SortedView& view) {
  std::vector<double> xyz;
  for (std::uint64_t i = 0; i < view.count; ++i) {
    double p[3];
    view.points.xyz(i, p);
    xyz.insert(xyz.end(), p, p + 3);
  }
  core::Delaunay dt;
  std::vector<std::array<std::uint64_t, 4>> out;
  EXPECT_EQ(dt.build(xyz.data(), nullptr, std::size_t(view.count)), core::BuildStatus::kOk);
  dt.for_each_finite_tet([&](const core::VertexId* v) { out.push_back({v[0], v[1], v[2], v[3]}); });
  return out;
}

std::vector<Quad> sorted_quads(const std::vector<std::array<std::uint64_t, 4>>& tets) {
  std::vector<Quad> out;
  for (const auto& t : tets) testing_util::add_quad(out, t[0], t[1], t[2], t[3]);
  std::sort(out.begin(), out.end());
  return out;
}

// The labels on the boundary of the convex hull, from the in-core kernel: the finite
// vertices of its infinite tets.
std::set<std::uint64_t> incore_hull_labels(const SortedView& view) {
  std::vector<double> xyz;
  for (std::uint64_t i = 0; i < view.count; ++i) {
    double p[3];
    view.points.xyz(i, p);
    xyz.insert(xyz.end(), p, p + 3);
  }
  core::Delaunay dt;
  EXPECT_EQ(dt.build(xyz.data(), nullptr, std::size_t(view.count)), core::BuildStatus::kOk);
  std::set<std::uint64_t> hull;
  for (core::TetId t = 0; t < dt.num_tet_slots(); ++t) {
    if (!dt.is_alive(t) || !dt.is_infinite(t)) continue;
    for (int i = 0; i < 4; ++i)
      if (dt.vertex(t, i) != core::kInfiniteVertex) hull.insert(dt.vertex(t, i));
  }
  return hull;
}

// Collects the triangulation's segments in place of the write stage.
class CollectSegments final : public SegmentSink {
 public:
  void add_segment(const std::vector<ZoneTets>& parts, const SegmentStats& work, std::uint64_t points,
                   std::uint64_t next_label) override {
    std::uint64_t last_min = 0;
    merge_by_min_label(parts, [&](const ZoneTets& part, std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) {
        EXPECT_GE(part.min_label(i), last_min) << "the merged stream is not ordered by minimum label";
        last_min = part.min_label(i);
        testing_util::add_quad(quads, part.label(i, 0), part.label(i, 1), part.label(i, 2), part.label(i, 3));
      }
    });
    EXPECT_EQ(next_label, labels_done + points) << "segments out of order";
    labels_done = next_label;
    tets += work.tets;
    ++segments;
  }
  std::vector<Quad> quads;
  std::uint64_t labels_done = 0, tets = 0, segments = 0;
};

class StagesTest : public testing_util::ScratchDirTest {
 protected:
  StagesTest() : ScratchDirTest("stages-test") {}
  void expect_write_stage_writes_what_it_is_handed();
  void SetUp() override {
    ScratchDirTest::SetUp();
    xyz_ = testing_util::generated_points(io::Distribution::kBall, kPoints, 21);
    options_.input = path("points.f64");
    testing_util::write_points_file(options_.input, xyz_);
    options_.output = path("out.tets");
    options_.memory_bytes = 64 * kMiB;
    options_.sort_run_points = 700;  // several runs, merged
    options_.segment_points = 1000;  // several segments
    options_.zones = 2;              // of two zones each (a zone takes at least 256 points)
    options_.progress = false;
  }
  StageContext context(Checkpoint* checkpoint = nullptr) {
    return StageContext{options_, checkpoint ? checkpoint->dir() : dir_.string(), checkpoint, state_};
  }
  // Stage 1 run alone, as the job runs it.
  // With `claim`, the merge writes the points into the output's points section.
  SortedPoints sort(Checkpoint* checkpoint = nullptr, const io::OutputClaim* claim = nullptr) {
    MemoryBudget budget(options_.memory_bytes, 0, 1, 1);
    SortStage stage(context(checkpoint), budget, 1, claim);
    stage.prepare();
    SortedPoints sorted = stage.run();
    stage.commit();
    return sorted;
  }

  std::vector<double> xyz_;
  RunOptions options_;
  nlohmann::json state_ = nlohmann::json::object();
};

TEST_F(StagesTest, SortStageWritesEveryPointInOrder) {
  const SortedPoints sorted = sort();
  EXPECT_EQ(sorted.count, kPoints);
  EXPECT_EQ(sorted.input_count, kPoints);
  EXPECT_GE(sorted.runs, 4u);
  // float64 input below 2^32 points: the container's 28-byte record (format.md 3.4).
  using Record = PointRecord<double, std::uint32_t>;
  ASSERT_EQ(sorted.layout, (RecordLayout{false, false}));
  ASSERT_EQ(std::filesystem::file_size(sorted.path), kPoints * sizeof(Record));
  std::vector<Record> records(kPoints);
  std::ifstream(sorted.path, std::ios::binary)
      .read(reinterpret_cast<char*>(records.data()), std::streamsize(kPoints * sizeof(Record)));
  std::vector<bool> seen(kPoints, false);
  for (std::size_t i = 0; i < records.size(); ++i) {
    if (i > 0) {
      EXPECT_TRUE(record_before(records[i - 1], records[i], sorted.axis)) << "label " << i;
    }
    const std::uint64_t o = records[i].original();
    ASSERT_LT(o, kPoints);
    EXPECT_FALSE(seen[o]) << "input point " << o << " twice";
    seen[o] = true;
    for (int k = 0; k < 3; ++k) EXPECT_EQ(records[i].coord(k), xyz_[3 * o + std::size_t(k)]);
  }
  EXPECT_TRUE(std::is_sorted(sorted.hull_labels.begin(), sorted.hull_labels.end()));
  EXPECT_TRUE(state_.empty()) << "a job without a checkpoint records nothing";
}

// The sort's record: commit replaces "sort" by "sorted", and a resumed job's prepare
// finds the sort done (it does not read the input again).
TEST_F(StagesTest, SortStageCommitsItsRecordAndResumesFromIt) {
  Checkpoint checkpoint(path("job.ckpt"));
  checkpoint.create_and_lock();
  const SortedPoints first = sort(&checkpoint);
  EXPECT_TRUE(state_.contains("sorted"));
  EXPECT_FALSE(state_.contains("sort"));
  std::filesystem::remove(options_.input);  // a second sort would fail
  const SortedPoints again = sort(&checkpoint);
  EXPECT_EQ(again.crc32c, first.crc32c);
  EXPECT_EQ(again.count, first.count);
  EXPECT_EQ(again.hull_labels, first.hull_labels);
}

TEST_F(StagesTest, IndexStageFindsTheInCoreHull) {
  const SortedPoints sorted = sort();
  IndexStage stage(sorted, 1);
  stage.prepare();
  stage.run();
  const SortedView& view = stage.view();
  ASSERT_EQ(view.count, kPoints);
  ASSERT_NE(view.index, nullptr);
  ASSERT_NE(view.hull_index, nullptr);
  std::set<std::uint64_t> hull;
  for (const SortedPoint& p : view.hull_points) {
    hull.insert(p.original);  // the label, for the hull's points
    for (int k = 0; k < 3; ++k) EXPECT_EQ(p.xyz[k], view.points.coord(p.original, k));
  }
  EXPECT_EQ(hull.size(), view.hull_points.size()) << "a hull point twice";
  EXPECT_EQ(hull, incore_hull_labels(view));
}

TEST_F(StagesTest, TriangulateStageEqualsTheInCoreKernel) {
  const SortedPoints sorted = sort();
  IndexStage index(sorted, 2);
  index.prepare();
  index.run();
  MemoryBudget budget(options_.memory_bytes, kPoints, 2, 2);
  const TriangulatePlan plan = plan_triangulation(index, options_, budget, 2);
  EXPECT_LE(budget.phase_total("triangulate"), options_.memory_bytes);
  CollectSegments out;
  {
    TriangulateStage stage(options_, index, plan.zones, plan.shares.query_page_bytes, plan.shares.shared_rim_bytes, 2);
    stage.prepare(0, 0);
    EXPECT_GE(stage.segments(), 3u);
    EXPECT_GT(stage.zones(), stage.segments()) << "no segment was cut into zones";
    stage.run(out);
    EXPECT_EQ(out.segments, stage.segments());
  }
  EXPECT_EQ(index.view().query_regions, nullptr) << "the stage's tracker outlived it";
  EXPECT_EQ(out.labels_done, kPoints);
  std::sort(out.quads.begin(), out.quads.end());
  EXPECT_EQ(out.quads.size(), out.tets);
  EXPECT_EQ(out.quads, sorted_quads(incore_tets(index.view())));
}

// The write stage fed the in-core kernel's tets as two segments (grouped by minimum
// label, as zones emit them): the container holds the points and exactly those tets.
// Its points come from the sorted file, or (a claimed output) the sort merged them
// into the output's points section itself: the same bytes either way.
TEST_F(StagesTest, WriteStageWritesTheTetsItIsHanded) {
  for (const bool bricks : {false, true}) {
    SCOPED_TRACE(bricks ? "version 2 (bricks)" : "version 1 (sorted)");
    options_.brick_labels = bricks;
    expect_write_stage_writes_what_it_is_handed();
  }
}

void StagesTest::expect_write_stage_writes_what_it_is_handed() {
  std::string bytes[2];
  for (const bool in_output : {false, true}) {
    SCOPED_TRACE(in_output ? "points merged into the output" : "points from the sorted file");
    std::optional<io::OutputClaim> claim;
    if (in_output) claim.emplace(options_.output);
    const SortedPoints sorted = sort(nullptr, claim ? &*claim : nullptr);
    EXPECT_EQ(sorted.offset != 0, in_output);
    if (in_output) {
      EXPECT_EQ(sorted.path, options_.output + ".partial");
    }
    IndexStage index(sorted, 1);
    index.prepare();
    index.run();
    std::vector<std::array<std::uint64_t, 4>> tets = incore_tets(index.view());
    // Read now: with the points in the output, the view maps the points section that
    // version 2's commit rewrites in place.
    std::map<std::array<double, 3>, std::uint64_t> sorted_label;
    for (std::uint64_t i = 0; i < kPoints; ++i) {
      std::array<double, 3> p;
      index.view().points.xyz(i, p.data());
      sorted_label[p] = i;
    }
    auto min_label = [](const std::array<std::uint64_t, 4>& t) { return *std::min_element(t.begin(), t.end()); };
    std::stable_sort(tets.begin(), tets.end(),
                     [&](const auto& a, const auto& b) { return min_label(a) < min_label(b); });
    const std::uint64_t split = kPoints / 2;
    ZoneTets parts[2];
    for (ZoneTets& part : parts)
      for (std::uint64_t i = 0; i < kPoints; ++i) part.labels.push_back(i);  // local id = label
    for (const auto& t : tets)
      for (std::uint64_t v : t) parts[min_label(t) < split ? 0 : 1].tets.push_back(std::uint32_t(v));
    {
      TriangulateShares shares;
      shares.encoders = 1;
      shares.file_buffer_bytes = std::size_t(1) << 16;
      WriteStage stage(context(), sorted, index.view(), shares, claim ? &*claim : nullptr);
      stage.prepare();
      EXPECT_EQ(stage.first_label(), 0u);
      stage.run();
      SegmentStats work;
      work.tets = parts[0].size();
      stage.add_segment({parts[0]}, work, split, split);
      work.tets = parts[1].size();
      stage.add_segment({parts[1]}, work, kPoints - split, kPoints);
      stage.commit();
      stage.finish();
      EXPECT_EQ(stage.segments_done(), 2u);
      EXPECT_EQ(stage.work().stats.tets, tets.size());
      EXPECT_EQ(stage.bytes_written(), std::filesystem::file_size(options_.output));
    }
    const io::TetReader reader(options_.output);
    EXPECT_EQ(reader.point_count(), kPoints);
    EXPECT_EQ(reader.version_major(), options_.brick_labels ? io::kVersionMajorBricks : io::kVersionMajor);
    // The container's labels as sorted ones, through the points' coordinates (version
    // 2 permutes each brick's labels: the same set of points, another order).
    std::vector<double> xyz(3 * kPoints);
    reader.read_points(0, kPoints, xyz.data(), nullptr);
    std::vector<std::uint64_t> as_sorted(kPoints);
    std::uint64_t moved = 0;
    for (std::uint64_t l = 0; l < kPoints; ++l) {
      const auto it = sorted_label.find({xyz[3 * l], xyz[3 * l + 1], xyz[3 * l + 2]});
      ASSERT_NE(it, sorted_label.end()) << "label " << l << ": a point the job did not have";
      as_sorted[l] = it->second;
      moved += it->second != l;
    }
    EXPECT_EQ(moved > 0, options_.brick_labels) << moved << " labels moved";
    std::vector<Quad> written;
    for (const Quad& q : testing_util::container_quads(options_.output))
      testing_util::add_quad(written, as_sorted[q[0]], as_sorted[q[1]], as_sorted[q[2]], as_sorted[q[3]]);
    std::sort(written.begin(), written.end());
    EXPECT_EQ(written, sorted_quads(tets));
    std::ifstream in(options_.output, std::ios::binary);
    bytes[in_output] = std::string(std::istreambuf_iterator<char>(in), {});
    std::filesystem::remove(options_.output);
  }
  EXPECT_TRUE(bytes[0] == bytes[1]) << "the points merged into the output gave other bytes";
}

}  // namespace
}  // namespace tetstream::pipeline
