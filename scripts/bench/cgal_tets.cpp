// Benchmark input only (never part of the product): a realistic tet stream.
// Generates N uniform points in the unit cube (seeded), sorts them along x (slab
// order, as the pipeline's external sort does), triangulates them with CGAL's
// Delaunay_triangulation_3, relabels every vertex by its position in the sorted
// order and emits the finite tets sorted by minimum label (stable: within one
// minimum the order is CGAL's), which is the order the pipeline's min-vertex
// filter emits them in.
//
// Output file (little-endian): u64 N, u64 T, N x 3 float64 sorted points,
// T x 4 uint32 labels (each tet positively oriented).
//
// Usage: cgal_tets N SEED OUT
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, K>;
using Tds = CGAL::Triangulation_data_structure_3<Vb>;
using Delaunay = CGAL::Delaunay_triangulation_3<K, Tds>;

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s N SEED OUT\n", argv[0]);
    return 2;
  }
  const std::uint64_t n = std::strtoull(argv[1], nullptr, 10);
  const std::uint64_t seed = std::strtoull(argv[2], nullptr, 10);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<std::array<double, 3>> pts(n);
  for (auto& p : pts) p = {u(rng), u(rng), u(rng)};
  std::sort(pts.begin(), pts.end());  // along x (ties by y, z): slab order

  auto t0 = std::chrono::steady_clock::now();
  std::vector<std::pair<K::Point_3, std::uint32_t>> input;
  input.reserve(n);
  for (std::uint32_t i = 0; i < n; ++i) input.emplace_back(K::Point_3(pts[i][0], pts[i][1], pts[i][2]), i);
  Delaunay dt(input.begin(), input.end());
  auto t1 = std::chrono::steady_clock::now();

  std::vector<std::array<std::uint32_t, 4>> tets;
  tets.reserve(dt.number_of_finite_cells());
  for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
    tets.push_back({c->vertex(0)->info(), c->vertex(1)->info(), c->vertex(2)->info(), c->vertex(3)->info()});
  }
  std::stable_sort(tets.begin(), tets.end(), [](const auto& a, const auto& b) {
    return *std::min_element(a.begin(), a.end()) < *std::min_element(b.begin(), b.end());
  });
  std::fprintf(stderr, "cgal_tets: %llu points, %zu tets (%.2f per point), CGAL %.2f s\n",
               (unsigned long long)n, tets.size(), double(tets.size()) / double(n),
               std::chrono::duration<double>(t1 - t0).count());

  std::FILE* f = std::fopen(argv[3], "wb");
  if (!f) { std::perror(argv[3]); return 3; }
  const std::uint64_t head[2] = {n, tets.size()};
  bool ok = std::fwrite(head, sizeof head, 1, f) == 1 &&
            std::fwrite(pts.data(), sizeof(pts[0]), n, f) == n &&
            std::fwrite(tets.data(), sizeof(tets[0]), tets.size(), f) == tets.size();
  ok = (std::fclose(f) == 0) && ok;
  if (!ok) { std::perror(argv[3]); return 3; }
  return 0;
}
