// The kernel on degenerate and awkward inputs, checked by check_delaunay
// (core/delaunay_check.hpp). General-position inputs are compared with CGAL in
// tests/cgal/kernel_vs_cgal_test.cpp; the 100^3 grid lives there too (too slow
// for the ASan run of the unit tests).
#include "core/delaunay.hpp"
#include "core/delaunay_check.hpp"
#include "tests/unit/test_points.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace tetstream::core {
namespace {

namespace tp = tetstream::test;
using Quad = std::array<std::uint64_t, 4>;

// The finite tets as sorted label quadruples, sorted.
std::vector<Quad> label_tets(const Delaunay& dt) {
  std::vector<Quad> out;
  dt.for_each_finite_tet([&](const VertexId* v) {
    Quad q = {dt.label(v[0]), dt.label(v[1]), dt.label(v[2]), dt.label(v[3])};
    std::sort(q.begin(), q.end());
    out.push_back(q);
  });
  std::sort(out.begin(), out.end());
  return out;
}

CheckOptions strict() {
  CheckOptions o;
  o.both_sides = true;
  return o;
}

::testing::AssertionResult valid(const Delaunay& dt, const CheckOptions& o = strict()) {
  const CheckReport r = check_delaunay(dt, o);
  if (r.ok) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << r.summary();
}

// True when the points contain 4 affinely independent ones (brute force, exact).
bool has_four_independent(const tp::Points& p) {
  const std::size_t n = tp::count(p);
  if (n < 4) return false;
  const double* a = &p[0];
  std::size_t i = 1;
  while (i < n && std::equal(a, a + 3, &p[3 * i])) ++i;
  if (i == n) return false;
  const double* b = &p[3 * i];
  // a, b, c are collinear iff orient3d(a, b, c, x) = 0 for the 4 corners x of the
  // unit simplex (they cannot all lie on one plane).
  static const double corners[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (std::size_t j = i + 1; j < n; ++j) {
    const double* c = &p[3 * j];
    for (const auto& x : corners) {
      if (orient3d(a, b, c, x) == 0) continue;
      for (std::size_t k = 0; k < n; ++k)
        if (orient3d(a, b, c, &p[3 * k]) != 0) return true;
      return false;  // a, b, c span a plane holding every point
    }
  }
  return false;  // all collinear
}

std::size_t distinct_points(const tp::Points& p) {
  std::set<std::array<double, 3>> s;
  for (std::size_t i = 0; i < tp::count(p); ++i) s.insert({p[3 * i], p[3 * i + 1], p[3 * i + 2]});
  return s.size();
}

void expect_valid_build(const tp::Points& p, const std::uint64_t* labels = nullptr) {
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), labels, tp::count(p)), BuildStatus::kOk);
  EXPECT_TRUE(valid(dt));
}

// The same points in another order, with their labels carried along, must give the
// same tets as label quadruples: the perturbation depends on labels only.
void expect_order_invariant(const tp::Points& p, std::uint64_t seed) {
  const std::size_t n = tp::count(p);
  const std::vector<std::uint64_t> labels = tp::shuffled_labels(n, seed);
  std::vector<std::size_t> perm(n);
  for (std::size_t i = 0; i < n; ++i) perm[i] = i;
  tp::Rng(seed ^ 0x5EEDu).shuffle(perm);
  tp::Points q(3 * n);
  std::vector<std::uint64_t> qlabels(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) q[3 * i + k] = p[3 * perm[i] + k];
    qlabels[i] = labels[perm[i]];
  }
  Delaunay a, b;
  ASSERT_EQ(a.build(p.data(), labels.data(), n), BuildStatus::kOk);
  ASSERT_EQ(b.build(q.data(), qlabels.data(), n), BuildStatus::kOk);
  EXPECT_TRUE(valid(b));
  // With duplicates, which copy survives may differ; compare only duplicate-free sets.
  if (distinct_points(p) == n) {
    EXPECT_EQ(label_tets(a), label_tets(b));
  }
}

std::uint64_t expected_grid_tets(std::size_t k) { return 6 * (k - 1) * (k - 1) * (k - 1); }

// ---------------------------------------------------------------- grids

class GridTest : public ::testing::TestWithParam<std::size_t> {};

