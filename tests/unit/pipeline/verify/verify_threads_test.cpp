// verify's pass on 1 to 4 threads (pipeline/verify/engine_run.ipp: frames prepared on
// any thread, several at once, and merged with the open facets in order): the same
// report, to the last bit of the volumes and the order of the listed violations, as on
// one thread, on valid and broken outputs, in steps smaller than a frame and with the
// open sets spilled; and a failing frame stops the pass with the error of the first
// failing frame in the visiting order. Small enough for the ThreadSanitizer tier.
#include "core/delaunay.hpp"
#include "core/error.hpp"
#include "pipeline/verify/verify.hpp"
#include "test_points.hpp"

#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <filesystem>
#include <numeric>
#include <string>
#include <unistd.h>
#include <vector>

namespace tetstream::pipeline {
namespace {

namespace fs = std::filesystem;

struct Output {
  std::vector<double> xyz;          // sorted, distinct: label = index
  std::vector<std::uint64_t> tets;  // 4 labels per tet
};

// The kernel's triangulation of the sorted, distinct points, tets by smallest label.
Output triangulate(const test::Points& raw) {
  std::vector<std::array<double, 3>> p(raw.size() / 3);
  for (std::size_t i = 0; i < p.size(); ++i) p[i] = {raw[3 * i], raw[3 * i + 1], raw[3 * i + 2]};
  std::sort(p.begin(), p.end());
  p.erase(std::unique(p.begin(), p.end()), p.end());
  Output o;
  for (const auto& q : p) o.xyz.insert(o.xyz.end(), q.begin(), q.end());
  std::vector<std::uint64_t> labels(p.size());
  std::iota(labels.begin(), labels.end(), 0);
  core::Delaunay dt;
  EXPECT_EQ(dt.build(o.xyz.data(), labels.data(), labels.size()), core::BuildStatus::kOk);
  std::vector<std::array<std::uint64_t, 4>> t;
  dt.for_each_finite_tet([&](const core::VertexId* v) { t.push_back({v[0], v[1], v[2], v[3]}); });
  std::stable_sort(t.begin(), t.end(), [](const auto& a, const auto& b) {
    return *std::min_element(a.begin(), a.end()) < *std::min_element(b.begin(), b.end());
  });
  for (const auto& a : t) o.tets.insert(o.tets.end(), a.begin(), a.end());
  return o;
}

// A source that fails to decode the batches listed in `bad` (a damaged frame).
class FailingSource : public MemorySource {
 public:
  FailingSource(const Output& o, std::size_t batch_tets, std::vector<std::size_t> bad)
      : MemorySource(o.xyz, o.tets, batch_tets), bad_(std::move(bad)) {}
  void read_batch(std::size_t k, std::vector<std::uint32_t>& labels) const override {
    fail(k);
    MemorySource::read_batch(k, labels);
  }
  void read_batch(std::size_t k, std::vector<std::uint64_t>& labels) const override {
    fail(k);
    MemorySource::read_batch(k, labels);
  }

