#include "pipeline/window/segment_plan.hpp"

#include <algorithm>
#include <limits>

namespace tetstream::pipeline {

int strip_axis(const SortedView& view) {
  const int a1 = (view.axis + 1) % 3, a2 = (view.axis + 2) % 3;
  return view.bbox_max[a1] - view.bbox_min[a1] >= view.bbox_max[a2] - view.bbox_min[a2] ? a1 : a2;
}

std::vector<SegmentPlan> plan_segments(const SortedView& view, std::uint64_t segment_points, double buffer_width,
                                       std::uint64_t first_label, std::uint64_t end_label) {
  std::vector<SegmentPlan> plans;
  end_label = std::min(end_label, view.count);
  if (first_label >= end_label) return plans;
  segment_points = std::max<std::uint64_t>(segment_points, 1);
  const std::uint64_t todo = end_label - first_label;
  const std::uint64_t segments = std::max<std::uint64_t>(1, (todo + segment_points - 1) / segment_points);
  for (std::uint64_t s = 0; s < segments; ++s) {
    SegmentPlan p;
    // Even split, so the last segment is not a sliver.
    p.label_begin = first_label + todo * s / segments;
    p.label_end = first_label + todo * (s + 1) / segments;
    if (p.label_begin == p.label_end) continue;
    p.window_begin = view.lower_bound(view.read_key(p.label_begin) - buffer_width);
    p.window_end = view.upper_bound(view.read_key(p.label_end - 1) + buffer_width);
    p.buffer_width = buffer_width;
    plans.push_back(p);
  }
  return plans;
}

namespace {

// Cuts `zones` strips along `axis` from the sorted sample of the segment's zone
// coordinates (split_into_zones).
void cut_strips(const std::vector<double>& coords, SegmentPlan& plan, int axis, int zones) {
  plan.zones.assign(1, Zone{});
  if (zones <= 1 || coords.empty()) return;
  // Each cut at the emptiest place near its quantile: of the sampled coordinates
  // within a tenth of a zone's share on either side, the one with the fewest others
  // within the buffer width of it. A strip's window holds the points within the
  // buffer width of its cuts, and a cut through a dense cluster puts thousands there:
  // redundant insertions, and windows that outgrow their share of the budget.
  // Zones stay within +-10% of an equal share (their outputs are planned by it).
  const std::size_t m = coords.size();
  const double w = plan.buffer_width;
  std::vector<double> cuts;  // increasing cut values
  for (int z = 1; z < zones; ++z) {
    const std::size_t at = m * std::size_t(z) / std::size_t(zones), slack = m / std::size_t(zones) / 10;
    const std::size_t first = at > slack ? at - slack : 0, last = std::min(m - 1, at + slack);
    std::size_t best = at, best_count = std::numeric_limits<std::size_t>::max();
    std::size_t lo = first, hi = first;  // [lo, hi): the samples within w of coords[i]
    for (std::size_t i = first; i <= last; ++i) {
      while (lo < i && coords[lo] < coords[i] - w) ++lo;
      while (lo > 0 && coords[lo - 1] >= coords[i] - w) --lo;
      hi = std::max(hi, i);
      while (hi < m && coords[hi] <= coords[i] + w) ++hi;
      // The cut value must differ from its neighbours' (strips need positive width):
      // the first of a run of equal coordinates stands for the run.
      if (i > first && coords[i] == coords[i - 1]) continue;
      if (hi - lo < best_count) best_count = hi - lo, best = i;
    }
    if (cuts.empty() || coords[best] > cuts.back()) cuts.push_back(coords[best]);
  }
  const double inf = std::numeric_limits<double>::infinity();
  plan.zones.assign(cuts.size() + 1, Zone{});
  for (std::size_t z = 0; z < plan.zones.size(); ++z) {
    Zone& st = plan.zones[z];
    st.axis = axis;
    st.lo = z == 0 ? -inf : cuts[z - 1];
    st.hi = z == cuts.size() ? inf : cuts[z];
    st.window_lo = st.lo - plan.buffer_width;
    st.window_hi = st.hi + plan.buffer_width;
  }
}

}  // namespace

void split_into_zones(const SortedView& view, SegmentPlan& plan, int zones) {
  const std::uint64_t segment_points = plan.label_end - plan.label_begin;
  zones = int(std::clamp<std::uint64_t>(std::uint64_t(std::max(zones, 1)), 1,
                                        std::max<std::uint64_t>(segment_points / 256, 1)));
  plan.zones.assign(1, Zone{});
  if (zones == 1) return;
  // Quantiles of a sample (at most ~64k points, every stride-th label): the zones
  // need about equal counts, not exact ones, and the sample keeps this pass cheap.
  const int axis = strip_axis(view);
  const std::uint64_t stride = std::max<std::uint64_t>(1, segment_points / 65536);
  std::vector<double> coords;
  coords.reserve(std::size_t(segment_points / stride + 1));
  for (std::uint64_t l = plan.label_begin; l < plan.label_end; l += stride)
    coords.push_back(view.points.coord(l, axis));
  std::sort(coords.begin(), coords.end());
  cut_strips(coords, plan, axis, zones);
}

}  // namespace tetstream::pipeline
