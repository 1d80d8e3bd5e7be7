// The out-of-core pipeline against the in-core kernel: the same tet set, whatever
// the number of segments, on every distribution, degenerate ones included.
#include "core/delaunay.hpp"
#include "io/point_generators.hpp"
#include "io/point_writer.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/run/run.hpp"
#include "scratch_dir.hpp"
#include "tet_sets.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace tetstream {
namespace {

using testing_util::Quad;

class PipelineTest : public testing_util::ScratchDirTest {
 protected:
  PipelineTest() : ScratchDirTest("pipeline-test") {}

  std::string write_points(const io::GeneratorOptions& g) {
    const io::PointGenerator gen(g);
    std::vector<double> xyz(3 * gen.count());
    gen.generate(0, gen.count(), xyz.data());
    const std::string path = (dir_ / "points.f64").string();
    auto w = io::create_points(path, {}, gen.count());
    w->write(xyz.data(), gen.count());
    w->commit();
    return path;
  }

  pipeline::RunSummary run(const std::string& input, std::uint64_t zone_points, const std::string& name = "out.tets",
                           int threads = 1, int zones = 1) {
    pipeline::RunOptions o;
    o.threads = threads;
    o.zones = zones;
    o.input = input;
    o.output = (dir_ / name).string();
    o.segment_points = zone_points;
    o.memory_bytes = std::uint64_t(256) << 20;
    o.progress = false;
    return pipeline::run_job(o);
  }

  // The container's tets as sorted quadruples, and, from its own points, the in-core
  // kernel's tets as its labels (testing_util::incore_quads).
  static std::vector<Quad> container_tets(const std::string& path) { return testing_util::container_quads(path); }
  static std::vector<Quad> incore_tets(const std::string& path) { return testing_util::incore_quads(path); }

