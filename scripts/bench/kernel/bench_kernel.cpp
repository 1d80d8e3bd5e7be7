// One benchmark run of one Delaunay tool on one seeded point set; prints one line of
// key=value pairs for scripts/bench-kernel. Each tool runs in its own process, so the
// peak resident memory (getrusage ru_maxrss) is that tool's alone; the seeded
// generators give every tool the same points.
//
//   bench_kernel --tool ours|cgal|hxt --dist uniform|ball|shell|clusters|grid --n N
//                [--seed S] [--threads T] [--check]
//
// Timed: the triangulation call only (ours: Delaunay::build; CGAL: the range
// constructor, which spatially sorts; HXT: gmsh::model::mesh::tetrahedralize).
// Memory: bytes_per_point = (peak RSS - RSS at start-up, before the points exist) / n,
// so it includes the input coordinates and whatever the tool copies them into, but
// not the shared libraries every tool's process loads.
#include "core/delaunay.hpp"
#include "core/delaunay_check.hpp"
#include "core/predicates.hpp"
#include "tests/unit/test_points.hpp"

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>
#include <gmsh.h>
#include <omp.h>
#include <sys/resource.h>
#include <time.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

namespace {

namespace tp = tetstream::test;
namespace tc = tetstream::core;

struct Args {
  std::string tool = "ours", dist = "uniform";
  std::size_t n = 1000000;
  std::uint64_t seed = 20240601;
  int threads = 1;
  bool check = false;
};

[[noreturn]] void usage(const char* why) {
  std::fprintf(stderr,
               "bench_kernel: %s\nusage: bench_kernel --tool ours|cgal|hxt --dist uniform|ball|shell|clusters|grid "
               "--n N [--seed S] [--threads T] [--check]\n",
               why);
  std::exit(2);
}

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string k = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage(("missing value for " + k).c_str());
      return argv[++i];
    };
    if (k == "--tool")
      a.tool = value();
    else if (k == "--dist")
      a.dist = value();
    else if (k == "--n")
      a.n = std::size_t(std::stod(value()));
    else if (k == "--seed")
      a.seed = std::stoull(value());
    else if (k == "--threads")
      a.threads = std::stoi(value());
    else if (k == "--check")
      a.check = true;
    else
      usage(("unknown option " + k).c_str());
  }
  if (a.tool != "ours" && a.tool != "cgal" && a.tool != "hxt") usage("unknown tool");
  return a;
}

tp::Points generate(const Args& a) {
  if (a.dist == "uniform") return tp::uniform_cube(a.n, a.seed);
  if (a.dist == "ball") return tp::uniform_ball(a.n, a.seed);
  if (a.dist == "shell") return tp::ellipsoid_shell(a.n, a.seed);
  if (a.dist == "clusters") return tp::clusters(a.n, a.seed);
  if (a.dist == "grid") return tp::grid(std::size_t(std::llround(std::cbrt(double(a.n)))));
  usage("unknown distribution");
}

std::uint64_t peak_rss_bytes() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return std::uint64_t(ru.ru_maxrss) * 1024;  // Linux: kilobytes
}

std::uint64_t current_rss_bytes() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
  return 0;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// CPU time of the whole process (all its threads): on a shared machine it is far
// less disturbed by other jobs than wall time.
double process_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

// Wall and CPU time of one call.
struct Timer {
  std::chrono::steady_clock::time_point wall0 = std::chrono::steady_clock::now();
  double cpu0 = process_cpu_seconds();
  double wall() const { return seconds_since(wall0); }
  double cpu() const { return process_cpu_seconds() - cpu0; }
};

struct Result {
  double seconds = 0;
  double cpu_seconds = 0;
  std::uint64_t tets = 0;
  std::string extra;  // tool-specific key=value pairs
};

