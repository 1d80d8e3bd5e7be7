#pragma once
// Point sets and helpers for the periodic tests (unit/pipeline/periodic, cgal/):
// points in the unit box on a dyadic grid (so every image p - 1 is a double, whatever
// the margin), lattices, exactly cospherical points, and the periodic tets of a
// container as comparable keys (labels sorted, offsets relative to the smallest).
#include "io/point_writer.hpp"
#include "io/tet_periodic.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/periodic/tet_records.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <tuple>
#include <vector>

namespace tetstream::testing_util {

// Uniform in [0, 1)^3, each coordinate a multiple of 2^-30: general position for
// every practical purpose, and exact images at any margin.
inline std::vector<double> dyadic_uniform(std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<double> xyz(3 * n);
  for (double& x : xyz) x = std::ldexp(double(rng() >> 34), -30);
  return xyz;
}

// The k^3 lattice of spacing 1/k (k a power of two: exact), the most degenerate input.
inline std::vector<double> lattice(int k) {
  std::vector<double> xyz;
  for (int i = 0; i < k; ++i)
    for (int j = 0; j < k; ++j)
      for (int l = 0; l < k; ++l) xyz.insert(xyz.end(), {double(i) / k, double(j) / k, double(l) / k});
  return xyz;
}

// The 48 points (±3, ±4, ±12)/64 and their permutations around (1/2, 1/2, 1/2): all on
// one sphere of radius 13/64, exactly.
inline std::vector<double> cospherical_48() {
  std::vector<double> xyz;
  const int base[3] = {3, 4, 12};
  int perm[3] = {0, 1, 2};
  do {
    for (int s = 0; s < 8; ++s) {
      for (int k = 0; k < 3; ++k) xyz.push_back(0.5 + ((s >> k & 1) ? -1 : 1) * base[perm[k]] / 64.0);
    }
  } while (std::next_permutation(perm, perm + 3));
  return xyz;
}

inline void write_f64(const std::string& path, const std::vector<double>& xyz) {
  auto w = io::create_points(path, {}, xyz.size() / 3);
  w->write(xyz.data(), xyz.size() / 3);
  w->commit();
}

// A periodic tet, comparable: labels sorted, each with its offset relative to the
// smallest, as (label, code) pairs.
using PeriodicKey = std::array<std::pair<std::uint64_t, int>, 4>;

inline PeriodicKey periodic_key(const std::uint64_t label[4], const int off[4][3]) {
  int mi = 0;
  for (int i = 1; i < 4; ++i) mi = label[i] < label[mi] ? i : mi;
  PeriodicKey k;
  for (int i = 0; i < 4; ++i) {
    int o[3] = {off[i][0] - off[mi][0], off[i][1] - off[mi][1], off[i][2] - off[mi][2]};
    k[std::size_t(i)] = {label[i], 100 * o[0] + 10 * o[1] + o[2]};
  }
  std::sort(k.begin(), k.end());
  return k;
}

// The container's periodic tets, by original index (the input's order).
inline std::vector<PeriodicKey> container_periodic_keys(const std::string& path) {
  const io::TetReader r(path, io::TetReader::Periodic::kAccept);
  const io::PeriodicOffsetsReader offsets(r);
  std::vector<std::uint64_t> ids(r.point_count());
  r.read_points(0, ids.size(), nullptr, ids.data());
  std::vector<PeriodicKey> out;
  pipeline::periodic::for_each_stored_tet(r, offsets,
                                          [&](const pipeline::periodic::KeptTet& t, std::uint64_t, std::size_t) {
                                            int off[4][3];
                                            pipeline::periodic::stored_offsets(t, off);
                                            std::uint64_t orig[4];
                                            for (int j = 0; j < 4; ++j) orig[j] = ids[t.v[j]];
                                            out.push_back(periodic_key(orig, off));
                                          });
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace tetstream::testing_util
