// `tetstream field` (pipeline/field.hpp) against a direct in-memory computation from
// the same container, done differently: hull points from facets seen once, Voronoi
// volumes from the Voronoi facets (polygons of the circumcentres around each Delaunay
// edge, ordered by angle) instead of the per-tet pieces, neighbours from a set of
// edges, the grid by a brute-force scan of every tet with barycentric coordinates.
#include "core/error.hpp"
#include "io/point_generators.hpp"
#include "io/point_writer.hpp"
#include "io/tet_reader.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/field/field.hpp"
#include "pipeline/field/geometry.hpp"
#include "pipeline/field/neighbours.hpp"
#include "pipeline/run/run.hpp"

#include "scratch_dir.hpp"
#include "tet_sets.hpp"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <numeric>
#include <set>
#include <string>
#include <type_traits>
#include <vector>

namespace tetstream {
namespace {

using Vec = std::array<double, 3>;
Vec sub(const Vec& a, const Vec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double dot(const Vec& a, const Vec& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec cross(const Vec& a, const Vec& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}

std::vector<char> file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

// The data of a v1.0 .npy file (header skipped) as T.
template <class T>
std::vector<T> load_npy(const std::string& path) {
  const std::vector<char> b = file_bytes(path);
  EXPECT_GE(b.size(), 10u) << path;
  if (b.size() < 10) return {};
  const std::size_t hl = std::uint8_t(b[8]) | std::size_t(std::uint8_t(b[9])) << 8;
  // The array's type must be T's: an int32 file read as int64 would pass no test.
  const char* descr = std::is_floating_point_v<T> ? (sizeof(T) == 4 ? "<f4" : "<f8") : (sizeof(T) == 4 ? "<i4" : "<i8");
  EXPECT_NE(std::string(b.data() + 10, std::min(hl, b.size() - 10)).find(std::string("'descr': '") + descr + "'"),
            std::string::npos)
      << path << " is not " << descr;
  std::vector<T> out((b.size() - 10 - hl) / sizeof(T));
  std::memcpy(out.data(), b.data() + 10 + hl, out.size() * sizeof(T));
  return out;
}

// Everything of a container in memory, and the reference fields by label.
struct Reference {
  std::size_t n = 0;
  std::vector<Vec> xyz;
  std::vector<std::uint64_t> ids, tets;
  std::vector<double> volume, voronoi;
  std::vector<bool> hull;
  std::vector<std::set<std::uint64_t>> neighbours;  // labels

  explicit Reference(const std::string& path) {
    io::TetReader r(path);
    n = std::size_t(r.point_count());
    xyz.resize(n);
    ids.resize(n);
    r.read_points(0, n, xyz[0].data(), ids.data());
    std::vector<std::uint64_t> f;
    for (std::uint64_t k = 0; k < r.frame_count(); ++k) {
      r.read_frame(k, f);
      tets.insert(tets.end(), f.begin(), f.end());
    }
    compute();
  }

  double tet_volume(const std::uint64_t* q) const {
    return dot(sub(xyz[q[1]], xyz[q[0]]), cross(sub(xyz[q[2]], xyz[q[0]]), sub(xyz[q[3]], xyz[q[0]]))) / 6.0;
  }

  // Circumcentre by solving 2 (p_i - p_0) . x = |p_i|^2 - |p_0|^2 (relative to p_0) with Cramer's rule.
  Vec circumcentre(const std::uint64_t* q) const {
    Vec r[3];
    double rhs[3];
    for (int i = 0; i < 3; ++i) r[i] = sub(xyz[q[i + 1]], xyz[q[0]]), rhs[i] = dot(r[i], r[i]) / 2;
    const double d = dot(r[0], cross(r[1], r[2]));
    Vec c;
    for (int k = 0; k < 3; ++k) {
      Vec m[3] = {r[0], r[1], r[2]};
      for (int i = 0; i < 3; ++i) m[i][std::size_t(k)] = rhs[i];
      c[std::size_t(k)] = dot(m[0], cross(m[1], m[2])) / d;
    }
    return {c[0] + xyz[q[0]][0], c[1] + xyz[q[0]][1], c[2] + xyz[q[0]][2]};
  }

  void compute() {
    volume.assign(n, 0.0);
    voronoi.assign(n, 0.0);
    hull.assign(n, false);
    neighbours.assign(n, {});
    std::map<std::array<std::uint64_t, 3>, int> faces;
    std::map<std::pair<std::uint64_t, std::uint64_t>, std::vector<Vec>> rings;
    for (std::size_t t = 0; t < tets.size(); t += 4) {
      const std::uint64_t* q = &tets[t];
      const double v = tet_volume(q);
      const Vec c = circumcentre(q);
      for (int i = 0; i < 4; ++i) {
        volume[q[i]] += v;
        std::array<std::uint64_t, 3> f;
        for (int j = 0, k = 0; j < 4; ++j)
          if (j != i) f[std::size_t(k++)] = q[j];
        std::sort(f.begin(), f.end());
        ++faces[f];
        for (int j = i + 1; j < 4; ++j) {
          neighbours[q[i]].insert(q[j]);
          neighbours[q[j]].insert(q[i]);
          rings[{std::min(q[i], q[j]), std::max(q[i], q[j])}].push_back(c);
        }
      }
    }
    for (const auto& [f, count] : faces)
      if (count == 1) hull[f[0]] = hull[f[1]] = hull[f[2]] = true;
    // Pyramids over the Voronoi facets: (1/3) (|pq| / 2) area(polygon of the ring's centres).
    for (const auto& [e, centres] : rings) {
      if (hull[e.first] && hull[e.second]) continue;  // may be a hull edge; its endpoints are not checked
      const Vec axis = sub(xyz[e.second], xyz[e.first]);
      const double len = std::sqrt(dot(axis, axis));
      Vec o{0, 0, 0};
      for (const Vec& c : centres)
        for (int k = 0; k < 3; ++k) o[std::size_t(k)] += c[std::size_t(k)] / double(centres.size());
      Vec u = cross(axis, std::fabs(axis[0]) < 0.5 * len ? Vec{1, 0, 0} : Vec{0, 1, 0});
      const double lu = std::sqrt(dot(u, u));
      for (double& x : u) x /= lu;
      Vec w = cross(axis, u);
      for (double& x : w) x /= len;
      std::vector<std::pair<double, Vec>> ring;
      for (const Vec& c : centres) ring.push_back({std::atan2(dot(sub(c, o), w), dot(sub(c, o), u)), c});
      std::sort(ring.begin(), ring.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
      Vec s{0, 0, 0};
      for (std::size_t i = 0; i < ring.size(); ++i) {
        const Vec x = cross(sub(ring[i].second, o), sub(ring[(i + 1) % ring.size()].second, o));
        for (int k = 0; k < 3; ++k) s[std::size_t(k)] += x[std::size_t(k)];
      }
      const double area = std::sqrt(dot(s, s)) / 2;
      voronoi[e.first] += area * len / 6;
      voronoi[e.second] += area * len / 6;
    }
  }

  // Label order -> input order: positions sorted by original index.
  std::vector<std::size_t> input_order() const {
    std::vector<std::size_t> o(n);
    std::iota(o.begin(), o.end(), 0);
    std::sort(o.begin(), o.end(), [&](std::size_t a, std::size_t b) { return ids[a] < ids[b]; });
    return o;
  }
};

class FieldTest : public testing_util::ScratchDirTest {
 protected:
  FieldTest() : ScratchDirTest("field-test") {}

  // gen -> run (out of core, several zones) -> the container rewritten with small
  // frames, so a field job has many frames and batches to combine.
  // duplicate_every k > 0: every k-th point is a copy of the one before it (`run` merges
  // it: the container's original indices have gaps).
  std::string container(io::Distribution dist, std::uint64_t n, std::uint64_t seed, std::uint32_t frame_tets = 3000,
                        std::uint64_t duplicate_every = 0) {
    std::vector<double> points = testing_util::generated_points(dist, n, seed);
    for (std::size_t i = duplicate_every; duplicate_every && i < n; i += duplicate_every)
      std::copy_n(&points[3 * (i - 1)], 3, &points[3 * i]);
    testing_util::write_points_file(path("points.f64"), points);
    pipeline::RunOptions o;
    o.input = path("points.f64");
    o.output = path("run.tets");
    o.memory_bytes = std::uint64_t(256) << 20;
    o.segment_points = 4000;
    o.progress = false;
    o.checkpoint = false;
    pipeline::run_job(o);
    // Rewrite with small frames (same points, same tets, same order).
    io::TetReader r(o.output);
    const std::size_t np = std::size_t(r.point_count());
    std::vector<double> p(3 * np);
    std::vector<std::uint64_t> ids(np), t, all;
    r.read_points(0, np, p.data(), ids.data());
    for (std::uint64_t k = 0; k < r.frame_count(); ++k) r.read_frame(k, t), all.insert(all.end(), t.begin(), t.end());
    io::TetWriterOptions wo;
    wo.frame_tets = frame_tets;
    wo.sync = false;
    io::TetWriter tw(path("small.tets"), r.header(), wo);
    tw.add_points(p.data(), ids.data(), np);
    tw.add_tets(std::span<const std::uint64_t>(all));
    tw.finish();
    return path("small.tets");
  }

  pipeline::FieldSummary fields(const std::string& input, const std::string& prefix, bool grid = false,
                                pipeline::HullMode hull = pipeline::HullMode::kNan, std::uint64_t memory = 256,
                                std::uint64_t batch_tets = 5000, std::uint64_t ring = 1024) {
    pipeline::FieldOptions o;
    o.input = input;
    o.output = path(prefix);
    o.density = o.voronoi = o.neighbours = true;
    if (grid) o.grid = {32, 32, 32};
    o.hull = hull;
    o.memory_bytes = memory << 20;
    o.batch_tets = batch_tets;
    o.ring_labels = ring;  // far smaller than N: labels beyond the ring are exercised
    o.progress = false;
    o.tmpdir = dir_.string();
    return pipeline::compute_fields(o);
  }

  // Every output against the reference; returns the reference.
  pipeline::FieldSummary check_against_reference(const std::string& tets, double voronoi_tolerance) {
    const Reference ref(tets);
    const pipeline::FieldSummary s = fields(tets, "f");
    const auto order = ref.input_order();
    const auto rho = load_npy<double>(path("f.density.npy"));
    const auto vor = load_npy<double>(path("f.voronoi.npy"));
    // int32: every offset and index fits (the default, --index-dtype auto).
    const auto off = load_npy<std::int32_t>(path("f.neighbours.offsets.npy"));
    const auto idx = load_npy<std::int32_t>(path("f.neighbours.indices.npy"));
    EXPECT_EQ(s.neighbour_dtype, "int32");
    EXPECT_EQ(rho.size(), ref.n);
    EXPECT_EQ(vor.size(), ref.n);
    EXPECT_EQ(off.size(), ref.n + 1);
    if (rho.size() != ref.n || vor.size() != ref.n || off.size() != ref.n + 1) return s;
    std::size_t hull = 0, interior = 0;
    double worst = 0;
    for (std::size_t i = 0; i < ref.n; ++i) {
      const std::size_t l = order[i];
      hull += ref.hull[l];
      if (ref.hull[l]) {
        EXPECT_TRUE(std::isnan(rho[i])) << "hull point " << l;
        EXPECT_TRUE(std::isinf(vor[i])) << "hull point " << l;
      } else {
        ++interior;
        EXPECT_NEAR(rho[i], 4.0 / ref.volume[l], 1e-12 * rho[i]) << "point " << l;
        worst = std::max(worst, std::fabs(vor[i] - ref.voronoi[l]) / ref.voronoi[l]);
        EXPECT_NEAR(vor[i], ref.voronoi[l], voronoi_tolerance * ref.voronoi[l]) << "point " << l;
      }
      std::vector<std::int64_t> want;
      for (const std::uint64_t q : ref.neighbours[l]) want.push_back(std::int64_t(ref.ids[q]));
      std::sort(want.begin(), want.end());
      const std::vector<std::int64_t> got(idx.begin() + off[i], idx.begin() + off[i + 1]);
      EXPECT_EQ(got, want) << "neighbours of point " << l;
    }
    EXPECT_EQ(s.hull_points, hull);
    EXPECT_GT(interior, ref.n / 2);
    // Every tet's Voronoi pieces tile it: all points' sums (hull ones included) add up
    // to the hull's volume.
    EXPECT_NEAR(s.voronoi_total, s.tet_volume, 1e-9 * s.tet_volume);
    std::printf("  %zu points, %zu on the hull, worst relative Voronoi difference %.3g\n", ref.n, hull, worst);
    return s;
  }
};

// Voronoi tolerances: 1e-12 where the cells are well shaped; clustered points make
// near-flat tets whose far circumcentres cancel in the sums (measured worst 1.3e-10).
TEST_F(FieldTest, UniformMatchesReference) {
  const auto s = check_against_reference(container(io::Distribution::kUniform, 10000, 11), 1e-12);
  EXPECT_GT(s.far_labels_peak, 0u);  // hull tets reach beyond the 1024-label ring
}

TEST_F(FieldTest, ClusteredMatchesReference) {
  const auto s = check_against_reference(container(io::Distribution::kClusters, 10000, 12), 1e-9);
  EXPECT_GT(s.far_labels_peak, 0u);
}

// --neighbours alone computes no solid angles: its hull flag comes from the rows (an
// interior point's T tets and d neighbours satisfy T = 2 d - 4). Against the facets
// seen once and the angle-based flag of a full job, on a lattice too (points on the
// hull's facets and edges), with far labels and many batches; the same volume bits,
// and the same neighbour files as the full job's.
TEST_F(FieldTest, NeighboursAloneHullFromRows) {
  struct Case {
    io::Distribution dist;
    std::uint64_t n, seed;
  };
  for (const Case c : {Case{io::Distribution::kUniform, 8000, 31}, Case{io::Distribution::kClusters, 8000, 32},
                       Case{io::Distribution::kGrid, 4096, 33}}) {
    const std::string tets = container(c.dist, c.n, c.seed);
    const Reference ref(tets);
    const std::size_t hull = std::size_t(std::count(ref.hull.begin(), ref.hull.end(), true));
    const pipeline::FieldSummary all = fields(tets, "all");
    pipeline::FieldOptions o;
    o.input = tets;
    o.output = path("alone");
    o.neighbours = true;
    o.memory_bytes = std::uint64_t(256) << 20;
    o.batch_tets = 5000;
    o.ring_labels = 1024;
    o.progress = false;
    o.tmpdir = dir_.string();
    const pipeline::FieldSummary alone = pipeline::compute_fields(o);
    if (c.dist != io::Distribution::kGrid) {
      EXPECT_GT(alone.far_labels_peak, 0u);  // the lattice's window fits the ring
    }
    EXPECT_GT(hull, 0u);
    EXPECT_EQ(all.hull_points, hull);
    EXPECT_EQ(alone.hull_points, hull);
    EXPECT_EQ(alone.tet_volume, all.tet_volume);  // the same sums, bit for bit
    for (const char* what : {"neighbours.offsets", "neighbours.indices"})
      EXPECT_EQ(file_bytes(path(std::string("all.") + what + ".npy")),
                file_bytes(path(std::string("alone.") + what + ".npy")))
          << what;
  }
}

// A lattice: cospherical and coplanar points everywhere, decided by the perturbation.
// Every interior cell is exactly the lattice's cube (h^3), whatever the tets.
TEST_F(FieldTest, LatticeInteriorCellsAreCubes) {
  const std::string tets = container(io::Distribution::kGrid, 9261, 13);  // 21^3
  check_against_reference(tets, 1e-12);
  const Reference ref(tets);
  const auto vor = load_npy<double>(path("f.voronoi.npy"));
  const auto order = ref.input_order();
  double h = 1e300;  // the lattice spacing: the smallest coordinate gap along x
  for (std::size_t i = 1; i < ref.n; ++i)
    if (const double d = std::fabs(ref.xyz[i][0] - ref.xyz[0][0]); d > 0) h = std::min(h, d);
  std::size_t checked = 0;
  for (std::size_t i = 0; i < ref.n; ++i)
    if (!ref.hull[order[i]]) {
      EXPECT_NEAR(vor[i], h * h * h, 1e-12 * h * h * h) << "point " << order[i];
      ++checked;
    }
  EXPECT_EQ(checked, std::size_t(19 * 19 * 19));
}

// The DTFE field (linear in each tet, open star at the hull) integrates to the total
// mass: sum over tets of V(t) times the mean of its vertices' densities.
TEST_F(FieldTest, DtfeConservesMass) {
  for (const auto dist : {io::Distribution::kUniform, io::Distribution::kClusters}) {
    const std::string tets = container(dist, 10000, 14);
    fields(tets, "open", false, pipeline::HullMode::kOpen);
    const Reference ref(tets);
    const auto rho = load_npy<double>(path("open.density.npy"));
    const auto order = ref.input_order();
    std::vector<double> by_label(ref.n);
    for (std::size_t i = 0; i < ref.n; ++i) by_label[order[i]] = rho[i];
    double mass = 0;
    for (std::size_t t = 0; t < ref.tets.size(); t += 4) {
      const std::uint64_t* q = &ref.tets[t];
      mass += ref.tet_volume(q) * (by_label[q[0]] + by_label[q[1]] + by_label[q[2]] + by_label[q[3]]) / 4;
    }
    EXPECT_NEAR(mass, double(ref.n), 1e-12 * double(ref.n)) << io::to_string(dist);
  }
}

// The grid against a brute-force location of each of the 32^3 centres in every tet.
TEST_F(FieldTest, GridMatchesBruteForce) {
  const std::string tets = container(io::Distribution::kClusters, 10000, 15);
  const pipeline::FieldSummary s = fields(tets, "g", true, pipeline::HullMode::kOpen);
  const Reference ref(tets);
  const auto rho = load_npy<double>(path("g.density.npy"));
  const auto grid = load_npy<double>(path("g.grid.npy"));
  ASSERT_EQ(grid.size(), 32u * 32u * 32u);
  const auto order = ref.input_order();
  std::vector<double> by_label(ref.n);
  for (std::size_t i = 0; i < ref.n; ++i) by_label[order[i]] = rho[i];
  io::TetReader r(tets);
  const auto& h = r.header();
  std::vector<double> want(grid.size(), std::nan(""));
  std::vector<int> hits(grid.size(), 0);
  std::vector<bool> unsure(grid.size(), false);
  auto centre = [&](int k, std::size_t i) {
    return h.bbox_min[std::size_t(k)] +
           (double(i) + 0.5) * (h.bbox_max[std::size_t(k)] - h.bbox_min[std::size_t(k)]) / 32.0;
  };
  // Each tet against the centres in its bounding box (widened by a cell: no exact
  // arithmetic decides anything here).
  auto cells = [&](int k, double a, double b, std::size_t& i0, std::size_t& i1) {
    const double s = 32.0 / (h.bbox_max[std::size_t(k)] - h.bbox_min[std::size_t(k)]);
    i0 = std::size_t(std::max(0.0, std::floor((a - h.bbox_min[std::size_t(k)]) * s - 1.5)));
    i1 = std::size_t(std::min(31.0, std::ceil((b - h.bbox_min[std::size_t(k)]) * s + 0.5)));
  };
  for (std::size_t t = 0; t < ref.tets.size(); t += 4) {
    const std::uint64_t* q = &ref.tets[t];
    const double v6 = 6 * ref.tet_volume(q);
    std::size_t r0[3], r1[3];
    for (int k = 0; k < 3; ++k) {
      double a = 1e300, b = -1e300;
      for (int v = 0; v < 4; ++v)
        a = std::min(a, ref.xyz[q[v]][std::size_t(k)]), b = std::max(b, ref.xyz[q[v]][std::size_t(k)]);
      cells(k, a, b, r0[k], r1[k]);
    }
    for (std::size_t ix = r0[0]; ix <= r1[0]; ++ix)
      for (std::size_t iy = r0[1]; iy <= r1[1]; ++iy)
        for (std::size_t iz = r0[2]; iz <= r1[2]; ++iz) {
          const std::size_t g = (ix * 32 + iy) * 32 + iz;
          const Vec x{centre(0, ix), centre(1, iy), centre(2, iz)};
          double lam[4], lo = 1;
          for (int i = 0; i < 4; ++i) {
            Vec p[4] = {ref.xyz[q[0]], ref.xyz[q[1]], ref.xyz[q[2]], ref.xyz[q[3]]};
            p[i] = x;
            lam[i] = dot(sub(p[1], p[0]), cross(sub(p[2], p[0]), sub(p[3], p[0]))) / v6;
            lo = std::min(lo, lam[i]);
          }
          if (lo < -1e-9) continue;
          if (lo < 1e-9) unsure[g] = true;  // on a face: the exact test picks one of the tets
          ++hits[g];
          want[g] =
              lam[0] * by_label[q[0]] + lam[1] * by_label[q[1]] + lam[2] * by_label[q[2]] + lam[3] * by_label[q[3]];
        }
  }
  std::size_t inside = 0, compared = 0;
  for (std::size_t g = 0; g < grid.size(); ++g) {
    if (hits[g] == 0) {
      EXPECT_TRUE(std::isnan(grid[g])) << "grid point " << g << " outside every tet";
      continue;
    }
    ++inside;
    if (hits[g] == 1 && !unsure[g]) {
      EXPECT_NEAR(grid[g], want[g], 1e-9 * std::fabs(want[g])) << "grid point " << g;
      ++compared;
    } else if (!std::isnan(grid[g])) {
      EXPECT_NEAR(grid[g], want[g], 1e-6 * std::fabs(want[g])) << "grid point " << g << " on a face";
    }
  }
  EXPECT_GT(compared, grid.size() / 4);
  // Points on the hull's boundary may go either way under the perturbation; none here.
  EXPECT_EQ(s.grid_inside, inside);
}

// The same bytes whatever the threads and the memory budget (batching).
TEST_F(FieldTest, SameBytesForThreadsAndMemory) {
  const std::string tets = container(io::Distribution::kClusters, 10000, 16, 1500);
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto a = fields(tets, "a", true, pipeline::HullMode::kNan, 64, 2000, 512);
  omp_set_num_threads(2);
  fields(tets, "b", true, pipeline::HullMode::kNan, 64, 2000, 512);
  const auto c = fields(tets, "c", true, pipeline::HullMode::kNan, 512, 0, 0);
  EXPECT_GT(a.far_labels_peak, 0u);
  EXPECT_EQ(c.far_labels_peak, 0u);
  EXPECT_GT(a.batches, c.batches);
  omp_set_num_threads(saved);
  for (const char* what : {"density", "voronoi", "neighbours.offsets", "neighbours.indices", "grid"}) {
    const auto a = file_bytes(path(std::string("a.") + what + ".npy"));
    EXPECT_FALSE(a.empty()) << what;
    EXPECT_EQ(a, file_bytes(path(std::string("b.") + what + ".npy"))) << what << ": threads";
    EXPECT_EQ(a, file_bytes(path(std::string("c.") + what + ".npy"))) << what << ": memory";
  }
}

// The points go back to input order placed by original index when their columns fit
// their share, through the external sort otherwise: the same bytes, with merged
// duplicates (gaps in the original indices) and the grid's densities with --mass (the
// way back to label order) included.
TEST_F(FieldTest, PointsPlacedOrSortedSameBytes) {
  const std::uint64_t n = 8000;
  const std::string tets = container(io::Distribution::kClusters, n, 41, 1500, 9);
  const std::uint64_t kept = io::TetReader(tets).point_count();
  EXPECT_EQ(kept, n - (n - 1) / 9);
  std::vector<double> mass(n);
  for (std::size_t i = 0; i < n; ++i) mass[i] = 1.0 + double(i % 7) / 8;
  std::ofstream(path("mass.f64"), std::ios::binary)
      .write(reinterpret_cast<const char*>(mass.data()), std::streamsize(8 * n));
  for (const std::uint64_t share : {std::uint64_t(0), std::uint64_t(1)}) {  // 0: from the budget (placed); 1: sorted
    pipeline::FieldOptions o;
    o.input = tets;
    o.output = path(share ? "sorted" : "placed");
    o.density = o.voronoi = true;
    o.grid = {16, 12, 8};
    o.mass = path("mass.f64");
    o.point_memory = share;
    o.progress = false;
    o.tmpdir = dir_.string();
    pipeline::compute_fields(o);
  }
  for (const char* what : {"density", "voronoi", "grid"}) {
    const auto placed = file_bytes(path(std::string("placed.") + what + ".npy"));
    EXPECT_FALSE(placed.empty()) << what;
    EXPECT_EQ(placed, file_bytes(path(std::string("sorted.") + what + ".npy"))) << what;
  }
  EXPECT_EQ(load_npy<double>(path("placed.density.npy")).size(), kept);
}

// Neighbour rows that outgrow their share spill to the scratch file in buckets by
// original index; the CSR files are the same bytes as when they stay in memory.
TEST_F(FieldTest, NeighbourRowsSpillSameBytes) {
  const std::string tets = container(io::Distribution::kUniform, 10000, 23, 1500);
  // share 0: from the budget; 1: the least (every row spills). wide: --index-dtype int64.
  auto neighbours = [&](const std::string& name, std::uint64_t share, bool wide) {
    pipeline::FieldOptions o;
    o.input = tets;
    o.output = path(name);
    o.neighbours = true;
    o.neighbour_int64 = wide;
    o.memory_bytes = std::uint64_t(256) << 20;
    o.batch_tets = 5000;
    o.neighbour_memory = share;
    o.progress = false;
    o.tmpdir = dir_.string();
    EXPECT_EQ(pipeline::compute_fields(o).neighbour_dtype, wide ? "int64" : "int32") << name;
  };
  neighbours("big", 0, false);
  neighbours("small", 1, false);
  for (const char* what : {"neighbours.offsets", "neighbours.indices"}) {
    const auto big = file_bytes(path(std::string("big.") + what + ".npy"));
    EXPECT_GT(big.size(), 128u) << what;
    EXPECT_EQ(big, file_bytes(path(std::string("small.") + what + ".npy"))) << what;
  }
  // --index-dtype int64: the same values in int64, spilled or not.
  neighbours("wide-big", 0, true);
  neighbours("wide-small", 1, true);
  for (const char* what : {"neighbours.offsets", "neighbours.indices"}) {
    const auto narrow = load_npy<std::int32_t>(path(std::string("big.") + what + ".npy"));
    for (const char* wide : {"wide-big.", "wide-small."})
      EXPECT_EQ(std::vector<std::int64_t>(narrow.begin(), narrow.end()),
                load_npy<std::int64_t>(path(std::string(wide) + what + ".npy")))
          << wide << what;
  }
}

// The writer on its own: rows in any order, originals with gaps (merged duplicates),
// a skewed degree distribution whose heavy rows overflow their bucket (written in
// parts), against a bound that underestimates them; same bytes as in memory.
TEST_F(FieldTest, NeighbourRowsBucketsAndParts) {
  const std::uint64_t end = 7500;
  std::vector<std::uint64_t> originals;
  for (std::uint64_t o = 0; o < end; ++o)
    if (o % 3 != 1) originals.push_back(o);
  std::vector<std::uint64_t> shuffled = originals;
  for (std::size_t i = 0; i < shuffled.size(); ++i) std::swap(shuffled[i], shuffled[(i * 7919) % shuffled.size()]);
  auto row = [](std::uint64_t o) {
    std::vector<std::uint32_t> r;
    const std::uint64_t degree = o < 600 ? 200 : o % 5;
    for (std::uint64_t k = 0; k < degree; ++k) r.push_back(std::uint32_t(o * 3 + k * 11));
    return r;
  };
  std::uint64_t entries = 0;
  for (const std::uint64_t o : originals) entries += row(o).size();
  struct Case {
    const char* name;
    std::uint64_t bound, memory;
  };
  for (const Case c : {Case{"mem", entries, std::uint64_t(1) << 30}, Case{"low", 5 * originals.size(), 0},
                       Case{"buckets", entries, 0}, Case{"wide", entries, 0}}) {
    pipeline::NeighbourRows rows(end, originals.size(), c.bound, c.memory, path(std::string(c.name) + ".rows"));
    for (const std::uint64_t o : shuffled) {
      const auto r = row(o);
      rows.add(o, r);
    }
    EXPECT_EQ(rows.spilled(), std::string(c.name) != "mem") << c.name;
    if (std::string(c.name) == "buckets" || std::string(c.name) == "wide") {
      EXPECT_GT(rows.buckets(), 1u);
    }
    EXPECT_FALSE(rows.needs_int64());
    rows.write(path(std::string(c.name) + ".off.npy"), path(std::string(c.name) + ".idx.npy"),
               std::string(c.name) == "wide");
    EXPECT_EQ(rows.entries(), entries);
  }
  const auto off = load_npy<std::int32_t>(path("mem.off.npy"));
  const auto idx = load_npy<std::int32_t>(path("mem.idx.npy"));
  // int64 on request (spilled, in buckets): the same values.
  const auto off64 = load_npy<std::int64_t>(path("wide.off.npy"));
  const auto idx64 = load_npy<std::int64_t>(path("wide.idx.npy"));
  EXPECT_EQ(std::vector<std::int64_t>(off.begin(), off.end()), off64);
  EXPECT_EQ(std::vector<std::int64_t>(idx.begin(), idx.end()), idx64);
  ASSERT_EQ(off.size(), originals.size() + 1);
  for (std::size_t i = 0; i < originals.size(); ++i) {
    const auto want = row(originals[i]);
    ASSERT_EQ(std::vector<std::int64_t>(idx.begin() + off[i], idx.begin() + off[i + 1]),
              std::vector<std::int64_t>(want.begin(), want.end()))
        << "row " << i;
  }
  for (const char* name : {"low", "buckets"})
    for (const char* what : {".off.npy", ".idx.npy"})
      EXPECT_EQ(file_bytes(path(std::string("mem") + what)), file_bytes(path(std::string(name) + what)))
          << name << what;
}

// int32 holds the CSR pair while the largest index (original_end - 1) and the entry
// count are at most INT32_MAX; past it the writer needs int64 and refuses int32.
TEST_F(FieldTest, NeighbourRowsInt32Limit) {
  const std::uint64_t int32_max = std::uint64_t(std::numeric_limits<std::int32_t>::max());
  const std::uint32_t row[] = {0, 1};
  {
    pipeline::NeighbourRows rows(int32_max + 1, 1, 2, std::uint64_t(1) << 30, path("at.rows"));
    rows.add(int32_max, row);  // the largest index int32 holds
    EXPECT_FALSE(rows.needs_int64());
  }
  pipeline::NeighbourRows rows(int32_max + 2, 1, 2, std::uint64_t(1) << 30, path("past.rows"));
  rows.add(int32_max + 1, row);
  EXPECT_TRUE(rows.needs_int64());
  EXPECT_THROW(rows.write(path("past.off.npy"), path("past.idx.npy"), false), std::logic_error);
}

TEST_F(FieldTest, PerturbedLocationIsExclusive) {
  // Two tets sharing the face z = 0 triangle; a point on the face belongs to one of them.
  const double a[3] = {0, 0, 0}, b[3] = {1, 0, 0}, c[3] = {0, 1, 0}, up[3] = {0.2, 0.2, 1}, dn[3] = {0.2, 0.2, -1};
  const double g[3] = {0.25, 0.25, 0};
  // (a, b, c, up) is positive; (a, c, b, dn) too.
  const bool in_up = pipeline::tet_contains(a, b, c, up, g), in_dn = pipeline::tet_contains(a, c, b, dn, g);
  EXPECT_NE(in_up, in_dn);
  // The floating-point prefilter agrees with the exact test, near faces included.
  const pipeline::TetLocator up_tet(a, b, c, up), dn_tet(a, c, b, dn);
  for (int i = 0; i <= 40; ++i)
    for (int j = 0; j <= 40; ++j)
      for (const double z : {-1e-300, 0.0, 1e-300, 1e-17, -1e-17, 0.3}) {
        const double q[3] = {i / 40.0, j / 40.0, z};
        EXPECT_EQ(up_tet.contains(q), pipeline::tet_contains(a, b, c, up, q)) << q[0] << " " << q[1] << " " << z;
        EXPECT_EQ(dn_tet.contains(q), pipeline::tet_contains(a, c, b, dn, q)) << q[0] << " " << q[1] << " " << z;
      }
  const double vertex[3] = {0, 0, 0};
  EXPECT_LE(int(pipeline::tet_contains(a, b, c, up, vertex)) + int(pipeline::tet_contains(a, c, b, dn, vertex)), 1);
}

TEST(FieldGeometry, HullTermsCancelAroundAnInteriorPoint) {
  // The octahedron around label 0 (the origin), cut into its 8 octant tets, each
  // positively oriented (its vertices swapped where the octant's orientation is
  // negative): the centre's terms cancel, every other vertex lies on the hull.
  const double xyz[7][3] = {{0, 0, 0}, {1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  std::uint64_t sum[7] = {};
  double volume = 0;
  for (int sx = 0; sx < 2; ++sx)
    for (int sy = 0; sy < 2; ++sy)
      for (int sz = 0; sz < 2; ++sz) {
        std::uint64_t q[4] = {0, std::uint64_t(1 + sx), std::uint64_t(3 + sy), std::uint64_t(5 + sz)};
        if ((sx + sy + sz) % 2 == 1) std::swap(q[2], q[3]);
        const double* p[4] = {xyz[q[0]], xyz[q[1]], xyz[q[2]], xyz[q[3]]};
        const auto t = pipeline::tet_contribution(p);
        ASSERT_GT(t.volume, 0);
        volume += t.volume;
        EXPECT_NEAR(t.voronoi[0] + t.voronoi[1] + t.voronoi[2] + t.voronoi[3], t.volume, 1e-15);
        std::uint64_t terms[4];
        pipeline::tet_hull_terms(q, terms);
        for (int v = 0; v < 4; ++v) sum[q[v]] += terms[v];
      }
  EXPECT_NEAR(volume, 8.0 / 6, 1e-15);
  EXPECT_EQ(sum[0], 0u);
  for (int v = 1; v < 7; ++v) EXPECT_NE(sum[v], 0u) << v;
  // A tet's terms do not depend on where its vertices start (an even permutation keeps
  // the orientation), and the other orientation negates them.
  const std::uint64_t q[4] = {10, 20, 30, 40}, even[4] = {20, 10, 40, 30}, odd[4] = {20, 10, 30, 40};
  std::uint64_t a[4], b[4], c[4];
  pipeline::tet_hull_terms(q, a);
  pipeline::tet_hull_terms(even, b);
  pipeline::tet_hull_terms(odd, c);
  EXPECT_EQ(a[0], b[1]);
  EXPECT_EQ(a[1], b[0]);
  EXPECT_EQ(a[2], b[3]);
  EXPECT_EQ(a[3], b[2]);
  EXPECT_EQ(a[0], std::uint64_t(0) - c[1]);
  EXPECT_EQ(a[2], std::uint64_t(0) - c[2]);
}

TEST_F(FieldTest, BadOptionsAndInput) {
  pipeline::FieldOptions o;
  o.input = path("missing.tets");
  o.output = path("x");
  EXPECT_THROW(pipeline::compute_fields(o), UsageError);  // nothing asked
  o.density = true;
  EXPECT_THROW(pipeline::compute_fields(o), IoError);  // no such file
  EXPECT_THROW(pipeline::parse_grid("0"), UsageError);
  EXPECT_THROW(pipeline::parse_grid("4,4"), UsageError);
  EXPECT_THROW(pipeline::parse_box("0,0,0,1,1"), UsageError);
  EXPECT_EQ(pipeline::parse_grid("8,4,2"), (std::array<std::uint64_t, 3>{8, 4, 2}));
}

}  // namespace
}  // namespace tetstream
