#pragma once
// The plan of the labels into segments and of each segment into zones
// (docs/architecture.md, "Glossary"). A segment owns a range of labels, a slab across
// the sort axis; a zone is a strip of a segment along the strip axis, triangulated
// alone in its window (its points and the buffers around them) by one thread.
#include "pipeline/window/sorted_view.hpp"

#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

// One zone of a segment, for parallel zonal insertion (the paper's section 3): the
// segment's zone points whose coordinate along `axis` lies in [lo, hi). It is
// triangulated alone, in a window of the segment's window points whose coordinate lies
// in [window_lo, window_hi] (the strip and a buffer on each side), plus the hull. Its
// boundary is made exact as a segment's is (docs/certificate.md): the points of the
// segment's label range outside the strip's window count as missing, for the range
// test and the emptiness query alike. axis < 0: the whole segment, no strip.
struct Zone {
  int axis = -1;
  double lo = 0, hi = 0;
  double window_lo = 0, window_hi = 0;
};

struct SegmentPlan {
  std::uint64_t label_begin = 0, label_end = 0;    // labels this segment owns
  std::uint64_t window_begin = 0, window_end = 0;  // labels in its window (zone + buffers)
  double buffer_width = 0;                         // of the buffers (and of its zones')
  // The segment's zones, in increasing strip order; one Zone{} (the whole
  // segment) unless split_into_zones cut it.
  std::vector<Zone> zones{Zone{}};
};

// Splits [first_label, min(end_label, count)) into segments of about `segment_points`
// labels and gives each a window extended by `buffer_width` along the axis on each
// side. (A resumed job plans the labels it has not written yet, a rank under MPI its
// own range; the output does not depend on the plan.)
std::vector<SegmentPlan> plan_segments(const SortedView& view, std::uint64_t segment_points, double buffer_width,
                                       std::uint64_t first_label = 0, std::uint64_t end_label = ~std::uint64_t(0));

// The axis zones are cut along: the longer of the two other than the sort axis.
int strip_axis(const SortedView& view);

// Cuts the segment into `zones` strips along strip_axis, near quantiles of (a sample
// of) its zone points, so that each holds about the same number (within a tenth of a
// zone's share: each cut at the emptiest place near its quantile); fewer when the
// segment has too few points (at least 256 a zone) or too few distinct coordinates.
void split_into_zones(const SortedView& view, SegmentPlan& plan, int zones);

}  // namespace tetstream::pipeline