 private:
  void fail(std::size_t k) const {
    if (std::find(bad_.begin(), bad_.end(), k) != bad_.end())
      throw InputError("batch " + std::to_string(k) + " is damaged");
  }
  std::vector<std::size_t> bad_;
};

struct Threads {
  explicit Threads(int n) : saved_(omp_get_max_threads()) { omp_set_num_threads(n); }
  ~Threads() { omp_set_num_threads(saved_); }
  int saved_;
};

VerifyOptions options(std::size_t step_tets, std::size_t open_bytes) {
  VerifyOptions v;
  v.progress = false;
  v.batch_tets = step_tets;
  v.open_bytes = open_bytes;
  v.max_listed = 3;
  v.tmpdir = fs::temp_directory_path().string();
  return v;
}

// Everything the report says but the time.
std::string fingerprint(const VerifyReport& r) {
  std::string s;
  auto put = [&](std::uint64_t v) { s += std::to_string(v) + ' '; };
  for (std::uint64_t v : {r.points, r.tets, r.vertices, r.facets, r.interior_facets, r.boundary_facets, r.edges,
                          r.hull_vertices, r.hull_edges, r.orient_tests, r.insphere_tests, r.hull_tests, r.tets_checked,
                          r.facets_checked, r.peak_open_facets, r.peak_open_edges, r.spilled_records, r.step_tets})
    put(v);
  put(std::uint64_t(r.euler)), put(std::uint64_t(r.hull_euler));
  for (double d : {r.tet_volume, r.hull_volume, r.volume_rel_error}) {
    std::uint64_t bits;
    std::memcpy(&bits, &d, sizeof bits);
    put(bits);
  }
  for (std::uint64_t c : r.counts) put(c);
  for (const auto& l : r.listed)
    s += std::string(violation_name(l.kind)) + ' ' + std::to_string(l.where) + ' ' + l.text + '\n';
  return s;
}

// The report on 1 thread, checked against 2, 3 and 4.
VerifyReport same_on_every_count(const Output& o, std::size_t batch_tets, const VerifyOptions& v) {
  const MemorySource src(o.xyz, o.tets, batch_tets);
  VerifyReport one;
  {
    Threads t(1);
    one = verify(src, v);
  }
  for (int threads = 2; threads <= 4; ++threads) {
    Threads t(threads);
    const VerifyReport r = verify(src, v);
    EXPECT_EQ(fingerprint(r), fingerprint(one)) << threads << " threads";
  }
  return one;
}

std::uint64_t count(const VerifyReport& r, Violation k) { return r.counts[std::size_t(k)]; }

const Output& uniform() {
  static const Output o = triangulate(test::uniform_cube(1200, 21));
  return o;
}

TEST(VerifyThreads, ValidOutputsGiveOneReport) {
  for (const auto& [name, pts] :
       {std::pair<const char*, test::Points>{"clusters", test::clusters(1200, 22)}, {"grid", test::grid(8)}}) {
    SCOPED_TRACE(name);
    const Output o = triangulate(pts);
    // Frames of 300 tets in steps of 128; then one step a frame, the open sets spilled.
    for (const auto& [step, open] : {std::pair<std::size_t, std::size_t>{128, 0}, {1 << 18, 1024}}) {
      const VerifyReport r = same_on_every_count(o, 300, options(step, open));
      EXPECT_TRUE(r.ok()) << r.summary();
      EXPECT_EQ(r.tets, o.tets.size() / 4);
      if (open) {
        EXPECT_GT(r.spilled_records, 0u);
      }
    }
  }
}

TEST(VerifyThreads, BrokenOutputsGiveOneReport) {
  Output o = uniform();
  const std::size_t t = o.tets.size() / 4;
  // A flipped tet, a repeated tet, a tet removed, and a tet moved far from its frame
  // (its facets meet their partners many steps later).
  std::swap(o.tets[4 * (t / 3) + 1], o.tets[4 * (t / 3) + 2]);
  o.tets.insert(o.tets.end(), o.tets.begin() + std::ptrdiff_t(4 * (t / 2)),
                o.tets.begin() + std::ptrdiff_t(4 * (t / 2) + 4));
  o.tets.erase(o.tets.begin() + std::ptrdiff_t(4 * (t / 4)), o.tets.begin() + std::ptrdiff_t(4 * (t / 4) + 4));
  std::rotate(o.tets.begin() + 40, o.tets.begin() + 44, o.tets.begin() + std::ptrdiff_t(4 * (t / 5)));
  const VerifyReport r = same_on_every_count(o, 250, options(100, 0));
  EXPECT_FALSE(r.ok());
  EXPECT_GT(count(r, Violation::kOrientation), 0u) << r.summary();
  EXPECT_GT(count(r, Violation::kDuplicateTet), 0u) << r.summary();
  EXPECT_GT(count(r, Violation::kVolume), 0u) << r.summary();
}

TEST(VerifyThreads, TheFirstFailingFrameInOrderIsReported) {
  const Output& o = uniform();
  const FailingSource src(o, 200, {9, 4});
  ASSERT_GT(src.batch_count(), 10u);
  for (int threads = 1; threads <= 4; ++threads) {
    Threads t(threads);
    try {
      verify(src, options(64, 0));
      ADD_FAILURE() << "no error on " << threads << " threads";
    } catch (const InputError& e) {
      EXPECT_STREQ(e.what(), "batch 4 is damaged") << threads << " threads";
    }
  }
}

}  // namespace
}  // namespace tetstream::pipeline
