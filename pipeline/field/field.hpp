#pragma once
// `tetstream field`: per-point fields computed out of core from a .tets container
// (docs/fields.md): DTFE densities, Voronoi cell volumes, Delaunay neighbours, and the
// DTFE density sampled on a grid.
//
//   FieldOptions o;  o.input = "out.tets";  o.output = "out";  o.density = true;
//   FieldSummary s = compute_fields(o);   // writes out.density.npy
//
// Stages (one file each):
//   field_window      the frame batches and the label window, from the frame index
//   field_points      the window's coordinates and original indices (a ring)
//   field_geometry    what one tet adds to its vertices; exact point location
//   field_accumulate  pass 1: per-point sums, retired in label order
//   field_output      the retire-to-input-order step (placed by original index, or sorted)
//   field_neighbours  the neighbour rows back in input order (buckets by original index)
//   field_grid        pass 2 (with --grid): the density on a grid, slab by slab
// Outputs are in the input's order: entry i belongs to the container point with the
// i-th smallest original index (the input's order, less the exact duplicates `run`
// merged; with none, exactly the input's order).
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::pipeline {

enum class HullMode { kNan, kOpen };
enum class FieldType { kFloat32, kFloat64 };

struct FieldOptions {
  std::string input;   // the .tets container
  std::string output;  // prefix: OUTPUT.density.npy, OUTPUT.voronoi.npy, ...
  bool density = false;
  bool voronoi = false;
  bool neighbours = false;
  std::array<std::uint64_t, 3> grid{0, 0, 0};  // all 0: no grid
  bool has_box = false;
  std::array<double, 6> box{};  // xmin, ymin, zmin, xmax, ymax, zmax; default: the points' bbox
  HullMode hull = HullMode::kNan;
  FieldType dtype = FieldType::kFloat64;
  bool neighbour_int64 = false;  // the neighbour arrays in int64 even when int32 holds them
  std::string mass;              // per-point masses in input order (.npy 1-D f4/f8, or raw little-endian f64); empty: 1
  std::uint64_t memory_bytes = std::uint64_t(1) << 30;
  std::string tmpdir;  // empty: $TMPDIR, else the output's directory
  bool progress = true;
  std::uint64_t batch_tets = 0;        // 0: from the budget (tests force small batches)
  std::uint64_t ring_labels = 0;       // a power of two; 0: from the budget (tests force far labels)
  std::uint64_t neighbour_memory = 0;  // bytes for the neighbour rows; 0: from the budget (tests force spills)
  std::uint64_t point_memory =
      0;  // bytes for placing the points by original index; 0: from the budget (tests force the sort)

  bool grid_wanted() const { return grid[0] > 0; }
  void validate() const;  // throws UsageError
};

struct FieldFile {
  std::string what, path;
};

struct FieldSummary {
  std::uint64_t points = 0, tets = 0, frames = 0, batches = 0;
  std::uint64_t hull_points = 0;
  std::uint64_t window_labels = 0, ring_labels = 0;  // the widest window, its ring
  std::uint64_t neighbour_entries = 0;
  std::string neighbour_dtype;                     // "int32" or "int64"; empty without --neighbours
  std::uint64_t far_labels_peak = 0;               // most labels held beyond the dense window
  std::uint64_t grid_points = 0, grid_inside = 0;  // grid points, those inside the hull
  double total_mass = 0.0;
  double tet_volume = 0.0;        // sum of the tets' volumes (the hull's volume)
  double interior_voronoi = 0.0;  // sum of the interior points' Voronoi volumes
  // The same plus the hull points' partial sums (their cells cut by the pieces of the
  // hull tets): every tet's pieces tile it, so this equals tet_volume up to rounding.
  double voronoi_total = 0.0;
  std::uint64_t memory_planned = 0;
  double seconds = 0.0;
  std::vector<FieldFile> files;
};

FieldSummary compute_fields(const FieldOptions& options);

// "32" -> {32, 32, 32}; "64,32,16" -> {64, 32, 16}. Throws UsageError.
std::array<std::uint64_t, 3> parse_grid(const std::string& text);
// "xmin,ymin,zmin,xmax,ymax,zmax". Throws UsageError.
std::array<double, 6> parse_box(const std::string& text);

}  // namespace tetstream::pipeline