TEST_P(GridTest, ValidWithSixTetsPerCube) {
  const std::size_t k = GetParam();
  const tp::Points p = tp::grid(k);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, tp::count(p)), BuildStatus::kOk);
  const CheckReport r = check_delaunay(dt, strict());
  EXPECT_TRUE(r.ok) << r.summary();
  EXPECT_EQ(r.vertices, k * k * k);
  EXPECT_NEAR(r.tet_volume, double((k - 1) * (k - 1) * (k - 1)), 1e-9 * double(k * k * k));
  // Every lattice cube is one cell of 8 cospherical points; the label-ordered
  // perturbation splits each into 6 tets, as CGAL does (6 * 99^3 for 100^3).
  EXPECT_EQ(r.finite_tets, expected_grid_tets(k));
}

INSTANTIATE_TEST_SUITE_P(Kernel, GridTest, ::testing::Values(2, 3, 10, 30));

TEST(Kernel, ScaledAndShuffledGridIsValidAndOrderInvariant) {
  const tp::Points p = tp::grid(8, 0.1);  // 0.1 is not a double: rounded lattice
  expect_valid_build(p);
  expect_order_invariant(tp::grid(6), 11);
}

// ---------------------------------------------------------------- spheres

TEST(Kernel, NormalisedRandomSphere) {
  for (std::uint64_t seed : {1, 2, 3}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    expect_valid_build(tp::sphere_surface(2000, seed));
  }
}

TEST(Kernel, IntegerCosphericalPoints) {
  // Every integer point of each sphere: large exactly cospherical subsets.
  for (long r2 : {3L, 50L, 325L, 2025L}) {
    SCOPED_TRACE("r2 " + std::to_string(r2));
    const tp::Points p = tp::integer_sphere(r2);
    ASSERT_GE(tp::count(p), 8u);
    expect_valid_build(p);
    expect_order_invariant(p, std::uint64_t(r2));
  }
}

TEST(Kernel, ConcentricIntegerSpheresAndCentre) {
  tp::Points p = tp::integer_sphere(27);
  const tp::Points q = tp::integer_sphere(243);  // radius x3: shares the first sphere's directions
  p.insert(p.end(), q.begin(), q.end());
  tp::push(p, 0, 0, 0);
  expect_valid_build(p);
}

// ---------------------------------------------------------------- planes

TEST(Kernel, CoplanarLayers) {
  for (std::uint64_t seed : {1, 2}) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    expect_valid_build(tp::coplanar_layers(1000, 3, seed));
    expect_valid_build(tp::coplanar_layers(1000, 5, seed, /*coarse=*/8));
    expect_order_invariant(tp::coplanar_layers(300, 4, seed, 6), seed);
  }
}

TEST(Kernel, ManyOnOnePlaneAndAFewOff) {
  tp::Rng rng(7);
  tp::Points p;
  for (int i = 0; i < 2000; ++i) tp::push(p, rng.uniform(), rng.uniform(), 0.5);
  tp::push(p, 0.5, 0.5, 0.9);
  tp::push(p, 0.2, 0.7, 0.1);
  tp::push(p, 1.5, -0.3, 0.5);  // on the plane, outside the others
  expect_valid_build(p);

  tp::Points one = tp::coplanar_layers(500, 1, 3, /*coarse=*/10);  // integer plane, duplicates
  tp::push(one, 4.5, 4.5, 1);
  expect_valid_build(one);
}

// ---------------------------------------------------------------- duplicates

TEST(Kernel, ManyDuplicates) {
  const tp::Points p = tp::with_duplicates(500, 6, 42);
  const std::size_t n = tp::count(p);
  const std::size_t distinct = distinct_points(p);
  ASSERT_LT(distinct, n);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, n), BuildStatus::kOk);
  const CheckReport r = check_delaunay(dt, strict());
  EXPECT_TRUE(r.ok) << r.summary();
  EXPECT_EQ(r.vertices, distinct);
  EXPECT_EQ(r.duplicates, n - distinct);
  EXPECT_EQ(dt.num_vertices(), distinct);
  EXPECT_EQ(dt.stats().duplicates, n - distinct);
}

TEST(Kernel, DuplicateOfMapsToAVertexWithTheSameCoordinates) {
  const tp::Points p = tp::coarse(400, 5, 3);  // 64 positions, ~6 copies each
  const std::size_t n = tp::count(p);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, n), BuildStatus::kOk);
  EXPECT_TRUE(valid(dt));
  std::map<std::array<double, 3>, std::set<VertexId>> copies;
  for (VertexId i = 0; i < n; ++i) copies[{p[3 * i], p[3 * i + 1], p[3 * i + 2]}].insert(i);
  for (const auto& [xyz, ids] : copies) {
    // All copies map to one representative, itself one of the copies and a vertex.
    const VertexId rep = dt.duplicate_of(*ids.begin());
    EXPECT_TRUE(ids.count(rep));
    EXPECT_EQ(dt.duplicate_of(rep), rep);
    EXPECT_NE(dt.incident_tet(rep), kNoTet);
    for (VertexId i : ids) {
      EXPECT_EQ(dt.duplicate_of(i), rep) << "point " << i;
      if (i != rep) {
        EXPECT_EQ(dt.incident_tet(i), kNoTet) << "point " << i;
      }
    }
  }
  EXPECT_EQ(dt.num_vertices(), copies.size());
}

