#pragma once
// Pass 2 of `tetstream field --grid`: the DTFE density, linear in each tet, sampled at
// the centres of an NX x NY x NZ grid over a box, written as a C-order .npy array of
// shape (NX, NY, NZ) (x slowest).
//
// Each grid point takes its value from the one tet that contains it, found with exact
// predicates (field_geometry.hpp: tet_contains, whose perturbation decides points on
// shared faces and edges the same way in every tet), so a value is written exactly
// once, whatever the threads; points outside the hull stay NaN.
//
// Slab by slab: the points are sorted along `axis` (the container's sort axis; in
// version 2 brick by brick, format.md §3.4), so a tet's vertices lie at or beyond the
// axis coordinate of its smallest label (version 2: of the top of the bricks before
// that label's). After a batch, the planes of grid points (perpendicular to the axis)
// below that floor for the next batch's first label are final and leave memory: the
// planes held are those the window's tets span, and in version 2 a brick more. Along
// x (axis 0) a final plane is the next piece of the file; along y or z, its values go
// through an external sort by C-order index.
#include "io/tet_reader.hpp"
#include "pipeline/field/field.hpp"
#include "pipeline/field/window.hpp"

#include <array>
#include <cstdint>
#include <string>

namespace tetstream::pipeline {

class Progress;

struct GridSpec {
  std::array<std::uint64_t, 3> n{0, 0, 0};
  std::array<double, 3> lo{}, hi{};
  double centre(int axis, std::uint64_t i) const {
    return lo[std::size_t(axis)] +
           (double(i) + 0.5) * (hi[std::size_t(axis)] - lo[std::size_t(axis)]) / double(n[std::size_t(axis)]);
  }
};

struct GridStats {
  std::uint64_t inside = 0;       // grid points inside the hull
  std::uint64_t peak_planes = 0;  // planes held at once
};

// rho_path: a file of float64 densities in label order (one per point). Writes
// options.output + ".grid.npy". plane_bytes_budget caps the planes held.
GridStats sample_grid(const io::TetReader& reader, const BatchPlan& plan, const GridSpec& grid, int axis,
                      const std::string& rho_path, const FieldOptions& options, std::uint64_t plane_bytes_budget,
                      const std::string& tmpdir, Progress* progress);

}  // namespace tetstream::pipeline