  pipeline::RunSummary expect_same_as_incore(const io::GeneratorOptions& g, std::uint64_t zone_points,
                                             std::uint64_t min_segments, int zones = 1) {
    SCOPED_TRACE(std::string(io::to_string(g.dist)) + " n=" + std::to_string(g.n) + " seed=" + std::to_string(g.seed) +
                 " zones=" + std::to_string(zones));
    const std::string input = write_points(g);
    const auto summary = run(input, zone_points, "out.tets", zones > 1 ? 2 : 1, zones);
    EXPECT_GE(summary.segments, min_segments);
    const std::string out = (dir_ / "out.tets").string();
    const auto ours = container_tets(out);
    const auto ref = incore_tets(out);
    EXPECT_EQ(ours.size(), summary.tets);
    EXPECT_TRUE(std::adjacent_find(ours.begin(), ours.end()) == ours.end()) << "a tet written twice";
    std::vector<Quad> missing, extra;
    std::set_difference(ref.begin(), ref.end(), ours.begin(), ours.end(), std::back_inserter(missing));
    std::set_difference(ours.begin(), ours.end(), ref.begin(), ref.end(), std::back_inserter(extra));
    EXPECT_EQ(missing.size(), 0u) << "tets of the in-core triangulation missing from the output";
    EXPECT_EQ(extra.size(), 0u) << "tets in the output that the in-core triangulation lacks";
    EXPECT_LE(summary.tets_by_query, summary.tets);
    return summary;
  }
};

io::GeneratorOptions dist(io::Distribution d, std::uint64_t n, std::uint64_t seed = 1) {
  io::GeneratorOptions g;
  g.dist = d;
  g.n = n;
  g.seed = seed;
  return g;
}

TEST_F(PipelineTest, UniformManySegments) { expect_same_as_incore(dist(io::Distribution::kUniform, 20000), 1500, 10); }
TEST_F(PipelineTest, BallManySegments) { expect_same_as_incore(dist(io::Distribution::kBall, 20000, 2), 1500, 10); }
TEST_F(PipelineTest, EllipsoidShell) {
  expect_same_as_incore(dist(io::Distribution::kEllipsoidShell, 20000, 3), 1500, 10);
}
TEST_F(PipelineTest, Mixed) { expect_same_as_incore(dist(io::Distribution::kMixed, 20000, 4), 1500, 10); }
TEST_F(PipelineTest, Clusters) { expect_same_as_incore(dist(io::Distribution::kClusters, 20000, 5), 1500, 10); }
TEST_F(PipelineTest, GridIsDegenerateButExact) {
  expect_same_as_incore(dist(io::Distribution::kGrid, 20 * 20 * 20), 600, 10);
}
// Surfaces: a LiDAR-like tile (flat roofs, walls, centimetre lattice, UTM offsets) and
// two jittered plates: most tets are flat and their balls huge.
TEST_F(PipelineTest, TerrainManySegments) {
  expect_same_as_incore(dist(io::Distribution::kTerrain, 20000, 7), 1500, 10);
}
TEST_F(PipelineTest, TwoPlatesManySegments) {
  expect_same_as_incore(dist(io::Distribution::kTwoPlates, 20000, 8), 1500, 10);
}
TEST_F(PipelineTest, SphereCospherical) { expect_same_as_incore(dist(io::Distribution::kSphere, 2000, 6), 150, 10); }

// The surface zoo (io/point_zoo.hpp): roofs without walls, crowns with several returns,
// holes, overlapping strips on scan lines, steep hills, closed rooms: small sets, small
// windows (many segments; then 3 zones a segment on 2 threads), the in-core kernel's tets.
const io::Distribution kZoo[] = {io::Distribution::kHills,  io::Distribution::kRoofs,  io::Distribution::kCanopy,
                                 io::Distribution::kWater,  io::Distribution::kStrips, io::Distribution::kScanLines,
                                 io::Distribution::kSurvey, io::Distribution::kIndoor};

TEST_F(PipelineTest, ZooManySegments) {
  for (io::Distribution d : kZoo) {
    const pipeline::RunSummary s = expect_same_as_incore(dist(d, 6000, 11), 500, 8);
    // Windows of 500 points on a surface: many tets need a query, and more than 256
    // range failures a zone (summed over its rounds) put the queue, whose cap is 256
    // entries for windows this small, through its mid-round flushes.
    EXPECT_GT(s.tets_by_query, 0u) << io::to_string(d);
    EXPECT_GT(s.range_failures, 256u * s.zones) << io::to_string(d);
    // The rim (docs/certificate.md, Lemma 6) certifies tets, and some rim tets a round
    // leaves unproved are checked again in the next: both paths run.
    EXPECT_GT(s.tets_by_rim, 0u) << io::to_string(d);
    EXPECT_GT(s.rim_rechecks, 0u) << io::to_string(d);
    // Finished zones hand their rim on, and the later zones find tets there (Lemma 7):
    // on one thread the zones end in plan order, so both happen on every member.
    EXPECT_GT(s.rim_published, 0u) << io::to_string(d);
    EXPECT_GT(s.rim_from_neighbours, 0u) << io::to_string(d);
    // ... and the later zones' windows start with the far ends of those tets.
    EXPECT_GT(s.neighbour_points, 0u) << io::to_string(d);
    // Queued tets in conflict with a repair point the round had already found are
    // left for its insertion, without a query (the tets still equal the kernel's).
    EXPECT_GT(s.queries_spared, 0u) << io::to_string(d);
    EXPECT_LE(s.tets_by_query + s.tets_by_wall + s.tets_by_rim + s.tets_by_neighbour, s.tets) << io::to_string(d);
    // The queries that found no conflict, by how far their balls reached past the
    // window's keys: at most the queries, and on a surface some reach past them.
    const std::uint64_t past = s.empty_reach_half + s.empty_reach_one + s.empty_reach_two + s.empty_reach_farther;
    EXPECT_LE(s.empty_reach_none + past, s.queries) << io::to_string(d);
    EXPECT_GT(past, 0u) << io::to_string(d);
  }
}

TEST_F(PipelineTest, ZooZonesOnTwoThreads) {
  for (io::Distribution d : kZoo) expect_same_as_incore(dist(d, 6000, 12), 2000, 2, 3);
}

// Parallel zonal insertion: each segment split into 3 strips, whose boundaries are
// made exact like the segments' (the strip's missing points go through the same range
// test and emptiness query).
TEST_F(PipelineTest, ZonesInsideSegments) {
  expect_same_as_incore(dist(io::Distribution::kUniform, 20000), 5000, 4, 3);
  expect_same_as_incore(dist(io::Distribution::kEllipsoidShell, 20000, 3), 5000, 4, 3);
  expect_same_as_incore(dist(io::Distribution::kMixed, 20000, 4), 5000, 4, 3);
  expect_same_as_incore(dist(io::Distribution::kClusters, 20000, 5), 5000, 4, 3);
  expect_same_as_incore(dist(io::Distribution::kGrid, 20 * 20 * 20), 2000, 4, 3);
  expect_same_as_incore(dist(io::Distribution::kSphere, 2000, 6), 800, 2, 3);
  expect_same_as_incore(dist(io::Distribution::kTerrain, 20000, 7), 5000, 4, 3);
  expect_same_as_incore(dist(io::Distribution::kTwoPlates, 20000, 8), 5000, 4, 3);
}

// The planner's own choice: a budget small enough that the segments are cut into
// zones (strips) chosen to waste the least on buffers, run on 2 threads.
TEST_F(PipelineTest, BudgetPlansZones) {
  for (const auto& g :
       {dist(io::Distribution::kUniform, 100000, 11), dist(io::Distribution::kEllipsoidShell, 100000, 12)}) {
    SCOPED_TRACE(io::to_string(g.dist));
    const std::string input = write_points(g);
    pipeline::RunOptions o;
    o.threads = 2;
    o.input = input;
    o.output = (dir_ / "out.tets").string();
    // (96M did this until the writer's frames shrank with the budget: its windows
    // then held 4 segments without strips.)
    o.memory_bytes = std::uint64_t(48) << 20;
    o.progress = false;
    const auto summary = pipeline::run_job(o);
    EXPECT_GE(summary.segments, 3u);
    // On uniform points the slabs are thin at this budget and the planner cuts them
    // into strips (5 segments, 15 zones). The shell's cut depends on its hull
    // vertices, which every window holds; only its exactness is checked.
    if (g.dist == io::Distribution::kUniform) {
      EXPECT_GT(summary.zones, summary.segments) << "the planner cut no zones";
    }
    EXPECT_EQ(container_tets(o.output), incore_tets(o.output));
  }
}

TEST_F(PipelineTest, DuplicatesAreMergedAndCounted) {
  auto g = dist(io::Distribution::kUniform, 10000, 7);
  g.duplicates = 0.1;
  const std::string input = write_points(g);
  const auto s = run(input, 1000);
  EXPECT_EQ(s.input_points, 10000u);
  EXPECT_GT(s.duplicates, 500u);
  EXPECT_EQ(s.points + s.duplicates, s.input_points);
  const std::string out = (dir_ / "out.tets").string();
  EXPECT_EQ(container_tets(out), incore_tets(out));
}

TEST_F(PipelineTest, ResultDoesNotDependOnTheSegmentCount) {
  const std::string input = write_points(dist(io::Distribution::kUniform, 8000, 8));
  run(input, 100000, "one.tets");
  run(input, 700, "many.tets");
  EXPECT_EQ(container_tets((dir_ / "one.tets").string()), container_tets((dir_ / "many.tets").string()));
}

std::string file_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST_F(PipelineTest, BytesDoNotDependOnTheThreadCount) {
  const std::string input = write_points(dist(io::Distribution::kClusters, 12000, 9));
  // Segments in parallel, and zones inside segments (3 zones, or as many as threads).
  for (int threads : {1, 2, 3, 8}) {
    run(input, 800, "t" + std::to_string(threads) + ".tets", threads);
    run(input, 3000, "z3-t" + std::to_string(threads) + ".tets", threads, 3);
    run(input, 3000, "zt-t" + std::to_string(threads) + ".tets", threads, std::max(threads, 2));
  }
  const std::string one = file_bytes(dir_ / "t1.tets");
  ASSERT_FALSE(one.empty());
  for (int threads : {1, 2, 3, 8}) {
    const std::string t = std::to_string(threads);
    if (threads > 1) {
      EXPECT_TRUE(file_bytes(dir_ / ("t" + t + ".tets")) == one) << threads << " threads";
    }
    EXPECT_TRUE(file_bytes(dir_ / ("z3-t" + t + ".tets")) == one) << threads << " threads, 3 zones";
    EXPECT_TRUE(file_bytes(dir_ / ("zt-t" + t + ".tets")) == one) << threads << " threads, zones = threads";
  }
}

TEST_F(PipelineTest, StoredOrderDoesNotDependOnTheSegmentPlan) {
  // Not only the set: the frames, hence the tets in stored order, are the same.
  const std::string input = write_points(dist(io::Distribution::kUniform, 8000, 10));
  run(input, 100000, "one.tets");
  run(input, 500, "many.tets", 2);
  auto stored = [](const std::string& path) {
    io::TetReader reader(path);
    std::vector<std::uint64_t> all, frame;
    for (std::uint64_t k = 0; k < reader.frame_count(); ++k) {
      reader.read_frame(k, frame);
      all.insert(all.end(), frame.begin(), frame.end());
    }
    return all;
  };
  EXPECT_EQ(stored((dir_ / "one.tets").string()), stored((dir_ / "many.tets").string()));
}

TEST_F(PipelineTest, TooFewIndependentPointsIsAnInputError) {
  // All points on one plane.
  std::vector<double> xyz;
  for (int i = 0; i < 100; ++i) xyz.insert(xyz.end(), {double(i % 10), double(i / 10), 0.0});
  const std::string path = (dir_ / "flat.f64").string();
  auto w = io::create_points(path, {}, 100);
  w->write(xyz.data(), 100);
  w->commit();
  EXPECT_THROW(run(path, 1000), InputError);
  EXPECT_FALSE(std::filesystem::exists(dir_ / "out.tets"));
  EXPECT_FALSE(std::filesystem::exists(dir_ / "out.tets.partial"));
}

}  // namespace
}  // namespace tetstream
