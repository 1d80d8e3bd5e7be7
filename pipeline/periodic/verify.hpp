#pragma once
// `tetstream verify` of a periodic container (docs/periodic.md, "Verify"): from the
// file alone, independently of how it was made,
//   - every tet positively oriented (exact orient3d on its vertices' exact images);
//   - every facet (three labels and their offsets) shared by exactly two tets, from
//     opposite sides, and locally Delaunay: the opposite vertex of one tet outside the
//     other's circumsphere (exact insphere with the job's perturbation, the points'
//     lexicographic order, which translations keep);
//   - the volumes summing to Lx Ly Lz: with their proved rounding bounds below half
//     the box, the covering's degree is exactly 1;
//   - Euler characteristic V - E + F - T = 0.
// A closed, positively oriented, locally Delaunay triangulation covering the torus
// once lifts to a locally Delaunay triangulation of space, which is Delaunay.
#include <cstdint>
#include <string>

namespace tetstream::pipeline::periodic {

struct PeriodicVerifyReport {
  bool ok = false;
  std::string problem;  // the first problem found, empty when ok
  std::uint64_t points = 0, tets = 0, vertices = 0, edges = 0, facets = 0;
  std::uint64_t bad_orientation = 0, unpaired = 0, not_delaunay = 0, inexact = 0;
  std::int64_t euler = 0;
  long double volume = 0, expected = 0, volume_bound = 0;
};

PeriodicVerifyReport verify_periodic(const std::string& path, std::uint64_t memory_bytes, const std::string& dir);

}  // namespace tetstream::pipeline::periodic
