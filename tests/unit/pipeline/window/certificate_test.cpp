// The certificate's pieces (pipeline/window/certificate.hpp, docs/certificate.md),
// each against brute force over every missing point with the kernel's exact,
// perturbed predicates:
//   - the range test is conservative: a tet it clears has no missing point in conflict;
//   - the emptiness query finds a conflicting point exactly when one exists;
//   - the hull-facet query, which searches the global hull's boundary points only,
//     agrees with a search of every missing point;
//   - a vertex whose star the certificate clears has its star in the Delaunay
//     triangulation of all the points: it is final, and never changes again.
// On uniform points, on a flat terrain-like surface (flat tets with huge balls) and on
// a coarse lattice (degenerate: cospherical and coplanar everywhere), for windows of
// a whole segment and for strips.
#include "pipeline/window/certificate.hpp"

#include "core/delaunay.hpp"
#include "core/predicates.hpp"
#include "pipeline/sort/hull.hpp"
#include "pipeline/window/zone_triangulator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace tetstream::pipeline {
namespace {

using core::TetId;
using core::VertexId;

enum class Shape { kUniform, kSurface, kLattice };

// Points sorted along x (the sort axis), with their index, key samples and the global
// hull's boundary points, as the index stage makes them.
struct Job {
  std::vector<SortedPoint> points, hull;
  PointIndex index, hull_index;
  SortedView view;

  Job(Shape shape, std::size_t n, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0, 1);
    std::uniform_int_distribution<int> along(0, 40), across(0, 10);
    for (std::size_t i = 0; i < n; ++i) {
      double p[3] = {4 * u(rng), u(rng), u(rng)};
      if (shape == Shape::kSurface) p[2] = 0.02 * std::sin(3 * p[0]) * std::cos(5 * p[1]) + 0.001 * u(rng);
      if (shape == Shape::kLattice) p[0] = along(rng) * 0.1, p[1] = across(rng) * 0.1, p[2] = across(rng) * 0.1;
      points.push_back(SortedPoint{{p[0], p[1], p[2]}, 0});
    }
    std::sort(points.begin(), points.end(), [](const SortedPoint& a, const SortedPoint& b) {
      return std::lexicographical_compare(a.xyz, a.xyz + 3, b.xyz, b.xyz + 3);
    });
    // Labels are positions in the duplicate-free sorted order.
    points.erase(
        std::unique(points.begin(), points.end(),
                    [](const SortedPoint& a, const SortedPoint& b) { return std::equal(a.xyz, a.xyz + 3, b.xyz); }),
        points.end());
    for (std::size_t i = 0; i < points.size(); ++i) points[i].original = i;
    view.points = records_of(points.data());
    view.count = points.size();
    view.axis = 0;
    for (int k = 0; k < 3; ++k) view.bbox_min[k] = view.bbox_max[k] = points[0].xyz[k];
    for (const SortedPoint& p : points)
      for (int k = 0; k < 3; ++k)
        view.bbox_min[k] = std::min(view.bbox_min[k], p.xyz[k]),
        view.bbox_max[k] = std::max(view.bbox_max[k], p.xyz[k]);
    index.build(view.points, view.count, 0, PointIndex::kMinBlockPoints);
    view.index = &index;
    view.sample_keys();
    std::vector<double> xyz;
    for (const SortedPoint& p : points) xyz.insert(xyz.end(), p.xyz, p.xyz + 3);
    for (std::uint32_t i : hull_vertex_candidates(xyz.data(), points.size())) hull.push_back(points[i]);
    std::sort(hull.begin(), hull.end(),
              [](const SortedPoint& a, const SortedPoint& b) { return a.original < b.original; });
    view.hull_points = hull;
    std::vector<double> hull_xyz;
    std::vector<std::uint64_t> hull_labels;
    for (const SortedPoint& p : hull)
      hull_xyz.insert(hull_xyz.end(), p.xyz, p.xyz + 3), hull_labels.push_back(p.original);
    view.hull_facets = hull_facet_labels(hull_xyz.data(), hull_labels.data(), hull_labels.size());
    hull_index.build(records_of(view.hull_points.data()), view.hull_points.size(), 0, PointIndex::kMinBlockPoints);
    view.hull_index = &hull_index;
  }
};

