#pragma once
// The retire-to-input-order step of `tetstream field`: pass 1 hands out points in label
// order (the container's sort order); users want them in their input's order. Each
// final point becomes a fixed-size record pushed to an external sort by original index
// (pipeline/external_sort.hpp: in memory when it fits its share of --memory, sorted runs
// on disk otherwise), and the merged stream is written to the .npy files front to back.
// (Neighbours take another way: field_neighbours.hpp.)
#include "io/npy.hpp"
#include "pipeline/external_sort.hpp"
#include "pipeline/field.hpp"
#include "pipeline/field_accumulate.hpp"

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

namespace tetstream::pipeline {

struct PointRecord {
  std::uint64_t original, label;
  double volume, voronoi;
  std::uint64_t hull;
};
struct ByOriginal {
  bool operator()(const PointRecord& a, const PointRecord& b) const { return a.original < b.original; }
};

// DTFE density under the hull convention: 4 m / V, NaN on the hull unless kOpen.
inline double dtfe_density(double mass, double volume, bool hull, HullMode mode) {
  if (hull && mode == HullMode::kNan) return std::numeric_limits<double>::quiet_NaN();
  return 4.0 * mass / volume;
}

// Writes OUTPUT.density.npy and/or OUTPUT.voronoi.npy from the records in original
// order, with masses from `masses` (nullptr: unit masses). Calls by_label(label, rho)
// for every point when set (the grid needs densities by label). Adds the files to
// summary.files and the totals to summary.
void write_point_fields(ExternalSorter<PointRecord, ByOriginal>& records, const FieldOptions& options,
                        std::uint64_t point_count, io::ScalarFileReader* masses,
                        const std::function<void(std::uint64_t, double)>& by_label, FieldSummary& summary);

std::string field_path(const FieldOptions& options, const std::string& what);  // OUTPUT.what.npy

}  // namespace tetstream::pipeline

namespace tetstream::pipeline {
// A density on its way back to label order (the grid with --mass).
struct GridDensity {
  std::uint64_t label;
  double rho;
};
struct ByLabel {
  bool operator()(const GridDensity& a, const GridDensity& b) const { return a.label < b.label; }
};
}  // namespace tetstream::pipeline
