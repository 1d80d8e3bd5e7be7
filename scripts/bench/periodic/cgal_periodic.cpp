// Benchmark peer only (never part of the product): CGAL's in-core periodic Delaunay
// triangulation of a raw float64 xyz file in the box [0, L)^3, as CGAL's manual inserts
// a large set (spatially sorted, with its dummy points). Prints
// "total_s=S tets=T one_sheet=B" on stdout.
//
// Usage: cgal_periodic POINTS.f64 L
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Periodic_3_Delaunay_triangulation_3.h>
#include <CGAL/Periodic_3_Delaunay_triangulation_traits_3.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <vector>

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Gt = CGAL::Periodic_3_Delaunay_triangulation_traits_3<K>;
using P3DT3 = CGAL::Periodic_3_Delaunay_triangulation_3<Gt>;

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: cgal_periodic POINTS.f64 L\n");
    return 2;
  }
  const double l = std::atof(argv[2]);
  std::ifstream in(argv[1], std::ios::binary | std::ios::ate);
  const std::streamsize bytes = in.tellg();
  in.seekg(0);
  std::vector<double> xyz(std::size_t(bytes) / 8);
  in.read(reinterpret_cast<char*>(xyz.data()), bytes);
  const auto start = std::chrono::steady_clock::now();
  std::vector<K::Point_3> pts;
  pts.reserve(xyz.size() / 3);
  for (std::size_t i = 0; i + 2 < xyz.size(); i += 3) pts.emplace_back(xyz[i], xyz[i + 1], xyz[i + 2]);
  P3DT3 t(P3DT3::Iso_cuboid(0, 0, 0, l, l, l));
  t.insert(pts.begin(), pts.end(), true);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("total_s=%.3f tets=%zu one_sheet=%d\n", s, std::size_t(t.number_of_cells()),
              int(t.is_triangulation_in_1_sheet()));
  return 0;
}
