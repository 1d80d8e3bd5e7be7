#pragma once
// The retire-to-input-order step of `tetstream field`: pass 1 hands out points in label
// order (the container's sort order); users want them in their input's order. The
// original index is a dense key (below the input's point count), so when one slot per
// original index fits the points' share of --memory each final point is simply placed
// at its original index (a column per value asked for, and a byte of flags), and the
// columns are read front to back: no sort. Otherwise each point becomes a fixed-size
// record pushed to an external sort by original index (pipeline/external_sort.hpp:
// sorted runs on disk). Both hand the same records, in the same order, to the writer,
// so the files do not depend on which way they went. (Neighbours take another way:
// field_neighbours.hpp.)
#include "core/page_array.hpp"
#include "io/npy.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/field/field.hpp"
#include "pipeline/field/accumulate.hpp"

#include <cstdint>
#include <functional>
#include <span>
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

// The final points in original order: placed (when they fit) or sorted.
class PointOrder {
 public:
  // original_end: every original index is below it. memory_bytes: the points' share of
  // the budget; sort: the external sort's options, used only when the columns do not fit.
  PointOrder(const FieldOptions& options, std::uint64_t original_end, std::uint64_t memory_bytes,
             ExternalSortOptions sort);
  void add(std::span<const FinalPoint> points);  // any order, each point once
  bool placed() const { return !sorter_; }
  // Ends the input and calls visit(std::span<const PointRecord>) with consecutive
  // batches of the records in original order. Call once.
  void merge(const std::function<void(std::span<const PointRecord>)>& visit);

 private:
  static constexpr std::uint8_t kPresent = 1, kHull = 2;
  std::uint64_t end_;
  core::PageArray<double> volume_, voronoi_;  // empty when not asked for
  core::PageArray<std::uint64_t> label_;      // only for the grid's densities with --mass
  core::PageArray<std::uint8_t> flags_;
  std::unique_ptr<ExternalSorter<PointRecord, ByOriginal>> sorter_;
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
void write_point_fields(PointOrder& records, const FieldOptions& options, std::uint64_t point_count,
                        io::ScalarFileReader* masses, const std::function<void(std::uint64_t, double)>& by_label,
                        FieldSummary& summary);

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
