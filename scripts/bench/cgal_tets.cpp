// Benchmark input only (never part of the product): realistic tet streams for
// scripts/bench-format. Generates N uniform points in the unit cube (seeded),
// triangulates them once with CGAL's Delaunay_triangulation_3, and writes the finite
// tets twice, relabelled by two point orders the pipeline may use:
//
//   PREFIX.x.bin      points sorted along x (the external sort's order);
//   PREFIX.cells.bin  10 slabs along x, each sorted by cells of about 8 points in
//                     (y, z, x) order (a slab sorted by cell).
//
// In both, the tets are sorted by minimum label (stable: within one minimum the
// order is CGAL's), the order the pipeline's min-vertex filter emits them in.
// File layout (little-endian): u64 N, u64 T, N x 3 float64 points in label order,
// T x 4 uint32 labels (each tet positively oriented). Prints CGAL's CPU time on
// stdout as "cgal_seconds S".
//
// Usage: cgal_tets N SEED PREFIX
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <algorithm>
#include <array>
#include <ctime>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <cmath>
#include <vector>

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Triangulation_vertex_base_with_info_3<std::uint32_t, K>;
using Tds = CGAL::Triangulation_data_structure_3<Vb>;
using Delaunay = CGAL::Delaunay_triangulation_3<K, Tds>;

namespace {

using Tet = std::array<std::uint32_t, 4>;

// Relabels by `order` (order[k] = old label of new label k) and writes PREFIX + suffix.
bool write_relabelled(const std::string& path, const std::vector<std::array<double, 3>>& pts,
                      const std::vector<Tet>& tets, const std::vector<std::uint32_t>& order) {
  const std::size_t n = pts.size();
  std::vector<std::uint32_t> label(n);
  std::vector<std::array<double, 3>> sorted(n);
  for (std::size_t k = 0; k < n; ++k) label[order[k]] = std::uint32_t(k), sorted[k] = pts[order[k]];
  std::vector<Tet> out(tets.size());
  for (std::size_t i = 0; i < tets.size(); ++i)
    for (int s = 0; s < 4; ++s) out[i][s] = label[tets[i][s]];
  std::stable_sort(out.begin(), out.end(), [](const Tet& a, const Tet& b) {
    return *std::min_element(a.begin(), a.end()) < *std::min_element(b.begin(), b.end());
  });
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return false;
  const std::uint64_t head[2] = {n, out.size()};
  bool ok = std::fwrite(head, sizeof head, 1, f) == 1 && std::fwrite(sorted.data(), sizeof(sorted[0]), n, f) == n &&
            std::fwrite(out.data(), sizeof(out[0]), out.size(), f) == out.size();
  ok = (std::fclose(f) == 0) && ok;
  return ok;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s N SEED PREFIX\n", argv[0]);
    return 2;
  }
  const std::uint64_t n = std::strtoull(argv[1], nullptr, 10);
  const std::uint64_t seed = std::strtoull(argv[2], nullptr, 10);
  const std::string prefix = argv[3];
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<std::array<double, 3>> pts(n);
  for (auto& p : pts) p = {u(rng), u(rng), u(rng)};
  std::sort(pts.begin(), pts.end());  // along x (ties by y, z): label = index

  // CPU time (CGAL runs on one thread): the machine may be shared.
  const std::clock_t t0 = std::clock();
  std::vector<std::pair<K::Point_3, std::uint32_t>> input;
  input.reserve(n);
  for (std::uint32_t i = 0; i < n; ++i) input.emplace_back(K::Point_3(pts[i][0], pts[i][1], pts[i][2]), i);
  Delaunay dt(input.begin(), input.end());
  const double cgal_seconds = double(std::clock() - t0) / CLOCKS_PER_SEC;

  std::vector<Tet> tets;
  tets.reserve(dt.number_of_finite_cells());
  for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
    tets.push_back({c->vertex(0)->info(), c->vertex(1)->info(), c->vertex(2)->info(), c->vertex(3)->info()});
  }
  std::fprintf(stderr, "cgal_tets: %llu points, %zu tets (%.2f per point), CGAL %.2f CPU s\n", (unsigned long long)n,
               tets.size(), double(tets.size()) / double(n), cgal_seconds);
  std::printf("cgal_seconds %.3f\n", cgal_seconds);

  std::vector<std::uint32_t> order(n);
  for (std::uint32_t i = 0; i < n; ++i) order[i] = i;
  if (!write_relabelled(prefix + ".x.bin", pts, tets, order)) {
    std::perror(prefix.c_str());
    return 3;
  }

  const int slabs = 10;
  const int cells = std::max(1, int(std::lround(std::cbrt(double(n) / 8.0))));
  auto cell_key = [&](std::uint32_t i) {
    const auto& p = pts[i];
    auto c = [&](double v) { return std::min(cells - 1, int(v * cells)); };
    return std::array<int, 4>{int(std::uint64_t(i) * slabs / n), c(p[1]), c(p[2]), c(p[0])};
  };
  std::stable_sort(order.begin(), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return cell_key(a) < cell_key(b); });
  if (!write_relabelled(prefix + ".cells.bin", pts, tets, order)) {
    std::perror(prefix.c_str());
    return 3;
  }
  return 0;
}
