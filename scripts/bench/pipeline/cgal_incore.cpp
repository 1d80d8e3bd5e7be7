// Reads a raw float64 xyz file and triangulates it in core with CGAL's sequential
// Delaunay_triangulation_3 (EPICK), timing the whole job from the file as `tetstream
// run` is timed: read + triangulate. Prints key=value pairs for scripts/bench-pipeline.
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <chrono>
#include <cstdio>
#include <vector>

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using DT = CGAL::Delaunay_triangulation_3<K>;

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: cgal_incore POINTS.f64\n");
    return 2;
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::FILE* f = std::fopen(argv[1], "rb");
  if (!f) {
    std::perror(argv[1]);
    return 3;
  }
  std::vector<K::Point_3> pts;
  double buf[3 * 4096];
  std::size_t n;
  while ((n = std::fread(buf, 3 * sizeof(double), 4096, f)) > 0)
    for (std::size_t i = 0; i < n; ++i) pts.emplace_back(buf[3 * i], buf[3 * i + 1], buf[3 * i + 2]);
  std::fclose(f);
  const auto t1 = std::chrono::steady_clock::now();
  DT dt(pts.begin(), pts.end());
  const auto t2 = std::chrono::steady_clock::now();
  const double read_s = std::chrono::duration<double>(t1 - t0).count();
  const double tri_s = std::chrono::duration<double>(t2 - t1).count();
  std::printf("tool=cgal points=%zu tets=%zu read_s=%.3f triangulate_s=%.3f total_s=%.3f\n", pts.size(),
              std::size_t(dt.number_of_finite_cells()), read_s, tri_s, read_s + tri_s);
  return 0;
}