// ---------------------------------------------------------------- tiny sets

TEST(Kernel, OneTetrahedron) {
  const tp::Points p = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, 4), BuildStatus::kOk);
  const CheckReport r = check_delaunay(dt, strict());
  EXPECT_TRUE(r.ok) << r.summary();
  EXPECT_EQ(r.finite_tets, 1u);
  EXPECT_EQ(r.infinite_tets, 4u);
  EXPECT_NEAR(r.tet_volume, 1.0 / 6, 1e-15);
}

TEST(Kernel, FivePoints) {
  expect_valid_build({0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0.3, 0.3, 0.3});  // one inside
  expect_valid_build({0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1});        // bipyramid-ish
  expect_valid_build({0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0.5, 0.5, 1});    // 4 coplanar + apex
  expect_valid_build({0, 0, 0, 2, 0, 0, 0, 2, 0, 0, 0, 2, 2, 2, 2});        // 5 cospherical
}

TEST(Kernel, FourCoplanarPlusOne) {
  // A square (cocircular: every insphere through it is degenerate) and one apex.
  const tp::Points p = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0.5, 0.5, 1};
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, 5), BuildStatus::kOk);
  const CheckReport r = check_delaunay(dt, strict());
  EXPECT_TRUE(r.ok) << r.summary();
  EXPECT_EQ(r.finite_tets, 2u);
  EXPECT_EQ(r.infinite_tets, 6u);
  // Square + apex below as well: an octahedron, cospherical, 4 tets.
  const tp::Points o = {1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1};
  Delaunay dt2;
  ASSERT_EQ(dt2.build(o.data(), nullptr, 6), BuildStatus::kOk);
  const CheckReport r2 = check_delaunay(dt2, strict());
  EXPECT_TRUE(r2.ok) << r2.summary();
  EXPECT_EQ(r2.finite_tets, 4u);
}

TEST(Kernel, TooFewAffinelyIndependentPoints) {
  struct Case {
    const char* name;
    tp::Points p;
  };
  tp::Rng rng(3);
  tp::Points line, plane, equal, plane_dups;
  for (int i = 0; i < 50; ++i) tp::push(line, 1 + 2 * i, 2 - i, 3 + 4 * i);
  for (int i = 0; i < 100; ++i) tp::push(plane, rng.uniform(), rng.uniform(), 0.25);
  for (int i = 0; i < 10; ++i) tp::push(equal, 0.1, 0.2, 0.3);
  for (int i = 0; i < 60; ++i) tp::push(plane_dups, double(i % 4), double(i % 3), double(i % 4) + double(i % 3));
  const std::vector<Case> cases = {
      {"empty", {}},
      {"one point", {1, 2, 3}},
      {"two points", {1, 2, 3, 4, 5, 6}},
      {"three points", {0, 0, 0, 1, 0, 0, 0, 1, 0}},
      {"four coplanar", {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0}},
      {"three distinct + duplicates", {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 0, 0, 0, 0, 0}},
      {"collinear", line},
      {"coplanar", plane},
      {"all equal", equal},
      {"tilted plane with duplicates", plane_dups},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    ASSERT_FALSE(has_four_independent(c.p));
    Delaunay dt;
    EXPECT_EQ(dt.build(c.p.data(), nullptr, tp::count(c.p)), BuildStatus::kTooFewPoints);
  }
}

// ---------------------------------------------------------------- incremental use

