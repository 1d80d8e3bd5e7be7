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

// The in-core kernel's tets of a container's own points (labels = positions in the
// container's point order): what the out-of-core output must equal.
inline std::vector<Quad> incore_quads(const std::string& path) {
  io::TetReader reader(path);
  const std::size_t n = std::size_t(reader.point_count());
  std::vector<double> xyz(3 * n);
  std::vector<std::uint64_t> ids(n);
  reader.read_points(0, n, xyz.data(), ids.data());
  core::Delaunay dt;
  std::vector<Quad> out;
  if (dt.build(xyz.data(), nullptr, n) != core::BuildStatus::kOk) return out;  // empty: never equal to a real output
  dt.for_each_finite_tet([&](const core::VertexId* v) { add_quad(out, v[0], v[1], v[2], v[3]); });
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
