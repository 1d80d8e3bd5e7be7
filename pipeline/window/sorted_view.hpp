#pragma once
// The sorted, duplicate-free points as the windows read them: addressed by label (a
// point's position in the sorted file), with the key samples that bound a key range
// without reading the file, and the global hull's boundary points with their index.
#include "pipeline/files/temp_files.hpp"
#include "pipeline/sort/hull.hpp"
#include "pipeline/sort/point_record.hpp"
#include "pipeline/sort/point_sort.hpp"
#include "pipeline/window/point_index.hpp"

#include <algorithm>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

// The sorted, duplicate-free points, read-only, addressed by label.
struct SortedView {
  PointRecords points;  // the sorted file's records (pipeline/point_record.hpp)
  std::uint64_t count = 0;
  int axis = 0;
  double bbox_min[3], bbox_max[3];
  // Every point on the boundary of the convex hull (hull.hpp), by increasing label:
  // its coordinates, and its label in `original`, with a spatial index of their own.
  // A window's hull facet is a facet of the global hull exactly when none of these
  // points conflicts with it.
  std::vector<SortedPoint> hull_points;
  const PointIndex* hull_index = nullptr;  // over hull_points
  // The global hull's facets (hull.hpp, hull_facet_labels), label triples sorted: a
  // window's hull facet whose labels are here is certified without a query. Empty
  // when unknown (a flat input): the queries decide.
  std::vector<LabelTriple> hull_facets;
  const PointIndex* index = nullptr;  // over points[0, count)
  // When `points` is a read-only file mapping: the tracker that keeps the regions the
  // workers' emptiness queries map within their share of the budget, and hands them
  // back. Null for points in memory (anonymous memory must never be handed back:
  // MADV_DONTNEED would zero it).
  MappedRegions* query_regions = nullptr;

  // The key of every kKeyStride-th label, so that lower_bound and upper_bound search
  // a small in-memory table and then one stride of the file, instead of probing the
  // mapped file all over (a cache and TLB miss each: a quarter of the check's time).
  static constexpr std::uint64_t kKeyStride = 128;
  std::vector<double> key_samples;
  // Fills key_samples. When `points` is a read-only file mapping, release_file_pages
  // hands the pages back as it goes (a sample every 4 KiB touches every page).
  void sample_keys(bool release_file_pages = false);

  double key(std::uint64_t label) const { return points.coord(label, axis); }
  // The same key read through query_regions when the points are a mapped file (pread
  // unless its region is held): a read that faults maps the whole folio of the page
  // cache around it (up to 2 MiB), and the plans' reads, scattered over the whole file
  // (the searches below, each segment's ends), held most of it resident (10^7 points
  // at --memory 100M: 166 MB sampled in the plan phase). key() where the pages are held.
  double read_key(std::uint64_t label) const;
  // First label whose axis coordinate is >= x (count when none).
  std::uint64_t lower_bound(double x) const;
  // First label whose axis coordinate is > x.
  std::uint64_t upper_bound(double x) const;
  // The same from the key samples alone, without reading the points: a label at most
  // lower_bound(x), and one at least upper_bound(x), each within kKeyStride of it
  // (0 and count without samples).
  std::uint64_t lower_bound_below(double x) const;
  std::uint64_t upper_bound_above(double x) const;
  // Bounds on the keys of the labels [first, last) (first < last), from the samples
  // alone when there are any.
  KeyRange key_range(std::uint64_t first, std::uint64_t last) const;
};

// Hands back the pages of the sorted file behind a scan that reads labels in
// increasing order, 4 MiB of records at a time, so that the scan's pages never add
// up in the resident set (window loads, key samples, the hull gather). Does nothing
// when `enabled` is false (anonymous memory, which MADV_DONTNEED would zero).
class ReleaseBehind {
 public:
  ReleaseBehind(const PointRecords& points, std::uint64_t first, bool enabled)
      : points_(points), released_(first), enabled_(enabled) {}
  ~ReleaseBehind() { release_to(reached_); }
  // The scan is at `label`: every chunk wholly below it is handed back.
  void reached(std::uint64_t label) {
    reached_ = std::max(reached_, label + 1);
    if (label >= released_ + kChunk) release_to(label / kChunk * kChunk);
  }

 private:
  static constexpr std::uint64_t kChunk = std::uint64_t(1) << 17;
  void release_to(std::uint64_t end) {
    if (enabled_ && end > released_)
      release_mapped_pages(points_.record(released_), (end - released_) * points_.record_bytes());
    released_ = std::max(released_, end);
  }
  PointRecords points_;
  std::uint64_t released_, reached_ = 0;
  bool enabled_;
};

}  // namespace tetstream::pipeline
