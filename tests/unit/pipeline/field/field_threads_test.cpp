// `field`'s accumulation on 1 to 3 threads (pipeline/field/accumulate.cpp: the tets'
// terms added into their vertices' sums by label ranges, one a thread, each in the
// tets' order): the same bytes in every output and the same summary sums as on one
// thread, with far labels (a ring smaller than the window) and both ways of summing
// (with the hull terms: density and Voronoi; without: neighbours alone). Small enough
// for the ThreadSanitizer tier.
#include "core/delaunay.hpp"
#include "io/tet_writer.hpp"
#include "pipeline/field/field.hpp"
#include "scratch_dir.hpp"
#include "test_points.hpp"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <fstream>
#include <iterator>
#include <numeric>
#include <string>
#include <vector>

namespace tetstream {
namespace {

class FieldThreadsTest : public testing_util::ScratchDirTest {
 protected:
  FieldThreadsTest() : ScratchDirTest("field-threads") {}

  // The kernel's triangulation of the sorted, distinct points in a container of small
  // frames, tets by smallest label; original indices in reverse (placed back by them).
  std::string container(const test::Points& raw) {
    std::vector<std::array<double, 3>> p(raw.size() / 3);
    for (std::size_t i = 0; i < p.size(); ++i) p[i] = {raw[3 * i], raw[3 * i + 1], raw[3 * i + 2]};
    std::sort(p.begin(), p.end());
    p.erase(std::unique(p.begin(), p.end()), p.end());
    std::vector<double> xyz;
    for (const auto& q : p) xyz.insert(xyz.end(), q.begin(), q.end());
    const std::size_t n = p.size();
    std::vector<std::uint64_t> labels(n), ids(n);
    std::iota(labels.begin(), labels.end(), 0);
    for (std::size_t i = 0; i < n; ++i) ids[i] = n - 1 - i;
    core::Delaunay dt;
    EXPECT_EQ(dt.build(xyz.data(), labels.data(), n), core::BuildStatus::kOk);
    std::vector<std::array<std::uint64_t, 4>> t;
    dt.for_each_finite_tet([&](const core::VertexId* v) { t.push_back({v[0], v[1], v[2], v[3]}); });
    std::stable_sort(t.begin(), t.end(), [](const auto& a, const auto& b) {
      return *std::min_element(a.begin(), a.end()) < *std::min_element(b.begin(), b.end());
    });
    std::vector<std::uint64_t> tets;
    for (const auto& a : t) tets.insert(tets.end(), a.begin(), a.end());
    io::TetFileHeader h;
    h.point_count = n;
    h.input_count = n;
    for (int c = 0; c < 3; ++c) {
      h.bbox_min[c] = h.bbox_max[c] = xyz[std::size_t(c)];
      for (std::size_t i = 0; i < n; ++i) {
        h.bbox_min[c] = std::min(h.bbox_min[c], xyz[3 * i + std::size_t(c)]);
        h.bbox_max[c] = std::max(h.bbox_max[c], xyz[3 * i + std::size_t(c)]);
      }
    }
    h.tool = "field_threads_test";
    io::TetWriterOptions wo;
    wo.frame_tets = 700;
    wo.sync = false;
    io::TetWriter w(path("in.tets"), h, wo);
    w.add_points(xyz.data(), ids.data(), n);
    w.add_tets(std::span<const std::uint64_t>(tets));
    w.finish();
    return path("in.tets");
  }

  pipeline::FieldSummary fields(const std::string& input, const std::string& prefix, bool neighbours_only) {
    pipeline::FieldOptions o;
    o.input = input;
    o.output = path(prefix);
    o.neighbours = true;
    o.density = o.voronoi = !neighbours_only;
    o.memory_bytes = std::uint64_t(64) << 20;
    o.batch_tets = 1500;
    o.ring_labels = 512;
    o.progress = false;
    o.tmpdir = dir_.string();
    return pipeline::compute_fields(o);
  }

  std::string bytes(const std::string& file) {
    std::ifstream in(path(file), std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
};

std::string sums(const pipeline::FieldSummary& s) {
  std::string out;
  for (double d : {s.total_mass, s.tet_volume, s.interior_voronoi, s.voronoi_total}) {
    std::uint64_t b;
    std::memcpy(&b, &d, sizeof b);
    out += std::to_string(b) + ' ';
  }
  return out + std::to_string(s.hull_points) + ' ' + std::to_string(s.far_labels_peak);
}

TEST_F(FieldThreadsTest, SameBytesOnEveryThreadCount) {
  const std::string in = container(test::clusters(2500, 31));
  const int saved = omp_get_max_threads();
  for (bool neighbours_only : {false, true}) {
    SCOPED_TRACE(neighbours_only ? "neighbours alone" : "density and Voronoi");
    omp_set_num_threads(1);
    const pipeline::FieldSummary one = fields(in, "t1", neighbours_only);
    EXPECT_GT(one.far_labels_peak, 0u);
    EXPECT_GT(one.tet_volume, 0.0);
    for (int threads = 2; threads <= 3; ++threads) {
      omp_set_num_threads(threads);
      const std::string prefix = "t" + std::to_string(threads);
      const pipeline::FieldSummary s = fields(in, prefix, neighbours_only);
      EXPECT_EQ(sums(s), sums(one)) << threads << " threads";
      for (const char* what : {"density", "voronoi", "neighbours.offsets", "neighbours.indices"}) {
        if (neighbours_only && (std::string(what) == "density" || std::string(what) == "voronoi")) continue;
        const std::string a = bytes("t1." + std::string(what) + ".npy");
        EXPECT_FALSE(a.empty()) << what;
        EXPECT_EQ(bytes(prefix + "." + what + ".npy"), a) << what << ", " << threads << " threads";
      }
    }
  }
  omp_set_num_threads(saved);
}

// OpenMP may give fewer threads than asked (OMP_THREAD_LIMIT, or here a nested region
// with nesting off, which runs on one thread while omp_get_max_threads() says 3): every
// label's sums are still added, the same bytes as on one thread.
TEST_F(FieldThreadsTest, FewerThreadsThanAskedLoseNoTerm) {
  const std::string in = container(test::clusters(2500, 32));
  const int saved = omp_get_max_threads();
  const int saved_levels = omp_get_max_active_levels();
  omp_set_num_threads(1);
  const pipeline::FieldSummary one = fields(in, "t1", false);
  omp_set_max_active_levels(1);
  pipeline::FieldSummary nested;
  int asked = 0;
#pragma omp parallel num_threads(2)
  {
#pragma omp single
    {
      omp_set_num_threads(3);
      asked = omp_get_max_threads();
      nested = fields(in, "tn", false);
    }
  }
  omp_set_max_active_levels(saved_levels);
  omp_set_num_threads(saved);
  EXPECT_EQ(asked, 3);
  EXPECT_EQ(sums(nested), sums(one));
  for (const char* what : {"density", "voronoi", "neighbours.offsets", "neighbours.indices"})
    EXPECT_TRUE(bytes("tn." + std::string(what) + ".npy") == bytes("t1." + std::string(what) + ".npy")) << what;
}

}  // namespace
}  // namespace tetstream