void expect_grow_equals_build(const tp::Points& all, std::size_t first, std::uint64_t seed) {
  const std::size_t n = tp::count(all);
  const std::vector<std::uint64_t> labels = tp::shuffled_labels(n, seed);
  Delaunay once;
  ASSERT_EQ(once.build(all.data(), labels.data(), n), BuildStatus::kOk);

  // Build on the first points from a buffer that is then replaced by a grown copy.
  tp::Points head(all.begin(), all.begin() + std::ptrdiff_t(3 * first));
  std::vector<std::uint64_t> head_labels(labels.begin(), labels.begin() + std::ptrdiff_t(first));
  Delaunay grown;
  ASSERT_EQ(grown.build(head.data(), head_labels.data(), first), BuildStatus::kOk);
  EXPECT_TRUE(valid(grown));
  const tp::Points copy = all;
  const std::vector<std::uint64_t> copy_labels = labels;
  head.assign(head.size(), std::nan(""));  // the old buffer must no longer be read
  grown.set_points(copy.data(), copy_labels.data(), n);
  grown.insert_range(VertexId(first), VertexId(n));
  EXPECT_TRUE(valid(grown));
  EXPECT_EQ(label_tets(grown), label_tets(once));

  // The same, one point at a time.
  Delaunay single;
  ASSERT_EQ(single.build(copy.data(), copy_labels.data(), first), BuildStatus::kOk);
  single.set_points(copy.data(), copy_labels.data(), n);
  for (std::size_t v = first; v < n; ++v) single.insert(VertexId(v));
  EXPECT_TRUE(valid(single));
  EXPECT_EQ(label_tets(single), label_tets(once));
}

TEST(Kernel, InsertMorePointsLater) {
  {
    SCOPED_TRACE("uniform");
    expect_grow_equals_build(tp::uniform_cube(3000, 5), 1500, 5);
  }
  {
    SCOPED_TRACE("grid");  // degenerate: the perturbation alone decides
    expect_grow_equals_build(tp::grid(9), 300, 6);
  }
  {
    SCOPED_TRACE("coarse, duplicate-free prefix of a cube");
    // Distinct lattice points in random order (duplicates would make "which copy
    // is the vertex" depend on insertion order).
    tp::Points p = tp::grid(7);
    std::vector<std::size_t> perm(tp::count(p));
    for (std::size_t i = 0; i < perm.size(); ++i) perm[i] = i;
    tp::Rng(9).shuffle(perm);
    tp::Points q;
    for (std::size_t i : perm) tp::push(q, p[3 * i], p[3 * i + 1], p[3 * i + 2]);
    expect_grow_equals_build(q, 20, 7);
  }
}

// A cavity with thousands of boundary vertices: the centre of a sphere inserted
// after 4,000 points of its surface conflicts with every tet, so the new tets are
// linked through the edge hash table rather than the dense one (kDenseEdgeSide),
// as flat regions (terrains) make them. The result must equal a build that inserts
// the centre among the others, and be valid.
TEST(Kernel, HugeCavityIsLinkedLikeASmallOne) {
  tp::Points p = tp::sphere_surface(4000, 21);
  tp::push(p, 0.0, 0.0, 0.0);
  expect_grow_equals_build(p, 4000, 22);
  // And a second huge cavity in the same kernel (the table is reused, not stale).
  tp::push(p, 1e-3, 2e-3, -1e-3);
  expect_grow_equals_build(p, 4000, 23);
}

TEST(Kernel, OrderInvariantOnDegenerateInputs) {
  expect_order_invariant(tp::grid(7), 1);
  expect_order_invariant(tp::integer_sphere(50), 2);
  expect_order_invariant(tp::uniform_cube(500, 3), 3);
}

// ---------------------------------------------------------------- star, circumsphere

TEST(Kernel, StarIsTheSetOfIncidentTets) {
  for (const tp::Points& p : {tp::uniform_cube(800, 8), tp::grid(6)}) {
    const std::size_t n = tp::count(p);
    Delaunay dt;
    ASSERT_EQ(dt.build(p.data(), nullptr, n), BuildStatus::kOk);
    std::vector<std::vector<TetId>> incident(n);
    for (TetId t = 0; t < dt.num_tet_slots(); ++t) {
      if (!dt.is_alive(t)) continue;
      for (int i = 0; i < 4; ++i)
        if (dt.vertex(t, i) != kInfiniteVertex) incident[dt.vertex(t, i)].push_back(t);
    }
    std::vector<TetId> star;
    for (VertexId v = 0; v < n; ++v) {
      star.clear();
      dt.star(v, star);
      std::sort(star.begin(), star.end());
      ASSERT_EQ(star, incident[v]) << "vertex " << v;
    }
  }
}

