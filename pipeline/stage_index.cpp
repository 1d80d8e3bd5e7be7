#include "pipeline/stage_index.hpp"

#include "core/error.hpp"
#include "pipeline/hull.hpp"
#include "pipeline/stage.hpp"
#include "pipeline/temp_files.hpp"

#include <algorithm>
#include <exception>
#include <vector>

namespace tetstream::pipeline {

void IndexStage::prepare() {
  try {
    // From the file's start to the records' end: a points section inside the partial
    // output is mapped with the header before it (a few hundred bytes), so that the
    // mapping's offsets are the file's (MappedRegions reads by them), and without
    // the frames the writer appends after it.
    mapping_.open(sorted_.path, std::size_t(sorted_.offset + sorted_.count * sorted_.layout.bytes()));
  } catch (const std::exception& e) {
    throw IoError(sorted_.path + ": cannot map: " + e.what());
  }
  view_.points = PointRecords(mapping_.data() + sorted_.offset, sorted_.layout);
  view_.count = sorted_.count;
  view_.axis = sorted_.axis;
  for (int k = 0; k < 3; ++k) view_.bbox_min[k] = sorted_.bbox_min[k], view_.bbox_max[k] = sorted_.bbox_max[k];
}

void IndexStage::run() {
  const ScopedThreads threads(threads_);
  SortedView& view = view_;
  view.sample_keys(/*release_file_pages=*/true);
  // An index over sorted records spread in the job's bounding box (its blocks' size
  // from their count in that box).
  auto build_index = [&view](PointIndex& into, const PointRecords& points, std::uint64_t count, bool release_pages) {
    double volume = 1;
    for (int k = 0; k < 3; ++k) volume *= view.bbox_max[k] - view.bbox_min[k];
    into.build(points, count, view.axis,
               PointIndex::block_points_for(count, view.bbox_max[view.axis] - view.bbox_min[view.axis], volume),
               release_pages);
  };
  build_index(index_, view.points, view.count, /*release_pages=*/true);
  view.index = &index_;

  // The global hull: the hull of the runs' candidates.
  {
    std::vector<double> xyz;
    // In label order, handing the pages back behind: a shell's hull candidates are
    // all over the file.
    ReleaseBehind release(view.points, 0, true);
    for (std::uint64_t label : sorted_.hull_labels) {
      double p[3];
      view.points.xyz(label, p);
      xyz.insert(xyz.end(), p, p + 3);
      release.reached(label);
    }
    std::vector<std::uint32_t> hull = hull_vertex_candidates(xyz.data(), sorted_.hull_labels.size());
    std::sort(hull.begin(), hull.end());  // candidates are sorted by label: so are these
    for (std::uint32_t i : hull) {
      SortedPoint p;
      std::copy_n(&xyz[3 * std::size_t(i)], 3, p.xyz);
      p.original = sorted_.hull_labels[i];
      view.hull_points.push_back(p);
    }
    release_mapped_pages(mapping_.data(), mapping_.size());
  }
  if (!view.hull_points.empty()) build_index(hull_index_, records_of(view.hull_points.data()), view.hull_points.size(), false);
  view.hull_index = &hull_index_;
}

}  // namespace tetstream::pipeline
