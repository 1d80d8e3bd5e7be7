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
  // On every thread: a serial copy of a run was a share of the sort that did not scale.
#pragma omp parallel for schedule(static) if (run.size() >= (std::size_t(1) << 16))
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

// A batch of the merge, in label order, with exact duplicates dropped and the hull
// candidates' labels found, on the OpenMP threads for a large batch: each thread marks
// its slice (a duplicate: equal to the record before it, the last one of the batch
// before for the first), then copies its kept records to their place after the
// slices before it. Equal records are adjacent, so comparing with the one before is
// comparing with the last kept.
template <class R>
class DuplicateFilter {
 public:
  explicit DuplicateFilter(const std::unordered_set<std::uint64_t>& hull_originals) : hull_(hull_originals) {}

  // The batch's kept records into `kept` (resized), its candidates' labels appended
  // to `hull_labels`; result.count and result.duplicates count them.
  void filter(std::span<const R> batch, std::vector<R>& kept, std::vector<std::uint64_t>& hull_labels,
              SortedPoints& result) {
    const std::size_t n = batch.size();
    const int threads = n >= (std::size_t(1) << 14) ? std::max(1, detail::max_threads()) : 1;
    flags_.resize(n);
    kept.resize(n);
    slice_kept_.assign(std::size_t(threads) + 1, 0);
    slice_hull_.resize(std::size_t(threads));
    for (auto& h : slice_hull_) h.clear();
    std::size_t team = 1;  // the team OpenMP gave (maybe fewer than asked)
    const std::uint64_t base = result.count;
#pragma omp parallel num_threads(threads) if (threads > 1)
    {
      const std::size_t t = std::size_t(detail::thread_id()), nt = std::size_t(detail::team_size());
      const std::size_t lo = n * t / nt, hi = n * (t + 1) / nt;
      slice_kept_[t + 1] = mark(batch, lo, hi);
#pragma omp barrier
#pragma omp single
      {
        team = nt;
        for (std::size_t u = 0; u < nt; ++u) slice_kept_[u + 1] += slice_kept_[u];
      }
      copy_kept(batch, lo, hi, slice_kept_[t], base, kept, slice_hull_[t]);
    }
    const std::size_t total = slice_kept_[team];
    kept.resize(total);
    for (auto& h : slice_hull_) hull_labels.insert(hull_labels.end(), h.begin(), h.end());
    result.count += total;
    result.duplicates += n - total;
    if (n) last_ = batch[n - 1], have_last_ = true;
  }

 private:
  static constexpr std::uint8_t kDuplicate = 1, kCandidate = 2;
  // Equal as numbers (so -0.0 == 0.0), as the kernel compares points.
  static bool same_point(const R& a, const R& b) {
    return a.coord(0) == b.coord(0) && a.coord(1) == b.coord(1) && a.coord(2) == b.coord(2);
  }
  // Flags [lo, hi) of the batch; returns how many it keeps.
  std::size_t mark(std::span<const R> batch, std::size_t lo, std::size_t hi) {
    std::size_t keep = 0;
    for (std::size_t i = lo; i < hi; ++i) {
      const R* before = i > 0 ? &batch[i - 1] : have_last_ ? &last_ : nullptr;
      const bool duplicate = before && same_point(batch[i], *before);
      flags_[i] = std::uint8_t((duplicate ? kDuplicate : 0) | (hull_.count(batch[i].original()) ? kCandidate : 0));
      keep += !duplicate;
    }
    return keep;
  }
  // Copies the kept records of [lo, hi) from kept[at] on; a candidate's label is that
  // of the record it is (or, a duplicate, the kept record it equals).
  void copy_kept(std::span<const R> batch, std::size_t lo, std::size_t hi, std::size_t at, std::uint64_t base,
                 std::vector<R>& kept, std::vector<std::uint64_t>& hull) const {
    for (std::size_t i = lo; i < hi; ++i) {
      if (!(flags_[i] & kDuplicate)) kept[at++] = batch[i];
      if (flags_[i] & kCandidate) hull.push_back(base + at - 1);
    }
  }

  const std::unordered_set<std::uint64_t>& hull_;
  std::vector<std::uint8_t> flags_;
  std::vector<std::size_t> slice_kept_;
  std::vector<std::vector<std::uint64_t>> slice_hull_;
  R last_{};
  bool have_last_ = false;
};

// The merge: the runs into `out` in label order, exact duplicates dropped (the first,
// the smallest original index, stays), the hull candidates' labels found (labels
// counted from 0: a rank's own). Sets result.count, duplicates and hull_labels, and
// finishes `out`.
template <class R>
void merge_runs_into(typename RecordSort<R>::Sorter& sorter, const std::unordered_set<std::uint64_t>& hull_originals,
                     SortedSink& out, bool sync, bool progress_on, std::uint64_t progress_total, SortedPoints& result) {
  DuplicateFilter<R> filter(hull_originals);
  std::vector<R> kept;
  std::vector<std::uint64_t> hull_labels;
  Progress progress("merging", "points", progress_total, progress_on);
  sorter.merge([&](std::span<const R> batch) {
    check_interrupted();
    filter.filter(batch, kept, hull_labels, result);
    if (!kept.empty()) out.write(kept.data(), sizeof(R) * kept.size());
    // Counted as read from the runs, duplicates included: the total is the input count.
    progress.add(batch.size());
  });
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