// strictly_inside: true exactly for points in the open hull. The unit cube's 8
// corners and its centre: the hull is the cube; points on its faces, edges and
// corners, and on the internal faces of the tets (the centre's, the diagonals'), are
// not strictly inside any tet.
TEST(Kernel, StrictlyInsideIsTheOpenHullMinusTheTetsBoundaries) {
  tp::Points p;
  for (int i = 0; i < 8; ++i) tp::push(p, i & 1, i >> 1 & 1, i >> 2 & 1);
  tp::push(p, 0.5, 0.5, 0.5);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, 9), BuildStatus::kOk);
  TetId hint = kNoTet;
  auto inside = [&](double x, double y, double z) {
    const double q[3] = {x, y, z};
    return dt.strictly_inside(q, hint);
  };
  EXPECT_FALSE(inside(2, 0.5, 0.5));  // outside
  EXPECT_FALSE(inside(-1e-300, 0.5, 0.5));
  EXPECT_FALSE(inside(0, 0.3, 0.6));    // on a face of the hull
  EXPECT_FALSE(inside(0.5, 0, 0));      // on an edge of the hull
  EXPECT_FALSE(inside(1, 1, 1));        // a vertex
  EXPECT_FALSE(inside(0.5, 0.5, 0.5));  // the inner vertex
  // Random points of the open cube miss the tets' internal faces.
  tp::Rng rng(5);
  int yes = 0;
  for (int k = 0; k < 2000; ++k) {
    const double q[3] = {rng.uniform(0.01, 0.99), rng.uniform(0.01, 0.99), rng.uniform(0.01, 0.99)};
    yes += dt.strictly_inside(q, hint);
  }
  EXPECT_EQ(yes, 2000);
  // On the internal face (centre, (0,0,0), (0,0,1)), shared by two tets.
  EXPECT_FALSE(inside(0.25, 0.25, 0.5));
}

TEST(Kernel, CircumsphereBoundHoldsAtTheVertices) {
  const tp::Points p = tp::uniform_ball(2000, 12);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, tp::count(p)), BuildStatus::kOk);
  std::size_t checked = 0;
  for (TetId t = 0; t < dt.num_tet_slots(); ++t) {
    if (!dt.is_alive(t) || dt.is_infinite(t)) continue;
    const Circumsphere cs = dt.tet_circumsphere(t);
    if (!cs.valid) continue;
    ++checked;
    for (int i = 0; i < 4; ++i) {
      const double* q = dt.point(dt.vertex(t, i));
      const double d = std::hypot(q[0] - cs.center[0], q[1] - cs.center[1], q[2] - cs.center[2]);
      const double slack = cs.radius_error + std::sqrt(3.0) * cs.center_error + 4e-16 * (d + cs.radius);
      EXPECT_LE(std::abs(d - cs.radius), slack) << "tet " << t;
    }
  }
  EXPECT_GT(checked, dt.num_finite_tets() * 9 / 10);
}

// ---------------------------------------------------------------- the checker itself

// check_delaunay must fail when the geometry under a valid structure changes:
// set_points() re-points the kernel at altered coordinates or labels.
TEST(DelaunayCheck, DetectsAPointThatIsNotAVertex) {
  tp::Points p = tp::uniform_cube(300, 21);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, 300), BuildStatus::kOk);
  tp::push(p, 0.5, 0.5, 0.5);  // never inserted
  dt.set_points(p.data(), nullptr, 301);
  const CheckReport r = check_delaunay(dt);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.bad_coverage, 1u) << r.summary();
}

TEST(DelaunayCheck, DetectsAMovedVertex) {
  const tp::Points p = tp::uniform_cube(300, 22);
  Delaunay dt;
  ASSERT_EQ(dt.build(p.data(), nullptr, 300), BuildStatus::kOk);
  // A small move breaks the empty-sphere property before it breaks orientation.
  tp::Points q = p;
  q[0] += 0.03;
  dt.set_points(q.data(), nullptr, 300);
  CheckReport r = check_delaunay(dt, strict());
  EXPECT_FALSE(r.ok);
  EXPECT_GT(r.bad_delaunay + r.bad_orientation + r.bad_hull, 0u) << r.summary();
  EXPECT_LE(r.messages.size(), CheckOptions{}.max_messages);
  // A large move inverts tets: the volumes no longer add up.
  tp::Points s = p;
  s[0] = 5, s[1] = 5, s[2] = 5;
  dt.set_points(s.data(), nullptr, 300);
  r = check_delaunay(dt);
  EXPECT_GT(r.bad_orientation, 0u) << r.summary();
  EXPECT_GT(r.bad_volume + r.bad_hull, 0u) << r.summary();
}