Result run_ours(tp::Points& xyz, std::size_t n, bool check) {
  Result r;
  tc::reset_predicate_stats();
  tc::Delaunay dt;
  const Timer timer;
  const tc::BuildStatus status = dt.build(xyz.data(), nullptr, n);
  r.seconds = timer.wall(), r.cpu_seconds = timer.cpu();
  const tc::PredicateStats ps = tc::predicate_stats();
  if (status != tc::BuildStatus::kOk) {
    std::fprintf(stderr, "bench_kernel: build failed\n");
    std::exit(1);
  }
  r.tets = dt.num_finite_tets();
  const tc::DelaunayStats& s = dt.stats();
  r.extra = "kernel_bytes=" + std::to_string(dt.memory_bytes()) + " o3d_calls=" + std::to_string(ps.orient3d_calls) +
            " o3d_exact=" + std::to_string(ps.orient3d_exact) + " ins_calls=" + std::to_string(ps.insphere_calls) +
            " ins_exact=" + std::to_string(ps.insphere_exact) +
            " ins_perturbed=" + std::to_string(ps.insphere_perturbed) + " walk_steps=" + std::to_string(s.walk_steps) +
            " cavity_tets=" + std::to_string(s.cavity_tets) + " duplicates=" + std::to_string(s.duplicates);
  if (check) {
    const auto t1 = std::chrono::steady_clock::now();
    const tc::CheckReport rep = tc::check_delaunay(dt);
    r.extra +=
        " check=" + std::string(rep.ok ? "ok" : "FAILED") + " check_seconds=" + std::to_string(seconds_since(t1));
    if (!rep.ok) std::fprintf(stderr, "%s\n", rep.summary().c_str());
  }
  return r;
}

Result run_cgal(tp::Points& xyz, std::size_t n) {
  using K = CGAL::Exact_predicates_inexact_constructions_kernel;
  using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, K>;
  using Tds = CGAL::Triangulation_data_structure_3<Vb>;
  using Cgal = CGAL::Delaunay_triangulation_3<K, Tds>;
  std::vector<std::pair<K::Point_3, std::uint32_t>> in;
  in.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    in.emplace_back(K::Point_3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]), std::uint32_t(i));
  tp::Points().swap(xyz);  // CGAL holds its own copy
  Result r;
  const Timer timer;
  Cgal dt(in.begin(), in.end());
  r.seconds = timer.wall(), r.cpu_seconds = timer.cpu();
  r.tets = dt.number_of_finite_cells();
  return r;
}

Result run_hxt(tp::Points& xyz, int threads) {
  gmsh::initialize(0, nullptr, false);
  gmsh::option::setNumber("General.Terminal", 0);
  gmsh::option::setNumber("General.Verbosity", 1);
  gmsh::option::setNumber("Mesh.Algorithm3D", 10);  // HXT
  gmsh::option::setNumber("General.NumThreads", threads);
  gmsh::option::setNumber("Mesh.MaxNumThreads3D", threads);
  gmsh::model::add("bench");
  std::vector<std::size_t> tetra;
  Result r;
  const Timer timer;
  gmsh::model::mesh::tetrahedralize(xyz, tetra);
  r.seconds = timer.wall(), r.cpu_seconds = timer.cpu();
  r.tets = tetra.size() / 4;
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  // Resident memory before any point exists: the loaded libraries (Gmsh's alone are
  // tens of MB), subtracted so that bytes per point are the tool's and the input's.
  const std::uint64_t start_rss = current_rss_bytes();
  const Args a = parse(argc, argv);
  omp_set_num_threads(a.threads);
  tp::Points xyz = generate(a);
  const std::size_t n = tp::count(xyz);
  const std::uint64_t base_rss = current_rss_bytes();
  Result r;
  if (a.tool == "ours")
    r = run_ours(xyz, n, a.check);
  else if (a.tool == "cgal")
    r = run_cgal(xyz, n);
  else
    r = run_hxt(xyz, a.threads);
  const std::uint64_t peak = peak_rss_bytes();
  std::printf(
      "tool=%s dist=%s n=%zu threads=%d seconds=%.4f cpu_seconds=%.4f tets=%llu tets_per_s=%.0f peak_rss=%llu "
      "start_rss=%llu "
      "points_rss=%llu bytes_per_point=%.1f %s\n",
      a.tool.c_str(), a.dist.c_str(), n, a.threads, r.seconds, r.cpu_seconds, (unsigned long long)r.tets,
      double(r.tets) / r.seconds, (unsigned long long)peak, (unsigned long long)start_rss, (unsigned long long)base_rss,
      double(peak - start_rss) / double(n), r.extra.c_str());
  std::fflush(stdout);
  std::_Exit(0);  // skip destructors: freeing 10^7-point structures costs seconds
}
