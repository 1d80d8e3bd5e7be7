// `tetstream run` (out of core, many segments) against CGAL's in-core
// Delaunay_triangulation_3 on points in general position: the same tets, none
// missing (near the hull included), none extra, none twice.
#include "io/point_generators.hpp"
#include "io/point_writer.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/run/run.hpp"
#include "../unit/tet_sets.hpp"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <unistd.h>
#include <vector>

namespace tetstream {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint64_t, K>;
using Tds = CGAL::Triangulation_data_structure_3<Vb>;
using CgalDT = CGAL::Delaunay_triangulation_3<K, Tds>;
using testing_util::Quad;

struct Case {
  io::Distribution dist;
  std::uint64_t n;
  std::uint64_t zone_points;
};

class PipelineVsCgal : public ::testing::TestWithParam<Case> {};

TEST_P(PipelineVsCgal, SameTets) {
  const Case c = GetParam();
  const auto dir = std::filesystem::temp_directory_path() / ("tetstream-pvc-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  io::GeneratorOptions g;
  g.dist = c.dist;
  g.n = c.n;
  g.seed = 11;
  const io::PointGenerator gen(g);
  std::vector<double> xyz(3 * gen.count());
  gen.generate(0, gen.count(), xyz.data());
  const std::string input = (dir / "points.f64").string(), output = (dir / "out.tets").string();
  {
    auto w = io::create_points(input, {}, gen.count());
    w->write(xyz.data(), gen.count());
    w->commit();
  }
  pipeline::RunOptions o;
  o.input = input;
  o.output = output;
  o.segment_points = c.zone_points;
  o.progress = false;
  const auto summary = pipeline::run_job(o);
  EXPECT_GE(summary.segments, 10u);

  io::TetReader reader(output);
  const std::size_t n = std::size_t(reader.point_count());
  ASSERT_EQ(n, gen.count());  // general position: no duplicates
  std::vector<double> sorted(3 * n);
  std::vector<std::uint64_t> ids(n);
  reader.read_points(0, n, sorted.data(), ids.data());
  std::vector<std::pair<K::Point_3, std::uint64_t>> pts;
  for (std::size_t i = 0; i < n; ++i)
    pts.emplace_back(K::Point_3(sorted[3 * i], sorted[3 * i + 1], sorted[3 * i + 2]), i);
  const CgalDT dt(pts.begin(), pts.end());
  std::vector<Quad> ref;
  for (auto cell = dt.finite_cells_begin(); cell != dt.finite_cells_end(); ++cell) {
    testing_util::add_quad(ref, cell->vertex(0)->info(), cell->vertex(1)->info(), cell->vertex(2)->info(),
                           cell->vertex(3)->info());
  }
  std::sort(ref.begin(), ref.end());

  const std::vector<Quad> ours = testing_util::container_quads(output);
  std::filesystem::remove_all(dir);
  EXPECT_TRUE(std::adjacent_find(ours.begin(), ours.end()) == ours.end()) << "a tet written twice";
  std::vector<Quad> missing, extra;
  std::set_difference(ref.begin(), ref.end(), ours.begin(), ours.end(), std::back_inserter(missing));
  std::set_difference(ours.begin(), ours.end(), ref.begin(), ref.end(), std::back_inserter(extra));
  EXPECT_EQ(missing.size(), 0u) << "CGAL tets missing from the out-of-core output";
  EXPECT_EQ(extra.size(), 0u) << "tets CGAL does not have";
  EXPECT_EQ(ours.size(), ref.size());
}

INSTANTIATE_TEST_SUITE_P(Distributions, PipelineVsCgal,
                         ::testing::Values(Case{io::Distribution::kUniform, 10000, 800},
                                           Case{io::Distribution::kUniform, 200000, 15000},
                                           Case{io::Distribution::kEllipsoidShell, 100000, 8000},
                                           Case{io::Distribution::kMixed, 100000, 8000},
                                           Case{io::Distribution::kClusters, 100000, 8000},
                                           Case{io::Distribution::kBall, 1000000, 90000}),
                         [](const auto& info) {
                           std::string name = io::to_string(info.param.dist);
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name + "_" + std::to_string(info.param.n);
                         });

}  // namespace
}  // namespace tetstream
