#pragma once
// Tet sets for comparisons in tests: a container's tets, or a triangulation's, as a
// sorted list of sorted label quadruples (orientation and order do not matter).
#include "core/delaunay.hpp"
#include "io/point_generators.hpp"
#include "io/point_writer.hpp"
#include "io/tet_reader.hpp"

#include <algorithm>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::testing_util {

using Quad = std::array<std::uint64_t, 4>;

inline void add_quad(std::vector<Quad>& out, std::uint64_t a, std::uint64_t b, std::uint64_t c, std::uint64_t d) {
  Quad q{a, b, c, d};
  std::sort(q.begin(), q.end());
  out.push_back(q);
}

inline std::vector<Quad> container_quads(const std::string& path) {
  io::TetReader reader(path);
  std::vector<Quad> out;
  std::vector<std::uint64_t> labels;
  for (std::uint64_t k = 0; k < reader.frame_count(); ++k) {
    reader.read_frame(k, labels);
    for (std::size_t i = 0; i < labels.size(); i += 4)
      add_quad(out, labels[i], labels[i + 1], labels[i + 2], labels[i + 3]);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// The in-core kernel's tets of a container's own points, as container labels: what the
// out-of-core output must equal. The kernel perturbs by the points' positions in its
// input, so it is given them in the container's perturbation order (format.md §3.4):
// the labels' for version 1, the sort order from the sort axis for version 2.
inline std::vector<Quad> incore_quads(const std::string& path) {
  io::TetReader reader(path);
  const std::size_t n = std::size_t(reader.point_count());
  std::vector<double> xyz(3 * n);
  std::vector<std::uint64_t> ids(n);
  reader.read_points(0, n, xyz.data(), ids.data());
  std::vector<std::uint64_t> label(n);  // label[i]: the label of the kernel's point i
  for (std::size_t i = 0; i < n; ++i) label[i] = i;
  if (const int a = io::perturbation_axis(reader); a >= 0) {
    const auto key = [&](std::uint64_t l) {
      return std::array<double, 3>{xyz[3 * l + std::size_t(a)], xyz[3 * l + std::size_t((a + 1) % 3)],
                                   xyz[3 * l + std::size_t((a + 2) % 3)]};
    };
    std::sort(label.begin(), label.end(), [&](std::uint64_t p, std::uint64_t q) { return key(p) < key(q); });
    std::vector<double> ordered(3 * n);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t k = 0; k < 3; ++k) ordered[3 * i + k] = xyz[3 * label[i] + k];
    xyz.swap(ordered);
  }
  core::Delaunay dt;
  std::vector<Quad> out;
  if (dt.build(xyz.data(), nullptr, n) != core::BuildStatus::kOk) return out;  // empty: never equal to a real output
  dt.for_each_finite_tet(
      [&](const core::VertexId* v) { add_quad(out, label[v[0]], label[v[1]], label[v[2]], label[v[3]]); });
  std::sort(out.begin(), out.end());
  return out;
}

// A generated point set (io/point_generators.hpp) as xyz triples.
inline std::vector<double> generated_points(io::Distribution dist, std::uint64_t n, std::uint64_t seed) {
  io::GeneratorOptions g;
  g.dist = dist;
  g.n = n;
  g.seed = seed;
  const io::PointGenerator gen(g);
  std::vector<double> xyz(3 * gen.count());
  gen.generate(0, gen.count(), xyz.data());
  return xyz;
}

// Writes xyz as a raw float64 point file.
inline void write_points_file(const std::string& path, const std::vector<double>& xyz) {
  auto w = io::create_points(path, {}, xyz.size() / 3);
  w->write(xyz.data(), xyz.size() / 3);
  w->commit();
}

}  // namespace tetstream::testing_util
