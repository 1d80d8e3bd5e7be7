// `run --periodic` (out of core, many segments) against CGAL's in-core
// Periodic_3_Delaunay_triangulation_3 in its 1-sheeted covering, on points in general
// position in the unit box: the same periodic tets (labels and offsets), none missing,
// none extra. Fast enough for the quick tier (cgal_quick): 10^3 to 10^5 points.
#include "pipeline/periodic/periodic.hpp"
#include "pipeline/periodic/verify.hpp"
#include "../unit/periodic_sets.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Periodic_3_Delaunay_triangulation_3.h>
#include <CGAL/Periodic_3_Delaunay_triangulation_traits_3.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <unistd.h>

namespace tetstream {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Gt = CGAL::Periodic_3_Delaunay_triangulation_traits_3<K>;
using P3DT3 = CGAL::Periodic_3_Delaunay_triangulation_3<Gt>;
using testing_util::PeriodicKey;

std::vector<PeriodicKey> cgal_keys(const std::vector<double>& xyz, bool& one_sheet) {
  std::vector<K::Point_3> pts;
  std::map<std::tuple<double, double, double>, std::uint64_t> index;
  for (std::size_t i = 0; i < xyz.size() / 3; ++i) {
    pts.emplace_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    index[{xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]}] = i;
  }
  P3DT3 t(P3DT3::Iso_cuboid(0, 0, 0, 1, 1, 1));
  t.insert(pts.begin(), pts.end(), true);
  one_sheet = t.is_triangulation_in_1_sheet();
  std::vector<PeriodicKey> out;
  for (auto it = t.periodic_tetrahedra_begin(P3DT3::UNIQUE); it != t.periodic_tetrahedra_end(P3DT3::UNIQUE); ++it) {
    std::uint64_t label[4];
    int off[4][3];
    for (int i = 0; i < 4; ++i) {
      const auto& [p, o] = (*it)[std::size_t(i)];
      label[i] = index.at({p.x(), p.y(), p.z()});
      off[i][0] = o.x();
      off[i][1] = o.y();
      off[i][2] = o.z();
    }
    out.push_back(testing_util::periodic_key(label, off));
  }
  std::sort(out.begin(), out.end());
  return out;
}

struct Case {
  std::size_t n;
  std::uint64_t seed;
};

class PeriodicVsCgal : public ::testing::TestWithParam<Case> {};

TEST_P(PeriodicVsCgal, SameTets) {
  const Case c = GetParam();
  const auto dir = std::filesystem::temp_directory_path() / ("tetstream-pvcgal-" + std::to_string(::getpid()) + "-" +
                                                             std::to_string(c.n) + "-" + std::to_string(c.seed));
  std::filesystem::create_directories(dir);
  const auto xyz = testing_util::dyadic_uniform(c.n, c.seed);
  const std::string input = (dir / "points.f64").string(), output = (dir / "out.tets").string();
  testing_util::write_f64(input, xyz);
  pipeline::RunOptions o;
  o.input = input;
  o.output = output;
  o.segment_points = c.n / 10;  // about ten segments: the budget a large job has
  o.progress = false;
  o.threads = 2;
  pipeline::periodic::PeriodicOptions p;
  p.period = {1, 1, 1};
  const auto s = pipeline::periodic::run_periodic(o, p);
  EXPECT_GE(s.padded.segments, 10u);
  bool one_sheet = false;
  const auto ref = cgal_keys(xyz, one_sheet);
  ASSERT_TRUE(one_sheet) << "CGAL kept the 27-sheeted covering: the case is not comparable";
  const auto ours = testing_util::container_periodic_keys(output);
  EXPECT_EQ(ours.size(), ref.size());
  std::vector<PeriodicKey> missing, extra;
  std::set_difference(ref.begin(), ref.end(), ours.begin(), ours.end(), std::back_inserter(missing));
  std::set_difference(ours.begin(), ours.end(), ref.begin(), ref.end(), std::back_inserter(extra));
  EXPECT_EQ(missing.size(), 0u);
  EXPECT_EQ(extra.size(), 0u);
  const auto v = pipeline::periodic::verify_periodic(output, std::uint64_t(64) << 20, dir.string());
  EXPECT_TRUE(v.ok) << v.problem;
  std::filesystem::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Uniform, PeriodicVsCgal,
                         ::testing::Values(Case{1000, 1}, Case{1000, 2}, Case{1000, 3}, Case{10000, 4}, Case{10000, 5},
                                           Case{100000, 6}),
                         [](const auto& info) {
                           std::string name = "n";  // (appended: GCC 12 warns, wrongly, on "n" + string)
                           name += std::to_string(info.param.n);
                           name += "_seed";
                           name += std::to_string(info.param.seed);
                           return name;
                         });

}  // namespace
}  // namespace tetstream
