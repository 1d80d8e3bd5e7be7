#include "pipeline/window/zone_plan.hpp"

#include "pipeline/util/memory_budget.hpp"
#include "pipeline/util/progress.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <utility>

namespace tetstream::pipeline {

namespace {

// Bytes per window point at the kernel's peak: tets (~6.75 x 32 bytes), the kernel's
// coordinate copy and vertex arrays, the window's coordinates and labels, the mapped
// sorted record and the spatial index, with headroom for the allocator; calibrated on
// the peak resident memory of uniform runs (scripts/bench-memory checks it holds).
constexpr double kWindowBytesPerPoint = 480;
// Bytes per zone point for the emitted tets (ZoneTets: ~6.8 tets of 4 x 4-byte local
// ids, and 8-byte labels for the zone's window, ~1.2 points per zone point).
constexpr double kOutputBytesPerPoint = 125;

// The windows' share of the ledger for a budget (pipeline/memory_budget.hpp).
double window_share(std::uint64_t memory_bytes, std::size_t frame_tets, const PlanInputs& in, int threads) {
  MemoryBudget budget(memory_bytes, in.points, threads, omp_get_num_procs());
  if (frame_tets != 0) budget.set_frame_tets(frame_tets);
  return budget.plan_triangulate(in.index_bytes).window_bytes;
}

// The plan for o.memory_bytes, or none when the budget cannot hold a window.
std::optional<ZonePlan> try_plan(const PlanInputs& in, const PlanOptions& o, int threads) {
  double extent[3], volume = 1;
  for (int k = 0; k < 3; ++k) {
    extent[k] = in.extent[k];
    volume *= std::max(extent[k], 1e-300);
  }
  const double n = double(in.points);
  ZonePlan plan;
  // The spacing the buffers are measured in: the bounding box's mean spacing, or the
  // index leaves' 90th percentile when smaller. On uniform points the two agree (the
  // percentile is the mean); on a shell or in clusters the mean is several times the
  // spacing where the points are, and buffers that thick are mostly redundant
  // insertions. The 90th percentile rather than the
  // median keeps the sparse regions of mixed inputs from thin buffers and many queries.
  const double mean_spacing = std::cbrt(volume / n), leaf_spacing = in.leaf_spacing;
  plan.buffer_width = o.buffer_spacings * (leaf_spacing > 0 ? std::min(leaf_spacing, mean_spacing) : mean_spacing);
  const double w = plan.buffer_width;
  const double axis_buffers = std::min(n, 2 * w * n / std::max(extent[in.axis], 1e-300));
  const double strip_extent = std::max(extent[in.strip_axis], 1e-300);
  const double t = double(threads);
  const double available = window_share(o.memory_bytes, o.frame_tets, in, threads);
  auto share = [&](int k) { return k == 1 ? 1.0 : std::min(1.0, 1.0 / k + 2 * w / strip_extent); };
  auto evaluate = [&](int k, double segment_points) {  // redundancy, memory
    const double window = (segment_points + axis_buffers) * share(k);
    const double zone = segment_points / k;
    const double memory = t * window * kWindowBytesPerPoint + (double(k) + t - 1) * zone * kOutputBytesPerPoint;
    return std::pair{window / zone - 1, memory};
  };
  auto largest_segment = [&](int k) {  // S with memory(S) = available (linear in S)
    const double fixed = evaluate(k, 0).second;
    return (available - fixed) / (evaluate(k, 1).second - fixed);
  };
  int first_k = 1, last_k = 256;
  if (o.zones > 0)
    first_k = last_k = o.zones;
  else if (o.segment_points > 0)
    last_k = 1;  // --zone-points alone: whole segments
  double best = std::numeric_limits<double>::infinity();
  for (int k = first_k; k <= last_k; ++k) {
    const double s = o.segment_points > 0 ? double(o.segment_points) : std::min(n, largest_segment(k));
    // Zones under 1000 points: the budget is too small for this k (for k = 1, for
    // the input), or the input too small for k zones.
    if (o.segment_points == 0 && s < std::min(n, 1000.0 * k)) continue;
    // Fewer zones than threads leave threads idle, even when the input fits one
    // window: an input of at least 50,000 points a thread gets a zone a thread.
    const double units = std::ceil(n / std::max(s, 1.0)) * k;
    if (o.zones == 0 && o.segment_points == 0 && units < t && n >= 50000 * t) continue;
    const double r = evaluate(k, s).first;
    if (r < best - 1e-9)
      best = r, plan.zones = k, plan.segment_points = std::uint64_t(s), plan.window_bytes = evaluate(k, s).second;
  }
  if (plan.segment_points == 0) return std::nullopt;
  plan.available = available;
  plan.buffer_spacings = o.buffer_spacings;
  plan.fixed = o.zones > 0 || o.segment_points > 0;
  return plan;
}

}  // namespace

PlanInputs plan_inputs(const SortedView& view, const PointIndex& index) {
  PlanInputs in;
  in.points = view.count;
  for (int k = 0; k < 3; ++k) in.extent[k] = view.bbox_max[k] - view.bbox_min[k];
  in.axis = view.axis;
  in.strip_axis = strip_axis(view);
  in.leaf_spacing = index.leaf_spacing_quantile(0.9);
  in.index_bytes = std::uint64_t(index.memory_bytes()) + view.hull_points.capacity() * sizeof(SortedPoint) +
                   view.hull_facets.capacity() * sizeof(LabelTriple) +
                   (view.hull_index ? std::uint64_t(view.hull_index->memory_bytes()) : 0);
  return in;
}

// The plan for the budget; when it cannot hold a window, a UsageError that names the
// smallest budget that can (to a mebibyte, found by bisection: the plan is cheap).
ZonePlan plan_for_budget(const PlanInputs& in, const PlanOptions& o, int threads) {
  if (std::optional<ZonePlan> plan = try_plan(in, o, threads)) return *plan;
  PlanOptions larger = o;
  auto works = [&](std::uint64_t bytes) {
    larger.memory_bytes = bytes;
    return try_plan(in, larger, threads).has_value();
  };
  std::uint64_t lo = o.memory_bytes, hi = std::max<std::uint64_t>(2 * lo, std::uint64_t(64) << 20);
  constexpr std::uint64_t kMost = std::uint64_t(1) << 50;
  while (hi < kMost && !works(hi)) lo = hi, hi *= 2;
  if (hi >= kMost) throw UsageError("no memory budget can hold a window of this input");
  while (hi - lo > (std::uint64_t(1) << 20)) {
    const std::uint64_t mid = lo + (hi - lo) / 2;
    (works(mid) ? hi : lo) = mid;
  }
  const std::uint64_t need_mib = (hi + o.reserved_bytes + (std::uint64_t(1) << 20) - 1) >> 20;
  const std::string points =
      o.stated_points != 0 && o.stated_points < in.points
          ? std::to_string(o.stated_points) + " points and " + std::to_string(in.points - o.stated_points) + " images"
          : std::to_string(in.points) + " points";
  throw UsageError("--memory " + human_bytes(double(o.stated_bytes != 0 ? o.stated_bytes : o.memory_bytes)) +
                   " is too small for this input (" + points + "): use --memory " + std::to_string(need_mib) +
                   "M or more");
}

namespace {

// Points in a zone's window (its strip's window within the segment's window
// labels), estimated from every stride-th label of the segment's window.
std::uint64_t estimate_window(const SortedView& view, const SegmentPlan& p, const Zone& st) {
  const std::uint64_t n = p.window_end - p.window_begin;
  if (st.axis < 0 || n == 0) return n;
  const std::uint64_t stride = std::max<std::uint64_t>(1, n / 16384);
  std::uint64_t in = 0, seen = 0;
  for (std::uint64_t l = p.window_begin; l < p.window_end; l += stride, ++seen) {
    const double c = view.points.coord(l, st.axis);
    in += c >= st.window_lo && c <= st.window_hi;
  }
  return std::uint64_t(double(n) * double(in) / double(seen));
}

// The segments of segment_points labels each and their zones, with the windows' bytes
// as their points are estimated: the largest run of `threads` zones' windows
// consecutive in the order they start (zone_start_order), and the zones' outputs. local_buffers: each segment's buffers
// at its own points' spacing.
SegmentCut measure_cut(const SortedView& view, const ZonePlan& plan, std::uint64_t segment_points, bool local_buffers,
                       std::uint64_t first_label, double t, std::uint64_t end_label) {
  SegmentCut cut;
  cut.plans = plan_segments(view, segment_points, plan.buffer_width, first_label, end_label);
  // The segments' bounds were found by binary searches over the whole mapped file, and
  // a read that faults maps its whole folio (up to 2 MiB): at 10^7 points and --memory
  // 100M, 110 MiB of the file were resident before the first zone. Handed back here.
  if (view.query_regions) release_mapped_pages(view.points.record(0), view.count * view.points.record_bytes());
  std::uint64_t largest_zone = 0, zones = 1;
  std::vector<std::uint64_t> windows;  // each zone's, in the order the zones run
  for (SegmentPlan& p : cut.plans) {
    // The median leaf spacing of the segment's own labels: a slab through a dense
    // cluster then has buffers as many of its spacings thick as the plan's.
    const double local = local_buffers && view.index
                             ? plan.buffer_spacings * view.index->leaf_spacing_quantile(0.5, p.label_begin, p.label_end)
                             : 0;
    if (local > 0 && local < p.buffer_width) {
      p.buffer_width = local;
      p.window_begin = view.lower_bound(view.read_key(p.label_begin) - local);
      p.window_end = view.upper_bound(view.read_key(p.label_end - 1) + local);
    }
    split_into_zones(view, p, plan.zones);
    for (std::size_t z : zone_start_order(p.zones.size())) {
      windows.push_back(estimate_window(view, p, p.zones[z]));
      cut.largest_window = std::max(cut.largest_window, windows.back());
    }
    largest_zone =
        std::max<std::uint64_t>(largest_zone, (p.label_end - p.label_begin + p.zones.size() - 1) / p.zones.size());
    zones = std::max<std::uint64_t>(zones, p.zones.size());
    // The samples touch about every page of the segment's window: hand them back
    // now, or the whole mapped file would be resident before the first zone starts
    // (a mapped file's only: MADV_DONTNEED would zero points held in memory). All of
    // the file's pages, not the window's: a read maps the whole folio around it (up to
    // 2 MiB), past a small window's ends, and what a window's release left of its
    // folios added up over the plan's segments (10^7 points at --memory 100M: 49 MiB
    // of the file resident, its share 12.5 MiB). Pages not mapped cost nothing here.
    if (view.query_regions) release_mapped_pages(view.points.record(0), view.count * view.points.record_bytes());
  }
  // The zones run in their start order, `threads` at a time: the windows in flight
  // are about `threads` consecutive ones, and the largest such run is what the kernels hold.
  const std::size_t run = std::min<std::size_t>(std::size_t(t), windows.size());
  std::uint64_t in_flight = 0, sum = 0;
  for (std::size_t i = 0; i < windows.size(); ++i) {
    sum += windows[i] - (i >= run ? windows[i - run] : 0);
    if (i + 1 >= run) in_flight = std::max(in_flight, sum);
  }
  cut.window_bytes =
      double(in_flight) * kWindowBytesPerPoint + (double(zones) + t - 1) * double(largest_zone) * kOutputBytesPerPoint;
  return cut;
}

}  // namespace

std::vector<std::size_t> zone_start_order(std::size_t zones) {
  std::vector<std::size_t> order;
  order.reserve(zones);
  for (std::size_t first : {0, 1})
    for (std::size_t z = first; z < zones; z += 2) order.push_back(z);
  return order;
}

SegmentCut cut_segments(const SortedView& view, const ZonePlan& plan, std::uint64_t first_label, int threads,
                        std::uint64_t end_label) {
  std::uint64_t segment_points = plan.segment_points;
  const double t = double(std::max(threads, 1));
  bool local_buffers = false;  // each segment's buffers at its own points' spacing
  SegmentCut best;
  std::uint64_t best_points = segment_points;  // best's segment size
  const std::uint64_t todo = std::min(end_label, view.count) - std::min(first_label, view.count);
  // The segments a cut of `size` labels each makes, and the size that makes `count`.
  auto segments_of = [&](std::uint64_t size) { return (todo + size - 1) / std::max<std::uint64_t>(size, 1); };
  auto size_for = [&](std::uint64_t count) { return (todo + count - 1) / std::max<std::uint64_t>(count, 1); };
  // A cut within the share, with one segment fewer while the measured windows still
  // fit. The shrinking below cuts a fifth at least, and the segment count is a
  // ceiling, so a fitting cut can be a whole segment smaller than it needs to be, and
  // every segment more costs its buffers again.
  // Each size is measured with the plan's buffers first: the local ones, which the
  // shrinking turns on, are thinner on flat data and cost it queries.
  auto grown = [&](SegmentCut cut, std::uint64_t points) {
    if (plan.fixed || plan.available <= 0 || cut.window_bytes > plan.available) return cut;
    bool local_cut = local_buffers;  // whether `cut` has the local buffers
    auto fitting = [&](std::uint64_t size, std::optional<SegmentCut>& out) {
      for (const bool local : {false, true}) {
        if (local && !local_cut) break;
        SegmentCut c = measure_cut(view, plan, size, local, first_label, t, end_label);
        if (c.window_bytes <= plan.available) return out = std::move(c), true;
      }
      return false;
    };
    // The same size with the plan's buffers, if they fit; then a segment fewer only
    // with the buffers of the cut: one segment's buffers cost less than the local
    // buffers' queries (below).
    if (local_buffers) {
      SegmentCut plain = measure_cut(view, plan, points, false, first_label, t, end_label);
      if (plain.window_bytes <= plan.available) cut = std::move(plain), local_cut = false;
    }
    std::optional<SegmentCut> found;
    for (int more = 0; more < 4; ++more) {
      const std::uint64_t segments = segments_of(points);
      if (segments <= 1) break;
      const std::uint64_t larger = size_for(segments - 1);
      if (!fitting(larger, found)) break;
      cut = std::move(*found);
      points = larger;
    }
    return cut;
  };
  for (int attempt = 0;; ++attempt) {
    SegmentCut cut = measure_cut(view, plan, segment_points, local_buffers, first_label, t, end_label);
    // A smaller segment that saved less than a tenth is not worth its extra buffers:
    // the windows are then mostly buffers, which smaller segments do not cut.
    if (attempt > 1 && cut.window_bytes > 0.9 * best.window_bytes) return grown(std::move(best), best_points);
    if (attempt == 0 || cut.window_bytes < best.window_bytes) best = std::move(cut), best_points = segment_points;
    if (plan.fixed || plan.available <= 0 || best.window_bytes <= plan.available || attempt == 8 ||
        segment_points <= 1000)
      return grown(std::move(best), best_points);
    // A little over the share with the plan's buffers: one segment more with them,
    // if that fits, before the local buffers. Uniform points, 10^6 at --memory 128M:
    // 9 segments with the plan's buffers were under 0.1% over the share, and 9 with local
    // buffers made 201,763 queries, 10 with the plan's 175,017 (the same tets; 9 with
    // the plan's buffers, under a sparser sample's estimate, 167,508).
    if (attempt == 0 && best.window_bytes < 1.1 * plan.available) {
      const std::uint64_t smaller = std::max<std::uint64_t>(1000, size_for(segments_of(segment_points) + 1));
      SegmentCut plain = measure_cut(view, plan, smaller, false, first_label, t, end_label);
      if (plain.window_bytes <= plan.available) return grown(std::move(plain), smaller);
    }
    // Over the share: first the local buffers (thinner buffers cost queries on flat
    // data, where the global spacing is what the stars need, so only when needed),
    // then smaller segments.
    if (!local_buffers) {
      local_buffers = true;
      continue;
    }
    const double shrink = std::clamp(plan.available / best.window_bytes, 0.5, 0.8);
    segment_points = std::max<std::uint64_t>(1000, std::uint64_t(double(segment_points) * shrink));
  }
}

// After the first pass (count and bounding box, nothing written): refuses a budget
// that cannot hold this many points even with buffers of width 0 and the index's
// smallest size, i.e. when no plan after the sort could work either. A budget that
// passes may still be refused after the sort, by the exact plan, with the sort's work
// kept for a --resume.
void refuse_budget_before_sort(const SortProgress& p, const PlanOptions& o, int threads) {
  PlanInputs in;
  in.points = p.input_count;
  for (int k = 0; k < 3; ++k) in.extent[k] = p.bbox_max[k] - p.bbox_min[k];
  in.axis = p.axis;
  in.strip_axis = in.extent[(p.axis + 1) % 3] >= in.extent[(p.axis + 2) % 3] ? (p.axis + 1) % 3 : (p.axis + 2) % 3;
  in.leaf_spacing = std::numeric_limits<double>::min();  // buffers of width ~0: a lower bound of the need
  in.index_bytes = std::min(std::uint64_t(kIndexBytesLowerBound * double(p.input_count)), kIndexDiskShareFloor);
  try {
    plan_for_budget(in, o, threads);
  } catch (const UsageError& e) {
    throw BudgetTooSmall(std::string(e.what()) + " (refused before the sort)");
  }
}

}  // namespace tetstream::pipeline
