// The kernel against CGAL's Delaunay_triangulation_3 (EPICK) on points in general
// position: the sets of finite tets, as sorted vertex-index quadruples, must be
// equal. Also the 100^3 grid (degenerate: validity and 6 tets per lattice cube),
// kept here rather than in the unit tests because it is too slow under ASan.
#include "core/delaunay.hpp"
#include "core/delaunay_check.hpp"
#include "tests/unit/test_points.hpp"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace tetstream::core {
namespace {

namespace tp = tetstream::test;

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, K>;
using Tds = CGAL::Triangulation_data_structure_3<Vb>;
using Cgal = CGAL::Delaunay_triangulation_3<K, Tds>;
using Quad = std::array<std::uint64_t, 4>;

void sort_quads(std::vector<Quad>& q) {
  for (Quad& t : q) std::sort(t.begin(), t.end());
  std::sort(q.begin(), q.end());
}

// CGAL's finite tets, each vertex given as map[index].
std::vector<Quad> cgal_tets(const tp::Points& p, const std::vector<std::uint64_t>* map = nullptr) {
  const std::size_t n = tp::count(p);
  std::vector<std::pair<K::Point_3, std::uint32_t>> in;
  in.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    in.emplace_back(K::Point_3(p[3 * i], p[3 * i + 1], p[3 * i + 2]), std::uint32_t(i));
  Cgal dt(in.begin(), in.end());  // range insertion: spatially sorted
  std::vector<Quad> out;
  out.reserve(dt.number_of_finite_cells());
  for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
    Quad q;
    for (int i = 0; i < 4; ++i) {
      const std::uint32_t v = c->vertex(i)->info();
      q[i] = map ? (*map)[v] : v;
    }
    out.push_back(q);
  }
  sort_quads(out);
  return out;
}

std::vector<Quad> our_tets(const Delaunay& dt) {
  std::vector<Quad> out;
  out.reserve(dt.num_finite_tets());
  dt.for_each_finite_tet([&](const VertexId* v) {
    out.push_back({dt.label(v[0]), dt.label(v[1]), dt.label(v[2]), dt.label(v[3])});
  });
  sort_quads(out);
  return out;
}

// Describes the first few differences of two sorted sets.
std::string diff(const std::vector<Quad>& ours, const std::vector<Quad>& cgal) {
  std::vector<Quad> only_ours, only_cgal;
  std::set_difference(ours.begin(), ours.end(), cgal.begin(), cgal.end(), std::back_inserter(only_ours));
  std::set_difference(cgal.begin(), cgal.end(), ours.begin(), ours.end(), std::back_inserter(only_cgal));
  std::string s = "ours " + std::to_string(ours.size()) + " tets, CGAL " + std::to_string(cgal.size()) +
                  "; only ours " + std::to_string(only_ours.size()) + ", only CGAL " + std::to_string(only_cgal.size());
  auto show = [&](const char* what, const std::vector<Quad>& v) {
    for (std::size_t i = 0; i < std::min<std::size_t>(v.size(), 5); ++i)
      s += std::string("\n  ") + what + " (" + std::to_string(v[i][0]) + " " + std::to_string(v[i][1]) + " " +
           std::to_string(v[i][2]) + " " + std::to_string(v[i][3]) + ")";
  };
  show("only ours", only_ours);
  show("only CGAL", only_cgal);
  return s;
}

enum class Dist { kUniform, kBall, kShell, kClusters };

const char* name(Dist d) {
  switch (d) {
    case Dist::kUniform:
      return "uniform";
    case Dist::kBall:
      return "ball";
    case Dist::kShell:
      return "shell";
    case Dist::kClusters:
      return "clusters";
  }
  return "?";
}

tp::Points generate(Dist d, std::size_t n, std::uint64_t seed) {
  switch (d) {
    case Dist::kUniform:
      return tp::uniform_cube(n, seed);
    case Dist::kBall:
      return tp::uniform_ball(n, seed);
    case Dist::kShell:
      return tp::ellipsoid_shell(n, seed);
    case Dist::kClusters:
      return tp::clusters(n, seed);
  }
  return {};
}