TEST(DelaunayCheck, DetectsTheWrongPerturbation) {
  // On a lattice only the labels decide; other labels give another triangulation.
  const tp::Points p = tp::grid(4);
  const std::size_t n = tp::count(p);
  const std::vector<std::uint64_t> shuffled = tp::shuffled_labels(n, 23);
  Delaunay a, b;
  ASSERT_EQ(a.build(p.data(), nullptr, n), BuildStatus::kOk);
  ASSERT_EQ(b.build(p.data(), shuffled.data(), n), BuildStatus::kOk);
  EXPECT_TRUE(valid(b));
  auto vertex_tets = [](const Delaunay& dt) {
    std::vector<Quad> out;
    dt.for_each_finite_tet([&](const VertexId* v) {
      Quad q = {v[0], v[1], v[2], v[3]};
      std::sort(q.begin(), q.end());
      out.push_back(q);
    });
    std::sort(out.begin(), out.end());
    return out;
  };
  ASSERT_NE(vertex_tets(a), vertex_tets(b));
  a.set_points(p.data(), shuffled.data(), n);
  const CheckReport r = check_delaunay(a, strict());
  EXPECT_FALSE(r.ok);
  EXPECT_GT(r.bad_delaunay + r.bad_hull, 0u) << r.summary();
  EXPECT_EQ(r.bad_orientation + r.bad_adjacency + r.bad_topology + r.bad_volume, 0u) << r.summary();
}

// ---------------------------------------------------------------- fuzz

// Hundreds of small sets on coarse lattices: duplicates, coplanar and cospherical
// subsets everywhere. A failure prints its seed; rebuild with tp::coarse(n, seed, m, scale).
TEST(KernelFuzz, CoarseLatticeSets) {
  struct Variant {
    int m;
    double scale;
  };
  const Variant variants[] = {{4, 1.0}, {2, 1.0}, {4, 0.1}, {9, 1.0 / 3}};
  int built = 0, too_few = 0;
  for (std::uint64_t seed = 1; seed <= 1000; ++seed) {
    tp::Rng rng(seed * 0x9E37u);
    const std::size_t n = 5 + rng.below(196);
    const Variant& var = variants[seed % 4];
    SCOPED_TRACE("seed " + std::to_string(seed) + " n " + std::to_string(n) + " m " + std::to_string(var.m) +
                 " scale " + std::to_string(var.scale));
    const tp::Points p = tp::coarse(n, seed, var.m, var.scale);
    Delaunay dt;
    const BuildStatus s = dt.build(p.data(), nullptr, n);
    if (s == BuildStatus::kTooFewPoints) {
      ++too_few;
      EXPECT_FALSE(has_four_independent(p));
      continue;
    }
    ++built;
    ASSERT_EQ(s, BuildStatus::kOk);
    const CheckReport r = check_delaunay(dt, strict());
    ASSERT_TRUE(r.ok) << r.summary();
    EXPECT_EQ(r.vertices, distinct_points(p));
    if (seed % 5 == 0) {
      // Labels permuted and the points reordered (distinct points only).
      std::set<std::array<double, 3>> seen;
      tp::Points q;
      for (std::size_t i = 0; i < n; ++i)
        if (seen.insert({p[3 * i], p[3 * i + 1], p[3 * i + 2]}).second)
          tp::push(q, p[3 * i], p[3 * i + 1], p[3 * i + 2]);
      if (has_four_independent(q)) expect_order_invariant(q, seed);
      // Grown from a prefix: the same tets as built at once.
      const std::size_t first = tp::count(q) / 2;
      if (has_four_independent(tp::Points(q.begin(), q.begin() + std::ptrdiff_t(3 * first))))
        expect_grow_equals_build(q, first, seed);
    }
  }
  EXPECT_GT(built, 900);
  (void)too_few;
}

// Tiny sets near the threshold: 4..8 points on a 2-lattice, many flat.
TEST(KernelFuzz, TinyDegenerateSets) {
  for (std::uint64_t seed = 1; seed <= 500; ++seed) {
    const std::size_t n = 4 + seed % 5;
    SCOPED_TRACE("seed " + std::to_string(seed) + " n " + std::to_string(n));
    const tp::Points p = tp::coarse(n, seed, 2);
    Delaunay dt;
    const BuildStatus s = dt.build(p.data(), nullptr, n);
    ASSERT_EQ(s == BuildStatus::kOk, has_four_independent(p));
    if (s == BuildStatus::kOk) {
      ASSERT_TRUE(valid(dt));
    }
  }
}

}  // namespace
}  // namespace tetstream::core