// A window of a job: the labels [w0, w1), inside the strip [window_lo, window_hi] of
// y when `strip`, triangulated by the kernel.
struct Window {
  SegmentPlan plan;
  Zone zone;
  std::vector<double> xyz;
  std::vector<std::uint64_t> labels, held;
  core::Delaunay dt;

  Window(const Job& job, std::uint64_t w0, std::uint64_t w1, bool strip) {
    plan.label_begin = plan.window_begin = w0;
    plan.label_end = plan.window_end = w1;
    if (strip) zone = Zone{1, 0.3, 0.6, 0.25, 0.65};
    for (std::uint64_t l = w0; l < w1; ++l) {
      const double* p = job.points[l].xyz;
      if (strip && (p[1] < zone.window_lo || p[1] > zone.window_hi)) continue;
      xyz.insert(xyz.end(), p, p + 3);
      labels.push_back(l);
    }
    EXPECT_EQ(dt.build(xyz.data(), labels.data(), labels.size()), core::BuildStatus::kOk);
  }
  bool missing(const Job& job, std::uint64_t l) const {
    if (l < plan.window_begin || l >= plan.window_end) return true;
    const double y = job.points[l].xyz[1];
    return zone.axis >= 0 && (y < zone.window_lo || y > zone.window_hi);
  }
  // Brute force: a missing point in conflict with tet t (finite or infinite), or none.
  bool any_missing_conflict(const Job& job, TetId t) const {
    VertexId v[4];
    for (int i = 0; i < 4; ++i) v[i] = dt.vertex(t, i);
    for (std::uint64_t l = 0; l < job.view.count; ++l) {
      if (!missing(job, l)) continue;
      const double* p = job.points[l].xyz;
      if (dt.is_infinite(t)) {
        int inf = 0;
        while (v[inf] != core::kInfiniteVertex) ++inf;
        VertexId f[3];
        for (int m = 0; m < 3; ++m) f[m] = v[core::kFacetVertex[inf][m]];
        if (core::infinite_conflict_sos(dt.point(f[0]), dt.point(f[1]), dt.point(f[2]), p, dt.label(f[0]),
                                        dt.label(f[1]), dt.label(f[2]), l) > 0)
          return true;
      } else if (core::insphere_sos(dt.point(v[0]), dt.point(v[1]), dt.point(v[2]), dt.point(v[3]), p, dt.label(v[0]),
                                    dt.label(v[1]), dt.label(v[2]), dt.label(v[3]), l) > 0) {
        return true;
      }
    }
    return false;
  }
  // Whether a conflict of tet t with the labelled point exists (for a query's answer).
  bool conflicts(const Job& job, TetId t, std::uint64_t l) const {
    const double* p = job.points[l].xyz;
    VertexId v[4];
    for (int i = 0; i < 4; ++i) v[i] = dt.vertex(t, i);
    return core::insphere_sos(dt.point(v[0]), dt.point(v[1]), dt.point(v[2]), dt.point(v[3]), p, dt.label(v[0]),
                              dt.label(v[1]), dt.label(v[2]), dt.label(v[3]), l) > 0;
  }
};

struct Case {
  Shape shape;
  std::size_t n;
  std::uint64_t seed;
  bool strip;
  std::string name() const {
    const char* s[] = {"uniform", "surface", "lattice"};
    return std::string(s[int(shape)]) + (strip ? " strip" : " segment") + " seed " + std::to_string(seed);
  }
};

std::vector<Case> cases() {
  std::vector<Case> out;
  for (Shape shape : {Shape::kUniform, Shape::kSurface, Shape::kLattice})
    for (bool strip : {false, true})
      for (std::uint64_t seed : {1, 2}) out.push_back({shape, 1500, seed, strip});
  return out;
}