class VsCgal : public ::testing::TestWithParam<std::tuple<Dist, std::size_t>> {};

TEST_P(VsCgal, SameTets) {
  const auto [dist, n] = GetParam();
  const std::uint64_t seed = 1000 + n + std::uint64_t(dist);
  SCOPED_TRACE(std::string(name(dist)) + " n " + std::to_string(n) + " seed " + std::to_string(seed));
  const tp::Points p = generate(dist, n, seed);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, n), BuildStatus::kOk);
  const std::vector<Quad> ours = our_tets(dt);
  const std::vector<Quad> ref = cgal_tets(p);
  EXPECT_TRUE(ours == ref) << diff(ours, ref);
  if (n <= 100000) {
    const CheckReport r = check_delaunay(dt);
    EXPECT_TRUE(r.ok) << r.summary();
  }
}

INSTANTIATE_TEST_SUITE_P(Kernel, VsCgal,
                         ::testing::Combine(::testing::Values(Dist::kUniform, Dist::kBall, Dist::kShell,
                                                              Dist::kClusters),
                                            ::testing::Values(10, 100, 10000, 100000, 1000000)),
                         [](const auto& info) {
                           return std::string(name(std::get<0>(info.param))) + "_" +
                                  std::to_string(std::get<1>(info.param));
                         });

// Non-identity labels only steer the perturbation: in general position the tets
// are the same, seen through the labels.
TEST(KernelVsCgal, LabelsDoNotChangeGeneralPositionResult) {
  const std::size_t n = 20000;
  const tp::Points p = tp::uniform_ball(n, 77);
  const std::vector<std::uint64_t> labels = tp::shuffled_labels(n, 77);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), labels.data(), n), BuildStatus::kOk);
  const std::vector<Quad> ours = our_tets(dt);
  const std::vector<Quad> ref = cgal_tets(p, &labels);
  EXPECT_TRUE(ours == ref) << diff(ours, ref);
}

// Grown in two steps (insert more points later) still equals CGAL's one-shot result.
TEST(KernelVsCgal, InsertLaterEqualsCgal) {
  const std::size_t n = 200000, first = 50000;
  const tp::Points p = tp::clusters(n, 31);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, first), BuildStatus::kOk);
  dt.set_points(p.data(), nullptr, n);
  dt.insert_range(VertexId(first), VertexId(n));
  const std::vector<Quad> ours = our_tets(dt);
  const std::vector<Quad> ref = cgal_tets(p);
  EXPECT_TRUE(ours == ref) << diff(ours, ref);
}

// Degenerate: the lattice. Each unit cube (8 cospherical points) becomes 6 tets,
// as in CGAL (its perturbation differs from ours, so only the counts can agree).
TEST(KernelVsCgal, Grid30CountMatchesCgal) {
  const tp::Points p = tp::grid(30);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, tp::count(p)), BuildStatus::kOk);
  EXPECT_EQ(dt.num_finite_tets(), cgal_tets(p).size());
  EXPECT_EQ(dt.num_finite_tets(), std::size_t(6 * 29 * 29 * 29));
}

TEST(KernelVsCgal, Grid100IsValid) {
  const std::size_t k = 100;
  const tp::Points p = tp::grid(k);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, tp::count(p)), BuildStatus::kOk);
  const CheckReport r = check_delaunay(dt);
  EXPECT_TRUE(r.ok) << r.summary();
  EXPECT_EQ(r.finite_tets, std::uint64_t(6 * 99 * 99 * 99));
  EXPECT_EQ(r.vertices, k * k * k);
  EXPECT_NEAR(r.tet_volume, 99.0 * 99 * 99, 1e-6);
}

}  // namespace
}  // namespace tetstream::core
