#pragma once
// `tetstream field` on a periodic container (docs/periodic.md, "Fields"): per point, in
// the input's order, the DTFE density rho_i = 4 m_i / W_i (W_i the volume of i's star)
// and the Voronoi volume, and the DTFE field sampled on a grid over the box. On the
// torus there is no hull: every point has a closed star and a bounded cell, so no
// value is NaN; the stars cover the box 4 times (sum W_i = 4 Lx Ly Lz) and the cells
// once (sum of Voronoi volumes = Lx Ly Lz).
//
// Memory: two doubles a point and the grid (this path holds them; it is not yet the
// out-of-core field of pipeline/field/). Serial sums in the container's order, so the
// files do not depend on the thread count.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::pipeline::periodic {

struct PeriodicFieldOptions {
  std::string prefix;
  bool density = false, voronoi = false;
  std::array<std::uint64_t, 3> grid{0, 0, 0};  // cells a side; 0: no grid
  bool float32 = false;
};

struct PeriodicFieldResult {
  std::vector<std::string> files;
  std::uint64_t points = 0, tets = 0, nan_points = 0, nan_cells = 0;
  double mass_check = 0;   // sum_i rho_i W_i / 4: N, up to rounding
  double voronoi_sum = 0;  // sum of Voronoi volumes: the box's volume, up to rounding
  double star_sum = 0;     // sum_i W_i: 4 times the box's volume
};

PeriodicFieldResult periodic_field(const std::string& container, const PeriodicFieldOptions& options);

}  // namespace tetstream::pipeline::periodic
