// `verify` (pipeline/verify.hpp) and the external sort it spills to
// (pipeline/external_sort.hpp).
//
// Correct containers come from the in-memory kernel: points sorted (x, y, z), exact
// duplicates merged, label = position, the kernel run with those labels, tets written
// in order of their smallest label with the container writer. Broken ones edit the
// tet list before writing; each must be caught with the right violation kind, and
// nothing else may be reported where the edit leaves everything else valid.
#include "core/delaunay.hpp"
#include "core/predicates.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/files/temp_files.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/verify/verify.hpp"
#include "thread_ranks.hpp"
#include "test_points.hpp"

#include <gtest/gtest.h>
#include <omp.h>
#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <unistd.h>
#include <vector>

namespace tetstream {
namespace {

using pipeline::VerifyOptions;
using pipeline::VerifyReport;
using pipeline::Violation;
namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------
// Building outputs.

struct Output {
  std::vector<double> xyz;          // sorted, distinct: label = index
  std::vector<std::uint64_t> tets;  // 4 labels per tet, positively oriented
  std::size_t count() const { return xyz.size() / 3; }
  const double* p(std::uint64_t l) const { return xyz.data() + 3 * l; }
};

// Sorted, duplicate-free copy of the points.
std::vector<double> sorted_distinct(const test::Points& raw) {
  const std::size_t n = raw.size() / 3;
  std::vector<std::array<double, 3>> p(n);
  for (std::size_t i = 0; i < n; ++i) p[i] = {raw[3 * i], raw[3 * i + 1], raw[3 * i + 2]};
  std::sort(p.begin(), p.end());
  p.erase(std::unique(p.begin(), p.end()), p.end());
  std::vector<double> xyz;
  xyz.reserve(3 * p.size());
  for (const auto& q : p) xyz.insert(xyz.end(), q.begin(), q.end());
  return xyz;
}

// Tets sorted by smallest label (the order tetstream writes), each kept as given.
void sort_by_min(std::vector<std::uint64_t>& tets) {
  const std::size_t t = tets.size() / 4;
  std::vector<std::array<std::uint64_t, 4>> v(t);
  for (std::size_t i = 0; i < t; ++i) v[i] = {tets[4 * i], tets[4 * i + 1], tets[4 * i + 2], tets[4 * i + 3]};
  std::stable_sort(v.begin(), v.end(), [](const auto& a, const auto& b) {
    return *std::min_element(a.begin(), a.end()) < *std::min_element(b.begin(), b.end());
  });
  for (std::size_t i = 0; i < t; ++i) std::copy(v[i].begin(), v[i].end(), tets.begin() + std::ptrdiff_t(4 * i));
}

// Triangulates `keep` (labels into xyz, increasing) with their labels; tets in labels.
std::vector<std::uint64_t> triangulate_labels(const std::vector<double>& xyz, const std::vector<std::uint64_t>& keep) {
  std::vector<double> sub;
  sub.reserve(3 * keep.size());
  for (std::uint64_t l : keep)
    sub.insert(sub.end(), xyz.begin() + std::ptrdiff_t(3 * l), xyz.begin() + std::ptrdiff_t(3 * l + 3));
  core::Delaunay dt;
  EXPECT_EQ(dt.build(sub.data(), keep.data(), keep.size()), core::BuildStatus::kOk);
  std::vector<std::uint64_t> tets;
  dt.for_each_finite_tet([&](const core::VertexId* v) {
    for (int i = 0; i < 4; ++i) tets.push_back(keep[v[i]]);
  });
  sort_by_min(tets);
  return tets;
}

// The points of `raw` (sorted, distinct), triangulated without label `left_out`: an
// output in which one point of the container is missing from the tets.
Output triangulate_without(const test::Points& raw, std::uint64_t left_out) {
  Output o;
  o.xyz = sorted_distinct(raw);
  std::vector<std::uint64_t> keep;
  for (std::uint64_t l = 0; l < o.count(); ++l)
    if (l != left_out) keep.push_back(l);
  o.tets = triangulate_labels(o.xyz, keep);
  return o;
}

Output triangulate(const test::Points& raw) {
  Output o;
  o.xyz = sorted_distinct(raw);
  std::vector<std::uint64_t> all(o.count());
  std::iota(all.begin(), all.end(), 0);
  o.tets = triangulate_labels(o.xyz, all);
  return o;
}

class TempFiles {
 public:
  TempFiles() {
    dir_ = fs::temp_directory_path() / ("verify_test-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  ~TempFiles() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  const fs::path& dir() const { return dir_; }

 private:
  fs::path dir_;
};

TempFiles& temp() {
  static TempFiles t;
  return t;
}

std::string write_container(const Output& o, const std::string& name, std::uint32_t frame_tets = 500,
                            io::CoordType coords = io::CoordType::kFloat64) {
  io::TetFileHeader h;
  h.coord_type = coords;
  h.point_count = o.count();
  // The box of the coordinates as stored (float32 rounds them).
  auto stored = [coords](double x) { return coords == io::CoordType::kFloat32 ? double(float(x)) : x; };
  for (int c = 0; c < 3; ++c) h.bbox_min[c] = h.bbox_max[c] = stored(o.xyz[std::size_t(c)]);
  for (std::size_t i = 0; i < o.count(); ++i)
    for (int c = 0; c < 3; ++c) {
      h.bbox_min[c] = std::min(h.bbox_min[c], stored(o.xyz[3 * i + c]));
      h.bbox_max[c] = std::max(h.bbox_max[c], stored(o.xyz[3 * i + c]));
    }
  h.tool = "verify_test";
  io::TetWriterOptions wo;
  wo.frame_tets = frame_tets;
  wo.sync = false;
  const std::string path = temp().path(name);
  io::TetWriter w(path, h, wo);
  w.add_points(o.xyz.data(), nullptr, o.count());
  w.add_tets(std::span<const std::uint64_t>(o.tets));
  w.finish();
  return path;
}

VerifyOptions quiet_options() {
  VerifyOptions v;
  v.progress = false;
  v.tmpdir = temp().dir().string();
  return v;
}

VerifyReport verify_output(const Output& o, const std::string& name, VerifyOptions v = quiet_options(),
                           std::uint32_t frame_tets = 500) {
  return pipeline::verify_file(write_container(o, name, frame_tets), v);
}

std::uint64_t count(const VerifyReport& r, Violation k) { return r.counts[std::size_t(k)]; }

// Everything but `allowed` is zero.
void expect_only(const VerifyReport& r, std::initializer_list<Violation> allowed) {
  for (int k = 0; k < pipeline::kViolationKinds; ++k) {
    if (std::find(allowed.begin(), allowed.end(), Violation(k)) != allowed.end()) continue;
    EXPECT_EQ(r.counts[std::size_t(k)], 0u) << pipeline::violation_name(Violation(k)) << "\n" << r.summary();
  }
}

// Facet -> tets, for picking tets to break.
struct Facets {
  std::map<std::array<std::uint64_t, 3>, std::vector<std::size_t>> of;
  explicit Facets(const std::vector<std::uint64_t>& tets) {
    for (std::size_t t = 0; t < tets.size() / 4; ++t)
      for (int f = 0; f < 4; ++f) {
        std::array<std::uint64_t, 3> k;
        int j = 0;
        for (int i = 0; i < 4; ++i)
          if (i != f) k[std::size_t(j++)] = tets[4 * t + std::size_t(i)];
        std::sort(k.begin(), k.end());
        of[k].push_back(t);
      }
  }
  int hull_facets_of(const std::vector<std::uint64_t>& tets, std::size_t t) const {
    int h = 0;
    for (int f = 0; f < 4; ++f) {
      std::array<std::uint64_t, 3> k;
      int j = 0;
      for (int i = 0; i < 4; ++i)
        if (i != f) k[std::size_t(j++)] = tets[4 * t + std::size_t(i)];
      std::sort(k.begin(), k.end());
      if (of.at(k).size() == 1) ++h;
    }
    return h;
  }
};

void erase_tet(std::vector<std::uint64_t>& tets, std::size_t t) {
  tets.erase(tets.begin() + std::ptrdiff_t(4 * t), tets.begin() + std::ptrdiff_t(4 * t + 4));
}

const Output& uniform_output() {
  static const Output o = triangulate(test::uniform_cube(2000, 11));
  return o;
}

// ---------------------------------------------------------------------------------
// Correct outputs pass.

struct Case {
  const char* name;
  test::Points points;
};

std::vector<Case> valid_cases() {
  std::vector<Case> c;
  c.push_back({"uniform", test::uniform_cube(3000, 1)});
  c.push_back({"ball", test::uniform_ball(2000, 2)});
  c.push_back({"shell", test::ellipsoid_shell(2000, 3)});
  c.push_back({"clusters", test::clusters(2000, 4)});
  c.push_back({"grid", test::grid(9)});
  c.push_back({"grid_scaled", test::grid(6, 0.1)});
  c.push_back({"cospherical", test::integer_sphere(50)});
  c.push_back({"sphere_surface", test::sphere_surface(500, 5)});
  c.push_back({"coplanar_layers", test::coplanar_layers(1500, 4, 6, 12)});
  c.push_back({"coarse", test::coarse(2000, 7, 5)});
  c.push_back({"duplicates", test::with_duplicates(800, 3, 8)});
  c.push_back({"one_tet", {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1}});
  c.push_back({"cube_corners", test::grid(2)});  // 8 cospherical points, 6 coplanar hull faces
  return c;
}

TEST(Verify, KernelOutputsPass) {
  for (const Case& c : valid_cases()) {
    SCOPED_TRACE(c.name);
    const Output o = triangulate(c.points);
    const VerifyReport r = verify_output(o, std::string(c.name) + ".tets");
    EXPECT_TRUE(r.ok()) << r.summary();
    EXPECT_EQ(r.points, o.count());
    EXPECT_EQ(r.tets, o.tets.size() / 4);
    EXPECT_EQ(r.vertices, o.count());
    EXPECT_EQ(r.euler, 1);
    EXPECT_EQ(r.hull_euler, 2);
    EXPECT_EQ(2 * r.interior_facets + r.boundary_facets, 4 * r.tets);
    EXPECT_EQ(r.insphere_tests, r.interior_facets);
    EXPECT_EQ(r.tets_checked, r.tets);
    EXPECT_GT(r.hull_tests, 0u);
    EXPECT_LT(r.volume_rel_error, 1e-12);
  }
}

// The same answers whatever the memory budget, step size or label width: a tiny
// budget spills open facets and edges to disk and merges them at the end.
TEST(Verify, BudgetAndWidthDoNotChangeTheResult) {
  const Output o = triangulate(test::clusters(6000, 21));
  const std::string path = write_container(o, "budget.tets", 1000);
  VerifyOptions big = quiet_options();
  const VerifyReport a = pipeline::verify_file(path, big);
  ASSERT_TRUE(a.ok()) << a.summary();
  EXPECT_EQ(a.spilled_records, 0u);

  VerifyOptions tiny = quiet_options();
  tiny.memory_bytes = 16 << 20;
  tiny.open_bytes = 20000;  // ~800 open facets: spills all the time
  tiny.batch_tets = 300;
  const VerifyReport b = pipeline::verify_file(path, tiny);
  EXPECT_TRUE(b.ok()) << b.summary();
  EXPECT_GT(b.spilled_records, 0u);

  VerifyOptions wide = quiet_options();
  wide.wide_labels = true;
  wide.batch_tets = 777;
  const VerifyReport c = pipeline::verify_file(path, wide);
  EXPECT_TRUE(c.ok()) << c.summary();
  for (const VerifyReport* r : {&b, &c}) {
    EXPECT_EQ(r->facets, a.facets);
    EXPECT_EQ(r->edges, a.edges);
    EXPECT_EQ(r->boundary_facets, a.boundary_facets);
    EXPECT_EQ(r->hull_edges, a.hull_edges);
    EXPECT_EQ(r->insphere_tests, a.insphere_tests);
    EXPECT_EQ(r->hull_volume, a.hull_volume);
  }
  // No temporary directory is left behind.
  for (const auto& e : fs::directory_iterator(temp().dir()))
    EXPECT_EQ(e.path().filename().string().rfind("tetstream-verify", 0), std::string::npos) << e.path();
}

// Frames in any order (not sorted by smallest label) and a spill forced by a budget
// too small for the open facets: still exact.
TEST(Verify, UnorderedTetsWithSpills) {
  Output o = triangulate(test::uniform_cube(4000, 31));
  test::Rng rng(5);
  const std::size_t t = o.tets.size() / 4;
  std::vector<std::size_t> perm(t);
  std::iota(perm.begin(), perm.end(), 0);
  rng.shuffle(perm);
  std::vector<std::uint64_t> shuffled(o.tets.size());
  for (std::size_t i = 0; i < t; ++i)
    std::copy(o.tets.begin() + std::ptrdiff_t(4 * perm[i]), o.tets.begin() + std::ptrdiff_t(4 * perm[i] + 4),
              shuffled.begin() + std::ptrdiff_t(4 * i));
  pipeline::MemorySource src(o.xyz, shuffled, 997);
  VerifyOptions v = quiet_options();
  v.open_bytes = 200000;
  const VerifyReport r = pipeline::verify(src, v);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_EQ(r.euler, 1);
  EXPECT_GT(r.spilled_records, 0u);
  const VerifyReport ref = verify_output(o, "unordered_ref.tets");
  EXPECT_EQ(r.facets, ref.facets);
  EXPECT_EQ(r.edges, ref.edges);
}

// ---------------------------------------------------------------------------------
// Broken outputs are caught.

TEST(Verify, FlippedTet) {
  Output o = uniform_output();
  const std::size_t t = o.tets.size() / 4 / 2;
  std::swap(o.tets[4 * t + 2], o.tets[4 * t + 3]);  // an odd permutation
  const VerifyReport r = verify_output(o, "flipped.tets");
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(count(r, Violation::kOrientation), 1u) << r.summary();
  ASSERT_FALSE(r.listed.empty());
  EXPECT_EQ(r.listed.front().kind, Violation::kOrientation);
}

// A float32 container is held as floats (12 bytes a point, not 24) and checked on the
// floats it stores: the same answers as the doubles of the same values, and a
// triangulation of other values (the doubles before rounding) is caught.
TEST(Verify, Float32ContainersAreCheckedOnTheirFloats) {
  test::Points raw = test::uniform_cube(3000, 41);
  for (double& x : raw) x = double(float(x));
  const Output o = triangulate(raw);
  VerifyOptions small = quiet_options();
  small.memory_bytes = 16 << 20;  // below what is fixed + 16 MiB: the plan is fixed + 16 MiB
  const VerifyReport d = pipeline::verify_file(write_container(o, "f64.tets"), small);
  const VerifyReport f = pipeline::verify_file(write_container(o, "f32.tets", 500, io::CoordType::kFloat32), small);
  ASSERT_TRUE(d.ok()) << d.summary();
  ASSERT_TRUE(f.ok()) << f.summary();
  EXPECT_EQ(f.facets, d.facets);
  EXPECT_EQ(f.insphere_tests, d.insphere_tests);
  EXPECT_EQ(f.hull_volume, d.hull_volume);
  EXPECT_EQ(d.memory_planned - f.memory_planned, 12 * o.count());

  // A grid (coordinates 1 to 6) jittered by far less than a float's spacing:
  // triangulated on the doubles it passes as float64; stored as float32 the points are
  // the exact grid, whose cospherical cells the labels' perturbation splits otherwise.
  test::Points g = test::grid(6);
  test::Rng rng(3);
  for (double& x : g) x += 1 + rng.uniform(-1e-12, 1e-12);
  const Output j = triangulate(g);
  const VerifyReport jd = verify_output(j, "jitter64.tets");
  EXPECT_TRUE(jd.ok()) << jd.summary();
  const VerifyReport jf =
      pipeline::verify_file(write_container(j, "jitter32.tets", 500, io::CoordType::kFloat32), quiet_options());
  EXPECT_FALSE(jf.ok());
  EXPECT_GT(count(jf, Violation::kDelaunay) + count(jf, Violation::kOrientation), 0u) << jf.summary();
}

TEST(Verify, RemovedInteriorTet) {
  Output o = uniform_output();
  const Facets f(o.tets);
  std::size_t t = o.tets.size() / 4 / 2;
  while (f.hull_facets_of(o.tets, t) != 0) ++t;
  erase_tet(o.tets, t);
  const VerifyReport r = verify_output(o, "removed.tets");
  EXPECT_FALSE(r.ok());
  // A cavity: its four facets form a second boundary surface, concave seen from the tets.
  EXPECT_GT(count(r, Violation::kHullConvex), 0u) << r.summary();
  EXPECT_GT(count(r, Violation::kHullTopology), 0u) << r.summary();
  EXPECT_GT(count(r, Violation::kEuler), 0u) << r.summary();
  expect_only(r, {Violation::kHullConvex, Violation::kHullTopology, Violation::kEuler});
}

TEST(Verify, DuplicatedTet) {
  Output o = uniform_output();
  const std::size_t t = o.tets.size() / 4 / 3;
  // A copy far away (in the last frame).
  const std::array<std::uint64_t, 4> copy = {o.tets[4 * t], o.tets[4 * t + 1], o.tets[4 * t + 2], o.tets[4 * t + 3]};
  o.tets.insert(o.tets.end(), copy.begin(), copy.end());
  const VerifyReport r = verify_output(o, "duplicated.tets");
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(count(r, Violation::kDuplicateTet), 1u) << r.summary();
  expect_only(r, {Violation::kDuplicateTet, Violation::kEuler, Violation::kVolume, Violation::kHullTopology});

  // A copy rotated evenly, next to it in the same frame.
  Output o2 = uniform_output();
  const std::uint64_t c[4] = {o2.tets[4 * t + 1], o2.tets[4 * t + 2], o2.tets[4 * t], o2.tets[4 * t + 3]};
  o2.tets.insert(o2.tets.begin() + std::ptrdiff_t(4 * t), c, c + 4);
  const VerifyReport r2 = verify_output(o2, "duplicated2.tets");
  EXPECT_EQ(count(r2, Violation::kDuplicateTet), 1u) << r2.summary();
  expect_only(r2, {Violation::kDuplicateTet, Violation::kEuler, Violation::kVolume, Violation::kHullTopology});
}

// A 2-3 flip of a locally Delaunay facet: still a triangulation of the hull, but no
// longer Delaunay. Only the Delaunay check may fail.
TEST(Verify, DelaunayFlipUndone) {
  Output o = uniform_output();
  const Facets f(o.tets);
  bool done = false;
  for (const auto& [key, ts] : f.of) {
    if (ts.size() != 2) continue;
    const std::uint64_t a = key[0], b = key[1], c = key[2];
    auto apex = [&](std::size_t t) {
      for (int i = 0; i < 4; ++i) {
        const std::uint64_t l = o.tets[4 * t + std::size_t(i)];
        if (l != a && l != b && l != c) return l;
      }
      return std::uint64_t(0);
    };
    const std::uint64_t d = apex(ts[0]), e = apex(ts[1]);
    const int s1 = core::orient3d(o.p(a), o.p(b), o.p(d), o.p(e));
    const int s2 = core::orient3d(o.p(b), o.p(c), o.p(d), o.p(e));
    const int s3 = core::orient3d(o.p(c), o.p(a), o.p(d), o.p(e));
    if (s1 == 0 || s1 != s2 || s2 != s3) continue;  // segment de must cross abc's interior
    std::vector<std::array<std::uint64_t, 4>> add = {{a, b, d, e}, {b, c, d, e}, {c, a, d, e}};
    for (auto& t : add)
      if (core::orient3d(o.p(t[0]), o.p(t[1]), o.p(t[2]), o.p(t[3])) < 0) std::swap(t[0], t[1]);
    const std::size_t lo = std::min(ts[0], ts[1]), hi = std::max(ts[0], ts[1]);
    erase_tet(o.tets, hi);
    erase_tet(o.tets, lo);
    for (const auto& t : add) o.tets.insert(o.tets.end(), t.begin(), t.end());
    sort_by_min(o.tets);
    done = true;
    break;
  }
  ASSERT_TRUE(done);
  const VerifyReport r = verify_output(o, "flip23.tets");
  EXPECT_FALSE(r.ok());
  EXPECT_GT(count(r, Violation::kDelaunay), 0u) << r.summary();
  expect_only(r, {Violation::kDelaunay});
  EXPECT_EQ(r.euler, 1);
}

TEST(Verify, MissingHullTet) {
  Output o = uniform_output();
  const Facets f(o.tets);
  std::set<std::uint64_t> hull_vertices;
  for (const auto& [key, ts] : f.of)
    if (ts.size() == 1) hull_vertices.insert(key.begin(), key.end());
  // A tet with one hull facet and its fourth vertex inside: removing it dents the hull.
  auto inner_apex = [&](std::size_t t) {
    int inside = 0;
    for (int i = 0; i < 4; ++i) inside += hull_vertices.count(o.tets[4 * t + std::size_t(i)]) == 0;
    return inside == 1;
  };
  std::size_t t = o.tets.size() / 4 / 2;
  while (t < o.tets.size() / 4 && (f.hull_facets_of(o.tets, t) != 1 || !inner_apex(t))) ++t;
  ASSERT_LT(t, o.tets.size() / 4);
  erase_tet(o.tets, t);
  const VerifyReport r = verify_output(o, "missing_hull_tet.tets");
  EXPECT_FALSE(r.ok());
  EXPECT_GT(count(r, Violation::kHullConvex), 0u) << r.summary();
  // The dented surface is still one closed sphere and encloses exactly the tets.
  expect_only(r, {Violation::kHullConvex});
}

// On a grid the hull's flat faces must be triangulated as the perturbed 2D Delaunay
// triangulation (what infinite_conflict_sos says): flipping the diagonal of one hull
// square (a 2-2 flip of the two tets below it) leaves a valid triangulation of the
// hull, with coplanar hull facets that the perturbation rejects.
TEST(Verify, FlatHullFacesFollowThePerturbation) {
  Output o = triangulate(test::grid(5));
  ASSERT_TRUE(verify_output(o, "grid_ok.tets").ok());
  const Facets f(o.tets);
  auto apex = [&](std::size_t t, const std::array<std::uint64_t, 3>& k) {
    for (int i = 0; i < 4; ++i) {
      const std::uint64_t l = o.tets[4 * t + std::size_t(i)];
      if (std::find(k.begin(), k.end(), l) == k.end()) return l;
    }
    return std::uint64_t(0);
  };
  std::vector<std::pair<std::array<std::uint64_t, 3>, std::size_t>> hull;
  for (const auto& [key, ts] : f.of)
    if (ts.size() == 1) hull.push_back({key, ts[0]});
  bool done = false;
  for (std::size_t i = 0; i < hull.size() && !done; ++i)
    for (std::size_t j = i + 1; j < hull.size() && !done; ++j) {
      const auto& [k1, t1] = hull[i];
      const auto& [k2, t2] = hull[j];
      std::vector<std::uint64_t> common;
      std::set_intersection(k1.begin(), k1.end(), k2.begin(), k2.end(), std::back_inserter(common));
      if (common.size() != 2 || apex(t1, k1) != apex(t2, k2)) continue;
      const std::uint64_t p = common[0], r = common[1], x = apex(t1, k1);
      const std::uint64_t q = k1[0] + k1[1] + k1[2] - p - r, s = k2[0] + k2[1] + k2[2] - p - r;
      if (core::orient3d(o.p(p), o.p(q), o.p(r), o.p(s)) != 0) continue;  // coplanar hull facets
      // The flip is valid when p and r lie strictly on opposite sides of plane (q, s, x).
      const int sp = core::orient3d(o.p(q), o.p(s), o.p(x), o.p(p));
      const int sr = core::orient3d(o.p(q), o.p(s), o.p(x), o.p(r));
      if (sp == 0 || sp == sr) continue;
      std::vector<std::array<std::uint64_t, 4>> add = {{q, r, s, x}, {p, q, s, x}};
      for (auto& t : add)
        if (core::orient3d(o.p(t[0]), o.p(t[1]), o.p(t[2]), o.p(t[3])) < 0) std::swap(t[0], t[1]);
      erase_tet(o.tets, std::max(t1, t2));
      erase_tet(o.tets, std::min(t1, t2));
      for (const auto& t : add) o.tets.insert(o.tets.end(), t.begin(), t.end());
      sort_by_min(o.tets);
      done = true;
    }
  ASSERT_TRUE(done);
  const VerifyReport r = verify_output(o, "grid_flipped_hull.tets");
  EXPECT_FALSE(r.ok());
  EXPECT_GT(count(r, Violation::kHullConvex), 0u) << r.summary();
  EXPECT_NE(r.summary().find("coplanar"), std::string::npos) << r.summary();
  expect_only(r, {Violation::kHullConvex, Violation::kDelaunay});
  EXPECT_EQ(r.euler, 1);
  EXPECT_EQ(r.hull_euler, 2);
}

TEST(Verify, MissingPoint) {
  // Label 700 is in the container but not triangulated.
  const Output o = triangulate_without(test::uniform_cube(1500, 41), 700);
  const VerifyReport r = verify_output(o, "missing_point.tets");
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(count(r, Violation::kMissingPoint), 1u) << r.summary();
  bool listed = false;
  for (const auto& l : r.listed) listed |= l.kind == Violation::kMissingPoint && l.where == 700;
  EXPECT_TRUE(listed) << r.summary();
  // The triangulation of the others is valid; only the point's absence shows.
  expect_only(r, {Violation::kMissingPoint});
}

TEST(Verify, StorageAndOverusedFacets) {
  const Output& o = uniform_output();
  std::vector<std::uint64_t> tets = o.tets;
  tets[4 * 10 + 1] = tets[4 * 10];   // repeated label
  tets[4 * 20 + 3] = o.count() + 5;  // label out of range
  // A tet through an existing interior facet, with a far apex: that facet is now in
  // three tets.
  const Facets f(o.tets);
  for (const auto& [key, ts] : f.of) {
    if (ts.size() != 2) continue;
    // An apex far from the facet (not one of the two tets already on it).
    std::uint64_t apex = o.count() - 1;
    while (std::find(key.begin(), key.end(), apex) != key.end() || apex == o.tets[4 * ts[0]] ||
           apex == o.tets[4 * ts[0] + 1] || apex == o.tets[4 * ts[0] + 2] || apex == o.tets[4 * ts[0] + 3] ||
           apex == o.tets[4 * ts[1]] || apex == o.tets[4 * ts[1] + 1] || apex == o.tets[4 * ts[1] + 2] ||
           apex == o.tets[4 * ts[1] + 3])
      --apex;
    std::array<std::uint64_t, 4> t = {key[0], key[1], key[2], apex};
    if (core::orient3d(o.p(t[0]), o.p(t[1]), o.p(t[2]), o.p(t[3])) == 0) continue;
    if (core::orient3d(o.p(t[0]), o.p(t[1]), o.p(t[2]), o.p(t[3])) < 0) std::swap(t[0], t[1]);
    tets.insert(tets.end(), t.begin(), t.end());
    break;
  }
  pipeline::MemorySource src(o.xyz, tets, 1000);
  const VerifyReport r = pipeline::verify(src, quiet_options());
  EXPECT_EQ(count(r, Violation::kStorage), 2u) << r.summary();
  EXPECT_GT(count(r, Violation::kFacetOverused), 0u) << r.summary();
}

TEST(Verify, ListsFirstViolationsByOrdinal) {
  // Memory source: the ordinals are the positions in this list (a container stores
  // each frame's tets in its own canonical order).
  Output o = uniform_output();
  for (std::size_t t : {700u, 30u, 400u, 31u}) std::swap(o.tets[4 * t], o.tets[4 * t + 1]);
  VerifyOptions v = quiet_options();
  v.max_listed = 3;
  pipeline::MemorySource src(o.xyz, o.tets, 256);
  const VerifyReport r = pipeline::verify(src, v);
  EXPECT_EQ(count(r, Violation::kOrientation), 4u);
  std::vector<std::uint64_t> where;
  for (const auto& l : r.listed)
    if (l.kind == Violation::kOrientation) where.push_back(l.where);
  EXPECT_EQ(where, (std::vector<std::uint64_t>{30, 31, 400}));
  EXPECT_NE(r.summary().find("tet #30"), std::string::npos) << r.summary();
}

// ---------------------------------------------------------------------------------
// Sample mode.

TEST(Verify, SampleChecksAFraction) {
  const Output& o = uniform_output();
  const std::string path = write_container(o, "sample.tets");
  VerifyOptions v = quiet_options();
  v.sample = 0.25;
  const VerifyReport r = pipeline::verify_file(path, v);
  EXPECT_TRUE(r.ok()) << r.summary();
  EXPECT_TRUE(r.sampled);
  const double t = double(r.tets);
  EXPECT_NEAR(double(r.tets_checked), 0.25 * t, 0.05 * t);
  EXPECT_NEAR(double(r.facets_checked), 0.25 * 4 * t, 0.05 * 4 * t);
  EXPECT_EQ(r.hull_tests, 0u);
  // Every sampled facet is either paired or unpaired (on the hull): none is split.
  EXPECT_EQ(2 * r.interior_facets + r.boundary_facets, r.facets_checked);
  // The sample is seeded: the same seed, the same sample.
  const VerifyReport again = pipeline::verify_file(path, v);
  EXPECT_EQ(again.facets_checked, r.facets_checked);
  EXPECT_EQ(again.tets_checked, r.tets_checked);
}

TEST(Verify, SampleStillSeesEveryPoint) {
  const Output o = triangulate_without(test::uniform_cube(800, 43), 123);
  VerifyOptions v = quiet_options();
  v.sample = 0.01;
  const VerifyReport r = verify_output(o, "sample_missing.tets", v);
  EXPECT_EQ(count(r, Violation::kMissingPoint), 1u) << r.summary();
}

TEST(Verify, SampleFindsAnUndoneFlipWhenItsFacetIsSampled) {
  // With a sample close to 1, a broken facet is almost surely in it.
  Output o = uniform_output();
  const std::size_t t = 100;
  std::swap(o.tets[4 * t + 2], o.tets[4 * t + 3]);
  VerifyOptions v = quiet_options();
  v.sample = 0.999;
  const VerifyReport r = verify_output(o, "sample_flip.tets", v);
  EXPECT_EQ(count(r, Violation::kOrientation), 1u) << r.summary();
}

// The fuzz tier's rewritten-but-checksummed containers (docs/safety.md): a container
// whose tets were edited and then written with valid CRCs passes every reader check,
// so `verify` alone must catch it. Seeded edits of the kinds a bug or a hand could
// make: a vertex replaced, two vertices swapped (orientation), a tet dropped or
// doubled, a tet moved onto a neighbour's vertex set; on grid (degenerate) and
// uniform points. Every one must be rejected. TETSTREAM_TEST_SEED replays one seed.
TEST(Verify, RewrittenButChecksummedTetsAreCaught) {
  const char* env = std::getenv("TETSTREAM_TEST_SEED");
  const std::uint64_t first = env ? std::strtoull(env, nullptr, 10) : 1, last = env ? first : 60;
  static const Output grid = triangulate(test::grid(7));
  for (std::uint64_t seed = first; seed <= last; ++seed) {
    SCOPED_TRACE("TETSTREAM_TEST_SEED=" + std::to_string(seed));
    std::mt19937_64 g(seed);
    Output o = seed % 3 == 0 ? grid : uniform_output();
    const std::size_t tets = o.tets.size() / 4, t = g() % tets, k = g() % 4;
    std::string edit;
    switch (g() % 5) {
      case 0: {  // a vertex replaced by another point
        std::uint64_t v;
        do v = g() % o.count();
        while (v == o.tets[4 * t + k]);
        o.tets[4 * t + k] = v;
        edit = "replaced a vertex";
        break;
      }
      case 1:
        std::swap(o.tets[4 * t + k], o.tets[4 * t + (k + 1) % 4]);
        edit = "swapped two vertices";
        break;
      case 2:
        erase_tet(o.tets, t);
        edit = "dropped a tet";
        break;
      case 3:
        o.tets.insert(o.tets.end(), o.tets.begin() + std::ptrdiff_t(4 * t), o.tets.begin() + std::ptrdiff_t(4 * t + 4));
        sort_by_min(o.tets);
        edit = "doubled a tet";
        break;
      default: {  // the vertex opposite a facet moved to the other side's apex
        const std::size_t u = (t + 1 + g() % (tets - 1)) % tets;
        o.tets[4 * t + k] = o.tets[4 * u + g() % 4];
        edit = "copied a vertex of another tet";
        break;
      }
    }
    SCOPED_TRACE(edit);
    const VerifyReport r = verify_output(o, "rewritten-" + std::to_string(seed) + ".tets");
    EXPECT_FALSE(r.ok()) << r.summary();
  }
}

// A distributed verify (K ranks as threads, tests/unit/thread_ranks.hpp) gives one
// process's report: counts, violations listed (kind, ordinal, text), volumes to the
// bit, on correct outputs and on the edits above (at random and near the middle,
// where the ranks hand records over), frames of 200 tets in steps of 64, stored in
// order or in reverse.
void expect_same_report(const VerifyReport& a, const VerifyReport& b) {
  EXPECT_EQ(a.ok(), b.ok());
  EXPECT_EQ(a.counts, b.counts);
  ASSERT_EQ(a.listed.size(), b.listed.size()) << a.summary() << "\n" << b.summary();
  for (std::size_t i = 0; i < a.listed.size(); ++i) {
    EXPECT_EQ(a.listed[i].kind, b.listed[i].kind);
    EXPECT_EQ(a.listed[i].where, b.listed[i].where);
    EXPECT_EQ(a.listed[i].text, b.listed[i].text);
  }
  EXPECT_EQ(std::make_tuple(a.points, a.tets, a.vertices, a.facets, a.interior_facets, a.boundary_facets, a.edges,
                            a.hull_vertices, a.hull_edges, a.euler, a.hull_euler),
            std::make_tuple(b.points, b.tets, b.vertices, b.facets, b.interior_facets, b.boundary_facets, b.edges,
                            b.hull_vertices, b.hull_edges, b.euler, b.hull_euler));
  EXPECT_EQ(std::make_tuple(a.orient_tests, a.insphere_tests, a.hull_tests, a.tets_checked, a.facets_checked),
            std::make_tuple(b.orient_tests, b.insphere_tests, b.hull_tests, b.tets_checked, b.facets_checked));
  EXPECT_EQ(std::make_tuple(a.tet_volume, a.hull_volume, a.volume_rel_error),
            std::make_tuple(b.tet_volume, b.hull_volume, b.volume_rel_error));
}

// The step (tets merged into the open sets at a time) is planned from --memory: a small
// budget takes smaller steps, and neither the step nor the budget changes the report,
// violations listed included.
TEST(Verify, StepsDoNotChangeTheReport) {
  static const Output o = triangulate(test::uniform_cube(20000, 5));
  std::vector<std::uint64_t> tets = o.tets;
  for (std::size_t t : {17u, 9000u, 64000u}) std::swap(tets[4 * t], tets[4 * t + 1]);  // flipped
  tets.insert(tets.end(), tets.begin() + 4 * 5000, tets.begin() + 4 * 5001);           // repeated
  erase_tet(tets, 30000);                                                              // a hole
  const std::size_t n_tets = tets.size() / 4;
  pipeline::MemorySource src(o.xyz, tets, n_tets);  // one frame of all the tets
  const VerifyReport whole = pipeline::verify(src, quiet_options());
  EXPECT_EQ(whole.step_tets, n_tets);
  EXPECT_FALSE(whole.ok());
  EXPECT_EQ(count(whole, Violation::kOrientation), 3u) << whole.summary();

  VerifyOptions small = quiet_options();
  small.memory_bytes = 16 << 20;  // 2 x the scratch of a whole-frame step is more
  const VerifyReport halved = pipeline::verify(src, small);
  EXPECT_LT(halved.step_tets, n_tets);
  EXPECT_GE(halved.step_tets, std::uint64_t(1) << 14);
  expect_same_report(whole, halved);

  VerifyOptions steps = quiet_options();
  steps.batch_tets = 1000;
  const VerifyReport small_steps = pipeline::verify(src, steps);
  EXPECT_EQ(small_steps.step_tets, 1000u);
  expect_same_report(whole, small_steps);
}

TEST(Verify, RanksGiveOneProcesssReport) {
  static const Output grid = triangulate(test::grid(7));
  for (std::uint64_t seed = 0; seed <= 24; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    std::mt19937_64 g(seed);
    Output o = seed % 3 == 0 ? grid : uniform_output();
    const std::size_t tets = o.tets.size() / 4;
    const std::size_t t = seed % 2 ? g() % tets : tets / 2 - 40 + g() % 80, k = g() % 4;
    switch (seed == 0 ? 9 : g() % 5) {
      case 0:
        o.tets[4 * t + k] = (o.tets[4 * t + k] + 1 + g() % (o.count() - 1)) % o.count();
        break;
      case 1:
        std::swap(o.tets[4 * t + k], o.tets[4 * t + (k + 1) % 4]);
        break;
      case 2:
        erase_tet(o.tets, t);
        break;
      case 3:
        o.tets.insert(o.tets.end(), o.tets.begin() + std::ptrdiff_t(4 * t), o.tets.begin() + std::ptrdiff_t(4 * t + 4));
        sort_by_min(o.tets);
        break;
      case 4:
        o.tets[4 * t + k] = o.tets[4 * ((t + 1 + g() % (tets - 1)) % tets) + g() % 4];
        break;
      default:
        break;  // seed 0: the correct output
    }
    if (seed % 4 == 2) {
      // Frames stored in reverse (a writer's order need not be the visiting order):
      // ordinals then run against the steps in which one process meets the records.
      // Whole frames of 200 tets (800 labels) move; the short last frame stays last.
      const std::size_t whole = o.tets.size() / 800 * 800;
      std::vector<std::uint64_t> reversed;
      for (std::size_t begin = whole; begin > 0; begin -= 800)
        reversed.insert(reversed.end(), o.tets.begin() + std::ptrdiff_t(begin - 800),
                        o.tets.begin() + std::ptrdiff_t(begin));
      reversed.insert(reversed.end(), o.tets.begin() + std::ptrdiff_t(whole), o.tets.end());
      o.tets = std::move(reversed);
    }
    const pipeline::MemorySource source(o.xyz, o.tets, 200);
    VerifyOptions v = quiet_options();
    v.batch_tets = 64;
    v.sample = seed % 8 == 5 ? 0.5 : 1.0;
    v.wide_labels = seed % 5 == 4;  // the 64-bit records travel too
    const VerifyReport one = pipeline::verify(source, v);
    for (int ranks : {2, 3}) {
      SCOPED_TRACE(std::to_string(ranks) + " ranks");
      std::vector<VerifyReport> reports(static_cast<std::size_t>(ranks));
      test::run_ranks(ranks, [&](pipeline::Communicator& comm) {
        reports[std::size_t(comm.rank())] = pipeline::verify(source, v, comm);
      });
      expect_same_report(one, reports[0]);
      for (const VerifyReport& r : reports) EXPECT_EQ(r.counts, one.counts);  // every rank knows the verdict
    }
  }
}

TEST(Verify, BadOptions) {
  VerifyOptions v;
  v.sample = 0;
  EXPECT_THROW(v.validate(), UsageError);
  v.sample = 1.5;
  EXPECT_THROW(v.validate(), UsageError);
  v.sample = 1;
  v.memory_bytes = 1000;
  EXPECT_THROW(v.validate(), UsageError);
}

TEST(Verify, DamagedContainerIsAnInputError) {
  const std::string path = write_container(uniform_output(), "damaged.tets");
  fs::resize_file(path, fs::file_size(path) - 10);
  EXPECT_THROW(pipeline::verify_file(path, quiet_options()), InputError);
}

// ---------------------------------------------------------------------------------
// The external sort.

struct Rec {
  std::uint64_t key;
  std::uint32_t seq;
  std::uint32_t pad;
};
struct RecLess {
  bool operator()(const Rec& a, const Rec& b) const { return a.key < b.key; }
};

TEST(ExternalSort, InMemoryAndSpilledAgree) {
  for (std::size_t memory : {std::size_t(64) << 20, std::size_t(64) << 10}) {
    SCOPED_TRACE(memory);
    pipeline::TempDir tmp(temp().dir().string(), "xsort");
    pipeline::ExternalSortOptions o;
    o.memory_bytes = memory;
    o.dir = tmp.dir();
    o.min_block_bytes = 4096;  // small budget: many runs and several merge passes
    o.batch_records = 1000;
    pipeline::ExternalSorter<Rec, RecLess> s(o);
    std::mt19937_64 g(7);
    std::vector<Rec> in(200000);
    for (std::uint32_t i = 0; i < in.size(); ++i) in[i] = {g() % 50000, i, 0};
    for (std::size_t i = 0; i < 1000; ++i) s.push(in[i]);
    s.push(std::span<const Rec>(in).subspan(1000));
    std::vector<Rec> out;
    s.merge([&](std::span<const Rec> b) {
      EXPECT_LE(b.size(), 1000u);
      out.insert(out.end(), b.begin(), b.end());
    });
    ASSERT_EQ(out.size(), in.size());
    std::vector<Rec> ref = in;
    std::stable_sort(ref.begin(), ref.end(), RecLess());
    for (std::size_t i = 0; i < out.size(); ++i) ASSERT_EQ(out[i].key, ref[i].key) << i;
    if (memory < (1 << 20)) {
      EXPECT_GT(s.stats().runs_written, 2u);
      EXPECT_GT(s.stats().merge_passes, 0u);
    } else {
      EXPECT_EQ(s.stats().runs_written, 0u);
    }
    // Runs are deleted once merged.
    // The sorter removed its runs: what is left is the work directory's own lock and marker.
    for (const auto& e : fs::directory_iterator(tmp.dir())) {
      const std::string name = e.path().filename().string();
      EXPECT_TRUE(name == pipeline::WorkDir::kLock || name == pipeline::WorkDir::kMarker) << name;
    }
  }
}

// A merge of spilled runs can take minutes: it polls for Ctrl-C / SIGTERM between its
// batches (sequential and in rounds) and unwinds with Interrupted, the runs removed.
TEST(ExternalSort, MergeStopsWhenInterrupted) {
  const int threads = omp_get_max_threads();
  for (int t : {1, 2}) {
    SCOPED_TRACE(t);
    omp_set_num_threads(t);
    pipeline::TempDir tmp(temp().dir().string(), "xsort-interrupt");
    std::size_t batches = 0;
    {
      pipeline::ExternalSortOptions o;
      o.memory_bytes = std::size_t(64) << 10;
      o.dir = tmp.dir();
      o.min_block_bytes = 4096;
      o.batch_records = 1000;
      pipeline::ExternalSorter<Rec, RecLess> s(o);
      std::mt19937_64 g(3);
      for (std::uint32_t i = 0; i < 100000; ++i) s.push(Rec{g() % 50000, i, 0});
      ASSERT_TRUE(s.spilled());
      EXPECT_THROW(s.merge([&](std::span<const Rec>) {
        if (++batches == 1) pipeline::request_interrupt(SIGTERM);  // as the handler does
      }),
                   pipeline::Interrupted);
    }
    pipeline::clear_interrupt();
    EXPECT_EQ(batches, 1u);  // stopped at the next batch, not at the end
    for (const auto& e : fs::directory_iterator(tmp.dir())) {
      const std::string name = e.path().filename().string();
      EXPECT_TRUE(name == pipeline::WorkDir::kLock || name == pipeline::WorkDir::kMarker) << name;
    }
  }
  omp_set_num_threads(threads);
}

TEST(ExternalSort, ReducerAndSortedRunsAndTies) {
  pipeline::TempDir tmp(temp().dir().string(), "xsort");
  pipeline::ExternalSortOptions o;
  o.memory_bytes = 1 << 20;
  o.dir = tmp.dir();
  pipeline::ExternalSorter<std::uint64_t, std::less<std::uint64_t>> s(o);
  s.set_reducer([](std::uint64_t* f, std::size_t n) { return std::size_t(std::unique(f, f + n) - f); });
  std::vector<std::uint64_t> in;
  for (std::uint64_t i = 0; i < 300000; ++i) in.push_back((i * 7919) % 1000);
  s.push(std::span<const std::uint64_t>(in));
  std::vector<std::uint64_t> sorted_run = {5, 5, 6, 2000};
  s.push_sorted_run(std::span<std::uint64_t>(sorted_run));
  std::vector<std::uint64_t> out;
  s.merge([&](std::span<const std::uint64_t> b) { out.insert(out.end(), b.begin(), b.end()); });
  EXPECT_TRUE(std::is_sorted(out.begin(), out.end()));
  out.erase(std::unique(out.begin(), out.end()), out.end());
  EXPECT_EQ(out.size(), 1001u);  // 0..999 and 2000
  EXPECT_GT(s.stats().runs_written, 1u);

  // Ties: records equal under Less come out in push order of their runs.
  pipeline::ExternalSortOptions o2;
  o2.memory_bytes = 1 << 20;
  o2.make_dir = [&] { return tmp.dir(); };
  pipeline::ExternalSorter<Rec, RecLess> t(o2);
  std::vector<Rec> r1 = {{1, 0, 0}, {2, 1, 0}}, r2 = {{1, 2, 0}, {2, 3, 0}};
  t.push_sorted_run(std::span<Rec>(r1));
  t.push_sorted_run(std::span<Rec>(r2));
  std::vector<std::uint32_t> seq;
  t.merge([&](std::span<const Rec> b) {
    for (const Rec& r : b) seq.push_back(r.seq);
  });
  EXPECT_EQ(seq, (std::vector<std::uint32_t>{0, 2, 1, 3}));
}

// give_back_runs: the merge punches holes behind its reads, so runs that a resumable
// job keeps (keep_files) hold no blocks once merged; the records come out the same.
TEST(ExternalSort, GivesBackRunsAsItMerges) {
  pipeline::TempDir tmp(temp().dir().string(), "xsort-give-back");
  pipeline::ExternalSortOptions o;
  o.memory_bytes = std::size_t(16) << 20;
  o.dir = tmp.dir();
  o.keep_files = true;
  pipeline::ExternalSorter<std::uint64_t, std::less<std::uint64_t>> s(o);
  std::vector<std::string> runs;
  std::vector<std::uint64_t> run(std::size_t(3) << 20);  // 24 MiB a run: given back in steps and at its end
  for (std::uint64_t r = 0; r < 3; ++r) {
    for (std::size_t i = 0; i < run.size(); ++i) run[i] = 3 * i + r;
    s.push_sorted_run(std::span<std::uint64_t>(run));
    runs.push_back(s.last_run_path());
  }
  s.set_give_back_runs(true);
  std::uint64_t next = 0;
  s.merge([&](std::span<const std::uint64_t> b) {
    for (std::uint64_t v : b) ASSERT_EQ(v, next++);
  });
  EXPECT_EQ(next, 3 * run.size());
  for (const std::string& path : runs) {
    struct stat st {};
    ASSERT_EQ(::stat(path.c_str(), &st), 0) << "keep_files: the run stays, as a hole";
    EXPECT_EQ(std::uint64_t(st.st_size), run.size() * 8) << "the size is kept";
    // Where the filesystem cannot punch (EOPNOTSUPP) the blocks stay: nothing to check.
    if (std::uint64_t(st.st_blocks) * 512 < run.size() * 8) {
      EXPECT_EQ(st.st_blocks, 0) << path << ": blocks left after the merge read it all";
    }
  }
}

TEST(ExternalSort, ParallelSortSorts) {
  std::mt19937_64 g(3);
  std::vector<std::uint64_t> v(1 << 20);
  for (auto& x : v) x = g() % 1000;
  std::vector<std::uint64_t> ref = v;
  std::sort(ref.begin(), ref.end());
  pipeline::parallel_sort(v.data(), v.data() + v.size(), std::less<std::uint64_t>());
  EXPECT_EQ(v, ref);
}

TEST(ExternalSort, RadixSortIsStable) {
  for (std::size_t n : {std::size_t(100), std::size_t(5000), std::size_t(300000)}) {
    SCOPED_TRACE(n);
    std::mt19937_64 g(n);
    std::vector<Rec> v(n), tmp;
    for (std::uint32_t i = 0; i < n; ++i) v[i] = {g() % 3000 + (std::uint64_t(1) << 40), i, 0};  // constant high digits
    std::vector<Rec> ref = v;
    std::stable_sort(ref.begin(), ref.end(), RecLess());
    pipeline::radix_sort(v.data(), v.size(), tmp, 48, [](const Rec& r) { return r.key; });
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(v[i].key, ref[i].key) << i;
      ASSERT_EQ(v[i].seq, ref[i].seq) << i;
    }
  }
}

}  // namespace
}  // namespace tetstream
