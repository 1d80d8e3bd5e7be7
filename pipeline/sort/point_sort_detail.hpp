#pragma once
// The pieces of the point sort (pipeline/point_sort.hpp) that the one-process sort and
// the sort spread over a job's ranks (pipeline/point_sort_distributed.hpp) share: a
// run sorted, its hull candidates found and handed to the external sorter; the merge
// of the runs into label order with exact duplicates dropped. Internal to pipeline/.
#include "pipeline/files/external_sort.hpp"
#include "pipeline/util/fault.hpp"
#include "pipeline/sort/hull.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/sort/point_sort.hpp"
#include "pipeline/util/progress.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <exception>
#include <optional>
#include <span>
#include <unordered_set>
#include <vector>

namespace tetstream::pipeline::sort_detail {

inline constexpr std::size_t kReadChunk = 1 << 16;  // points per read() call

using Clock = std::chrono::steady_clock;
inline double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// A sorted run of SortedPoint converted, in place, into the file's records (never
// larger: record i is written at or before where point i was read, after it was).
template <class R>
std::span<R> compact_in_place(std::vector<SortedPoint>& run) {
  static_assert(sizeof(R) <= sizeof(SortedPoint));
  std::byte* out = reinterpret_cast<std::byte*>(run.data());
  for (std::size_t i = 0; i < run.size(); ++i) {
    R r;
    r.set(run[i].xyz, run[i].original);
    std::memcpy(out + i * sizeof(R), &r, sizeof r);
  }
  return {reinterpret_cast<R*>(out), run.size()};
}

// The external sorter of records R in the sorted file's order.
template <class R>
struct RecordSort {
  struct Less {
    int axis;
    bool operator()(const R& a, const R& b) const { return record_before(a, b, axis); }
  };
  using Sorter = ExternalSorter<R, Less>;
};

// Sorts `run` along `axis`, finds its hull vertex candidates (original indices into
// `run_hull` and `hull_originals`; pieces of shares.hull_piece_points on
// shares.hull_threads threads, so the kernels' memory stays a fraction of the budget
// even when most points are on the hull, a thin shell). sort_and_push_run() then hands
// it to the sorter.
inline void sort_run_and_find_hull(std::vector<SortedPoint>& run, int axis, const SortShares& shares,
                                   std::vector<double>& run_xyz, std::vector<std::uint64_t>& run_hull,
                                   std::unordered_set<std::uint64_t>& hull_originals) {
  parallel_sort(run.data(), run.data() + run.size(),
                [axis](const SortedPoint& a, const SortedPoint& b) { return sorted_before(a, b, axis); });
  run_xyz.resize(3 * run.size());
  for (std::size_t i = 0; i < run.size(); ++i) std::memcpy(&run_xyz[3 * i], run[i].xyz, 3 * sizeof(double));
  run_hull.clear();
  const std::size_t piece = shares.hull_piece_points;
  const std::size_t pieces = (run.size() + piece - 1) / piece;
  std::vector<std::vector<std::uint32_t>> piece_hull(pieces);
  std::exception_ptr failure;  // (out of memory) rethrown after the join, never out of the region
#pragma omp parallel for schedule(dynamic, 1) num_threads(shares.hull_threads)
  for (std::size_t p = 0; p < pieces; ++p) {
    const std::size_t first = p * piece, n = std::min(piece, run.size() - first);
    try {
      piece_hull[p] = hull_vertex_candidates(&run_xyz[3 * first], n);
    } catch (...) {
#pragma omp critical(tetstream_hull_failure)
      if (!failure) failure = std::current_exception();
    }
  }
  if (failure) std::rethrow_exception(failure);
  for (std::size_t p = 0; p < pieces; ++p)
    for (std::uint32_t i : piece_hull[p]) run_hull.push_back(run[p * piece + i].original);
  hull_originals.insert(run_hull.begin(), run_hull.end());
}

// One run of either sort, from the points read to the sorter: sorted with its hull
// candidates found (sort_run_and_find_hull), then handed to the sorter as records R
// (`run` is consumed: its memory holds the compacted records until the sorter has
// written them), `runs` counting it. A fault can be injected before the hand-over
// ("sort-run", by run number). The caller clears `run`.
template <class R>
void sort_and_push_run(typename RecordSort<R>::Sorter& sorter, std::vector<SortedPoint>& run, int axis,
                       const SortShares& shares, std::vector<double>& run_xyz, std::vector<std::uint64_t>& run_hull,
                       std::unordered_set<std::uint64_t>& hull_originals, std::size_t& runs) {
  sort_run_and_find_hull(run, axis, shares, run_xyz, run_hull, hull_originals);
  maybe_inject_fault("sort-run", runs);
  sorter.push_sorted_run(compact_in_place<R>(run));
  ++runs;
}

// The merge: the runs into `out` in label order, exact duplicates dropped (the first,
// the smallest original index, stays), the hull candidates' labels found (labels
// counted from 0: a rank's own). Sets result.count, duplicates and hull_labels, and
// finishes `out`.
template <class R>
void merge_runs_into(typename RecordSort<R>::Sorter& sorter, const std::unordered_set<std::uint64_t>& hull_originals,
                     SortedSink& out, bool sync, bool progress_on, std::uint64_t progress_total, SortedPoints& result) {
  std::vector<R> block;
  block.reserve(std::size_t(1) << 15);
  R last{};
  bool have_last = false;
  std::vector<std::uint64_t> hull_labels;
  Progress progress("merging", "points", progress_total, progress_on);
  sorter.merge([&](std::span<const R> batch) {
    check_interrupted();
    for (const R& p : batch) {
      const bool candidate = hull_originals.count(p.original()) != 0;
      // Equal as numbers (so -0.0 == 0.0), as the kernel compares points.
      if (have_last && p.coord(0) == last.coord(0) && p.coord(1) == last.coord(1) && p.coord(2) == last.coord(2)) {
        ++result.duplicates;  // the first occurrence (smallest original index) stays
        if (candidate) hull_labels.push_back(result.count - 1);
        continue;
      }
      if (candidate) hull_labels.push_back(result.count);
      block.push_back(p);
      last = p;
      have_last = true;
      ++result.count;
      if (block.size() == block.capacity()) {
        out.write(block.data(), sizeof(R) * block.size());
        block.clear();
      }
    }
    // Counted as read from the runs, duplicates included: the total is the input count.
    progress.add(batch.size());
  });
  out.write(block.data(), sizeof(R) * block.size());
  progress.finish();
  std::sort(hull_labels.begin(), hull_labels.end());
  hull_labels.erase(std::unique(hull_labels.begin(), hull_labels.end()), hull_labels.end());
  result.hull_labels = std::move(hull_labels);
  out.finish(result, sync);
}

// The sort's shares of the ledger (run buffer, hull pieces, merge), sized for this
// input's count (a small input takes little of a large budget): from the job's ledger
// when the options carry one, else from one of the sort's own, made in `own`.
inline SortShares sort_shares(const PointSortOptions& options, std::uint64_t input_count,
                              std::optional<MemoryBudget>& own) {
  MemoryBudget* budget = options.budget;
  if (!budget) budget = &own.emplace(options.memory_bytes, input_count, detail::max_threads(), detail::max_threads());
  budget->set_points(input_count);
  return budget->plan_sort();
}

}  // namespace tetstream::pipeline::sort_detail