// A case's job, its window (the middle third of the labels) and the certificate of
// that window's zone.
struct ZoneCase {
  Job job;
  Window w;
  Certificate cert;
  SegmentStats stats;
  explicit ZoneCase(const Case& c)
      : job(c.shape, c.n, c.seed), w(job, job.view.count / 3, 2 * job.view.count / 3, c.strip), cert(job.view) {
    cert.start_zone(w.plan, w.zone, w.held);
  }
};

TEST(Certificate, RangeTestIsConservativeAndQueryIsExact) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name());
    ZoneCase setup(c);
    const Job& job = setup.job;
    Window& w = setup.w;
    Certificate& cert = setup.cert;
    SegmentStats& stats = setup.stats;
    std::size_t cleared = 0, queried = 0, conflicting = 0;
    for (TetId t = 0; t < w.dt.num_tet_slots(); ++t) {
      if (!w.dt.is_alive(t) || w.dt.is_infinite(t)) continue;
      const bool truth = w.any_missing_conflict(job, t);
      const RangeTest r = cert.range_test(w.dt, t);
      if (r.clears()) {
        ++cleared;
        ASSERT_FALSE(truth) << "the range test cleared tet " << t << " with a missing point in conflict";
        continue;
      }
      ++queried;
      const std::uint64_t found = cert.query(w.dt, t, r, stats);
      ASSERT_EQ(found != Certificate::kNone, truth) << "tet " << t;
      if (found != Certificate::kNone) {
        ++conflicting;
        EXPECT_TRUE(w.missing(job, found));
        EXPECT_TRUE(w.conflicts(job, t, found));
      }
    }
    // Both paths ran: the test is not vacuous.
    EXPECT_GT(cleared, 0u);
    EXPECT_GT(queried, 0u);
    EXPECT_GT(conflicting, 0u);
  }
}

// The reach of a failed range test (--json's empty_query_reach): 0 exactly when the
// clipped ball stays between the window's missing keys (only the strip's window was
// too narrow), otherwise how far past them it reaches, in widths of the segment.
TEST(Certificate, ReachPastTheWindowIsInSegmentWidths) {
  std::size_t within = 0, past = 0;
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name());
    ZoneCase setup(c);
    const Job& job = setup.job;
    Window& w = setup.w;
    const SegmentPlan& plan = w.plan;
    auto key = [&](std::uint64_t l) { return job.points[l].xyz[0]; };
    const double clear_lo = plan.window_begin == 0 ? -INFINITY : key(plan.window_begin - 1);
    const double clear_hi = plan.window_end == job.view.count ? INFINITY : key(plan.window_end);
    const double width = key(plan.label_end - 1) - key(plan.label_begin);
    for (TetId t = 0; t < w.dt.num_tet_slots(); ++t) {
      if (!w.dt.is_alive(t) || w.dt.is_infinite(t)) continue;
      const RangeTest r = setup.cert.range_test(w.dt, t);
      if (r.clears() || !r.bounded) continue;
      const double reach = setup.cert.reach_past_window(r);
      ASSERT_EQ(reach == 0, r.outside_clear) << "tet " << t;
      if (reach == 0) {
        ++within;
        EXPECT_FALSE(r.strip_clear);
        continue;
      }
      ++past;
      const double expected =
          std::max(r.hi >= clear_hi ? r.hi - clear_hi : 0.0, r.lo <= clear_lo ? clear_lo - r.lo : 0.0);
      EXPECT_NEAR(reach * width, expected, 1e-12 * (1 + expected)) << "tet " << t;
    }
  }
  EXPECT_GT(within, 0u);
  EXPECT_GT(past, 0u);
}

// The global hull's facets from its boundary points alone are those of the kernel's
// triangulation of every point (flat faces of the lattice included, cut by the same
// perturbation).
TEST(Certificate, HullFacetsOfTheBoundaryPointsAreTheHulls) {
  for (Shape shape : {Shape::kUniform, Shape::kSurface, Shape::kLattice}) {
    const Job job(shape, 3000, 7);
    std::vector<double> xyz;
    std::vector<std::uint64_t> labels;
    for (const SortedPoint& p : job.points) xyz.insert(xyz.end(), p.xyz, p.xyz + 3), labels.push_back(p.original);
    const std::vector<LabelTriple> all = hull_facet_labels(xyz.data(), labels.data(), labels.size());
    ASSERT_FALSE(all.empty());
    EXPECT_EQ(job.view.hull_facets, all);
    EXPECT_LT(job.view.hull_points.size(), job.points.size());
  }
}

