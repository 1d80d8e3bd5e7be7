#pragma once
// Tet sets for comparisons in tests: a container's tets, or a triangulation's, as a
// sorted list of sorted label quadruples (orientation and order do not matter).
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
    for (std::size_t i = 0; i < labels.size(); i += 4) add_quad(out, labels[i], labels[i + 1], labels[i + 2], labels[i + 3]);
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace tetstream::testing_util
