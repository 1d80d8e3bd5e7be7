#include "pipeline/run/stage_triangulate.hpp"

#include "core/error.hpp"
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/util/fault.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/util/progress.hpp"
#include "pipeline/util/resident_memory.hpp"
#include "pipeline/run/stage.hpp"

#include <spdlog/spdlog.h>

#include <omp.h>
#include <malloc.h>

#include <algorithm>
#include <atomic>
#include <exception>
#include <memory>

namespace tetstream::pipeline {

TriangulatePlan plan_triangulation(const IndexStage& indexed, const RunOptions& options, MemoryBudget& budget,
                                   int threads) {
  TriangulatePlan plan;
  const PlanInputs inputs = plan_inputs(indexed.view(), indexed.index());
  plan.zones = plan_for_budget(inputs, options.plan_options(), threads);
  budget.set_points(indexed.view().count);
  plan.shares = budget.plan_triangulate(inputs.index_bytes, plan.zones.window_bytes);
  for (const MemoryBudget::Share& share : budget.shares())
    spdlog::debug("memory: {} {} {}", share.phase, share.name, human_bytes(double(share.bytes)));
  return plan;
}

// The queries' pages are counted in the 2 MiB regions that a read may map
// (MappedRegions), within an eighth of the budget (MemoryBudget::plan_triangulate).
// The queries of a zone read the file along the sort axis, and a share that holds
// their sweep saves faulting regions in again.
TriangulateStage::TriangulateStage(const RunOptions& options, IndexStage& indexed, const ZonePlan& plan,
                                   std::uint64_t query_page_bytes, std::uint64_t shared_rim_bytes, int threads)
    : options_(options),
      indexed_(indexed),
      plan_(plan),
      threads_(threads),
      query_regions_(indexed.mapped_data(), indexed.mapped_bytes(),
                     std::max<std::size_t>(1, std::size_t(query_page_bytes / MappedRegions::kRegionBytes)),
                     indexed.path()),
      shared_rim_(std::size_t(shared_rim_bytes)) {
  indexed_.view().query_regions = &query_regions_;
}

TriangulateStage::~TriangulateStage() { indexed_.view().query_regions = nullptr; }

void TriangulateStage::prepare(std::uint64_t first_label, std::uint64_t first_segment, std::uint64_t end_label) {
  const SortedView& view = indexed_.view();
  first_label_ = first_label;
  first_segment_ = first_segment;
  end_label_ = std::min(end_label, view.count);
  SegmentCut cut = cut_segments(view, plan_, first_label, threads_, end_label_);
  plans_ = std::move(cut.plans);
  window_bytes_ = cut.window_bytes;
  for (std::size_t s = 0; s < plans_.size(); ++s) {
    const std::size_t first = units_.size();
    for (std::size_t z = 0; z < plans_[s].zones.size(); ++z) units_.push_back({s, z});
    for (std::size_t z : zone_start_order(plans_[s].zones.size())) run_order_.push_back(first + z);
  }
  spdlog::debug("windows measured: largest ~{} points, {} (the plan's share {})", cut.largest_window,
                human_bytes(window_bytes_), human_bytes(plan_.available));
  // No cut fits the windows' share (a slab through a dense cluster is mostly buffers,
  // which smaller segments do not thin): the job goes on with the smallest one, and
  // says before it starts that it may pass its budget, and by how much at most.
  if (plan_.available > 0 && window_bytes_ > plan_.available)
    spdlog::warn(
        "memory: the windows measured (the largest ~{} points) need {}, over their share of the budget ({}): "
        "this job may take up to {} more than its budget",
        cut.largest_window, human_bytes(window_bytes_), human_bytes(plan_.available),
        human_bytes(window_bytes_ - plan_.available));
  spdlog::info("{} segments of ~{} points in {} zones of ~{} points, buffer {:.3g} ({} spacings), {} hull vertices",
               plans_.size(), plans_.empty() ? 0 : plans_[0].label_end - plans_[0].label_begin, units_.size(),
               plans_.empty() ? 0 : (plans_[0].label_end - plans_[0].label_begin) / plans_[0].zones.size(),
               plan_.buffer_width, options_.buffer_spacings, view.hull_points.size());
}

// Each thread triangulates whole zones (they are independent given the sorted file),
// taking them in run_order_ (zone_start_order within each segment, the segments in
// order). The ordered region collects a segment's zones in that order; after its last
// one the write stage merges them by minimum label into its frames, so the bytes depend
// neither on the thread count nor on the plan. A finished zone waits there for its
// predecessors: at most `threads` zones are in flight, and the outputs of at most one
// segment plus `threads` - 1 zones are held, which is what the plan was sized for.
// After each segment the checkpoint records the output so far: a crash loses the
// zones finished or started since.
void TriangulateStage::run(SegmentSink& out) {
  const SortedView& view = indexed_.view();
  Progress progress("triangulating", "points", shared_progress_ ? shared_progress_->total : end_label_,
                    options_.progress);
  progress.add(first_label_);
  if (shared_progress_) {
    if (!shared_progress_->own.empty()) progress.share_to(shared_progress_->own, shared_progress_->base);
    progress.add_shared(shared_progress_->peers);
  }
  std::exception_ptr failure;
  std::atomic<bool> cancelled{false};
  const auto stage_start = StageClock::now();
  const std::int64_t unit_count = std::int64_t(units_.size());
  // Per thread, a triangulator whose buffers live from zone to zone; and the zones'
  // output vectors, recycled once merged: fresh memory for each zone would cost the
  // OS's page zeroing again and again.
  std::vector<std::unique_ptr<ZoneTriangulator>> triangulators(static_cast<std::size_t>(threads_));
#pragma omp parallel for ordered schedule(dynamic, 1) num_threads(threads_)
  for (std::int64_t i = 0; i < unit_count; ++i) {
    const std::size_t u = run_order_[std::size_t(i)];
    const Unit unit = units_[u];
    const SegmentPlan& plan = plans_[unit.segment];
    ZoneTets tets;
    SegmentStats s;
    if (!cancelled.load()) {
      try {
        check_interrupted();
        maybe_inject_fault("segment", first_segment_ + unit.segment);
        auto& triangulator = triangulators[std::size_t(omp_get_thread_num())];
        if (!triangulator) triangulator = std::make_unique<ZoneTriangulator>(view, &output_pool_, &shared_rim_);
        s = triangulator->run(plan, plan.zones[unit.zone], tets);
        out.zone_done(u, tets);
        tets.xyz = {};  // the worker's, refilled by its next zone
      } catch (...) {
        // A worker never throws out of the parallel region (that would terminate the
        // process): the first failure is kept, the others stop, and it is rethrown
        // after the join.
#pragma omp critical(tetstream_run_failure)
        if (!failure) failure = std::current_exception();
        cancelled = true;
      }
    }
#pragma omp ordered
    {
      if (!cancelled.load()) {
        const std::uint64_t points = plan.label_end - plan.label_begin, k = plan.zones.size();
        progress.add(points * (unit.zone + 1) / k - points * unit.zone / k);
        try {
          collect(unit, std::move(tets), s, out);
        } catch (...) {
#pragma omp critical(tetstream_run_failure)
          if (!failure) failure = std::current_exception();
          cancelled = true;
        }
      }
      tets = ZoneTets{};
      indexed_.release_pages();
      malloc_trim(0);  // hand any freed heap back, so resident memory tracks the windows
    }
  }
  // The windows' and the query pages' shares are free from here: what the output stage
  // does at its end (a periodic job's last sort) is planned in them, so the zones'
  // buffers and the held regions of the sorted file go now.
  triangulators.clear();
  output_pool_.clear();
  query_regions_.release_all();
  malloc_trim(0);
  if (failure) {
    try {
      std::rethrow_exception(failure);
    } catch (const DamagedCheckpoint&) {
      throw;
    } catch (const InputError& e) {
      // The kernel's word on the points (too few affinely independent ones) names no
      // file: the input is the job's.
      throw InputError(options_.input + ": " + e.what());
    }
  }
  seconds_ = seconds_since(stage_start) - sink_seconds_;
  progress.finish();
}

// In the ordered region: a zone's tets and work, its segment's in the start order.
// After a segment's last zone, its tets go, in plan order, to the write stage and its
// buffers back to the pool (also when the write stage fails: the zones' outputs are
// never held past their segment).
void TriangulateStage::collect(const Unit& unit, ZoneTets&& tets, const SegmentStats& stats, SegmentSink& out) {
  const SegmentPlan& plan = plans_[unit.segment];
  if (parts_in_ == 0) parts_.resize(plan.zones.size());
  parts_[unit.zone] = std::move(tets);
  segment_work_ += stats;
  if (++parts_in_ < plan.zones.size()) return;
  parts_in_ = 0;
  std::exception_ptr failure;
  try {
    const auto t0 = StageClock::now();
    out.add_segment(parts_, segment_work_, plan.label_end - plan.label_begin, plan.label_end);
    sink_seconds_ += seconds_since(t0);
  } catch (...) {
    failure = std::current_exception();
  }
  spdlog::debug(
      "segment [{}, {}) in {} zones: windows {} (+{} repairs), {} range failures, {} queries, "
      "{} rounds, {} tets, build {:.2f}s check {:.2f}s (summed), kernels {}",
      plan.label_begin, plan.label_end, plan.zones.size(), segment_work_.window_points, segment_work_.repair_points,
      segment_work_.range_failures, segment_work_.queries, segment_work_.rounds, segment_work_.tets,
      segment_work_.seconds_build, segment_work_.seconds_check, human_bytes(double(segment_work_.kernel_bytes)));
  warn_if_past_budget(plan);
  for (auto& part : parts_) output_pool_.give(std::move(part));
  parts_.clear();
  // Every zone of the segments so far has finished: a tet of labels all below this
  // segment's end has no vertex in a zone still to run.
  shared_rim_.forget_below(plan.label_end);
  spdlog::debug("shared rim: {} tets ({}) kept for the zones to come", shared_rim_.size(),
                human_bytes(double(shared_rim_.bytes())));
  segment_work_ = SegmentStats{};
  if (failure) std::rethrow_exception(failure);
}

// The plan sizes the windows by a sample of their points, before their repairs and
// the neighbours' seeds, which on surfaces add up to 87% (docs/zoo.md, "What a window
// takes past its sample"): a job the plan said would fit can pass its budget. Said
// once, when a segment ends with the resident peak past the budget.
void TriangulateStage::warn_if_past_budget(const SegmentPlan& plan) {
  if (warned_past_budget_) return;
  const std::uint64_t budget = options_.memory_stated != 0 ? options_.memory_stated : options_.memory_bytes;
  const std::uint64_t peak = peak_resident_bytes();
  if (budget == 0 || peak <= budget) return;
  warned_past_budget_ = true;
  spdlog::warn(
      "memory: the resident set reached {}, past the budget of {}, by the end of segment [{}, {}) (its windows: "
      "{} points, then {} repair points): a larger --memory holds this input",
      human_bytes(double(peak)), human_bytes(double(budget)), plan.label_begin, plan.label_end,
      segment_work_.window_points, segment_work_.repair_points);
}

}  // namespace tetstream::pipeline