TEST(Certificate, HullFacetQueryAgreesWithBruteForce) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name());
    ZoneCase setup(c);
    const Job& job = setup.job;
    Window& w = setup.w;
    Certificate& cert = setup.cert;
    SegmentStats& stats = setup.stats;
    std::size_t facets = 0, global = 0;
    for (TetId t = 0; t < w.dt.num_tet_slots(); ++t) {
      if (!w.dt.is_alive(t) || !w.dt.is_infinite(t)) continue;
      ++facets;
      const bool truth = w.any_missing_conflict(job, t);
      if (cert.hull_facet_range_test(w.dt, t)) {
        ASSERT_FALSE(truth) << "the range test cleared hull facet " << t << " with a missing point beyond it";
        ++global;
        continue;
      }
      ASSERT_EQ(cert.is_global_hull_facet(w.dt, t), !truth) << "hull facet " << t << " and the global hull's list";
      const std::uint64_t found = cert.hull_facet_query(w.dt, t, stats);
      ASSERT_EQ(found == Certificate::kNone, !truth) << "hull facet " << t;
      global += found == Certificate::kNone;
    }
    EXPECT_GT(facets, global) << "every window hull facet was global: nothing tested";
  }
}

// The labelled tets of vertex v's star (finite tets only), as sorted label quadruples.
std::set<std::vector<std::uint64_t>> star_labels(const core::Delaunay& dt, VertexId v) {
  std::vector<TetId> star;
  dt.star(v, star);
  std::set<std::vector<std::uint64_t>> out;
  for (TetId t : star) {
    if (dt.is_infinite(t)) continue;
    std::vector<std::uint64_t> q;
    for (int i = 0; i < 4; ++i) q.push_back(dt.label(dt.vertex(t, i)));
    std::sort(q.begin(), q.end());
    out.insert(q);
  }
  return out;
}

TEST(Certificate, AClearedStarIsTheFinalStar) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name());
    ZoneCase setup(c);
    const Job& job = setup.job;
    Window& w = setup.w;
    Certificate& cert = setup.cert;
    SegmentStats& stats = setup.stats;
    // The triangulation of all the points, and each label's vertex in it.
    std::vector<double> all_xyz;
    std::vector<std::uint64_t> all_labels;
    for (const SortedPoint& p : job.points)
      all_xyz.insert(all_xyz.end(), p.xyz, p.xyz + 3), all_labels.push_back(p.original);
    core::Delaunay all;
    ASSERT_EQ(all.build(all_xyz.data(), all_labels.data(), all_labels.size()), core::BuildStatus::kOk);
    std::size_t final_vertices = 0, pending = 0;
    std::vector<TetId> star;
    for (VertexId v = 0; v < w.labels.size(); ++v) {
      star.clear();
      w.dt.star(v, star);
      bool certified = true;
      for (TetId t : star) {
        if (w.dt.is_infinite(t)) {
          certified &= cert.hull_facet_range_test(w.dt, t) || cert.is_global_hull_facet(w.dt, t) ||
                       cert.hull_facet_query(w.dt, t, stats) == Certificate::kNone;
        } else {
          const RangeTest r = cert.range_test(w.dt, t);
          certified &= r.clears() || cert.query(w.dt, t, r, stats) == Certificate::kNone;
        }
        if (!certified) break;
      }
      if (!certified) {
        ++pending;
        continue;
      }
      ++final_vertices;
      ASSERT_EQ(star_labels(w.dt, v), star_labels(all, VertexId(w.labels[v])))
          << "vertex of label " << w.labels[v] << ": its certified star differs from its star among all points";
    }
    EXPECT_GT(final_vertices, 0u);
    EXPECT_GT(pending, 0u);
  }
}

}  // namespace
}  // namespace tetstream::pipeline
