#include "pipeline/field/accumulate.hpp"

#include "core/compiler.hpp"
#include "core/error.hpp"
#include "core/page_array.hpp"
#include "pipeline/files/external_sort.hpp"
#include "pipeline/field/geometry.hpp"
#include "pipeline/field/points.hpp"
#include "pipeline/util/interrupt.hpp"
#include "pipeline/util/progress.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <bit>
#include <unordered_map>
#include <vector>

namespace tetstream::pipeline {
namespace {

struct Accum {
  double volume = 0.0, voronoi = 0.0;
  std::uint64_t hull = 0;  // the hull terms' sum: 0 exactly when interior (field_geometry.hpp)
  std::uint64_t tets = 0;  // incident tets (the hull flag from the rows)
};

// A tet's contribution and its vertices' hull terms, computed on all threads.
struct TetTerms {
  TetContribution geometry;
  std::uint64_t hull[4];
};

class Accumulator {
 public:
  Accumulator(const io::TetReader& reader, const BatchPlan& plan, const AccumulateSinks& sinks, Progress* progress)
      : reader_(reader),
        plan_(plan),
        sinks_(sinks),
        progress_(progress),
        voronoi_(sinks.voronoi),
        terms_(sinks.hull_terms || !sinks.row),
        points_(reader, plan.ring_labels),
        acc_(plan.ring_labels) {
    // The per-tet buffers at the largest batch's size at once: grown batch by batch,
    // a resize past the capacity doubles it and copies, the old and the new buffers
    // alive together (the 10^7-point density at --memory 1G peaked at 542,120 KB that
    // way, 516,580 KB this way).
    if (terms_) contrib_.reserve(plan.largest_batch_tets);
    if (sinks_.row) edges_.reserve(6 * plan.largest_batch_tets);
    if (!terms_) volumes_.reserve(plan.largest_batch_tets);
  }

  AccumulateStats run() {
    for (const FrameBatch& b : plan_.batches) {
      check_interrupted();
      points_.advance(b.lo, [this](std::uint64_t l) {
        // A label entering the ring brings the sums it gathered while far, if any.
        const auto it = far_acc_.find(l);
        acc_[l] = it == far_acc_.end() ? Accum{} : it->second;
        if (it != far_acc_.end()) far_acc_.erase(it);
      });
      batch_.decode(reader_, b);
      points_.fetch_far(batch_);
      stats_.peak_far = std::max<std::uint64_t>(stats_.peak_far, points_.far_count());
      contributions();
      // Without hull terms the volumes come from the edges' loop (one pass over the tets).
      if (terms_) combine();
      if (sinks_.row) gather_rows(b);
      if (!terms_) combine();
      retire(b.retire_below);
      for (std::size_t k = b.first_frame; k < b.end_frame; ++k) reader_.release_frame_pages(k);
      stats_.tets += b.tets;
      ++stats_.batches;
      if (progress_) progress_->add(b.tets);
    }
    return stats_;
  }

 private:
  void contributions() {
    const std::size_t n = batch_.tets();
    const std::int64_t nn = std::int64_t(n);
    if (!terms_) return;  // gather_rows computes the volumes
    contrib_.resize(n);
#pragma omp parallel for schedule(static, 4096)
    for (std::int64_t t = 0; t < nn; ++t) {
      if (t + kAhead < nn) {
        const std::uint64_t* ahead = batch_.tet(std::size_t(t + kAhead));
        for (int v = 0; v < 4; ++v) points_.prefetch(ahead[v]);
      }
      const std::uint64_t* q = batch_.tet(std::size_t(t));
      const double* p[4] = {points_.xyz(q[0]), points_.xyz(q[1]), points_.xyz(q[2]), points_.xyz(q[3])};
      TetTerms& c = contrib_[std::size_t(t)];
      c.geometry = tet_contribution(p, voronoi_);
      tet_hull_terms(q, c.hull);
    }
  }

  // The tets' terms into their vertices' sums, on every thread: the dense labels are
  // cut into ranges, each range's sums are added by one thread going through all the
  // batch's tets in their order, adding only to its own labels (the far ones, in their
  // map: the last range's), so every label's terms are added in the tets' order
  // whatever the threads: the bits of every sum do not depend on them. OpenMP may give
  // fewer threads than asked (OMP_THREAD_LIMIT, a nested region): a thread then takes
  // every team-size-th range, and every range is still added once.
  void combine() {
    const std::size_t n = batch_.tets();
    const int parts = n < kParallelTets ? 1 : std::max(1, omp_get_max_threads());
    split_ranges(parts);
#pragma omp parallel num_threads(parts) if (parts > 1)
    {
      const int team = omp_get_num_threads();
      for (int r = omp_get_thread_num(); r < parts; r += team) add_range(r, r == parts - 1);
    }
  }

  // combine()'s r-th range of dense labels, [cut_[r], cut_[r + 1]), and the far labels
  // when far_here.
  void add_range(int r, bool far_here) {
    const std::uint64_t own_lo = cut_[std::size_t(r)], own_hi = cut_[std::size_t(r) + 1];
    std::size_t t = 0;
    for (std::size_t f = 0; f < batch_.frames(); ++f) {
      const std::vector<std::uint64_t>& labels = batch_.frame(f);
      for (std::size_t i = 0; i < labels.size(); i += 4, ++t) {
        if (terms_)
          for (std::size_t v = i + 4 * kAhead; v < std::min(labels.size(), i + 4 * kAhead + 4); ++v)
            if (labels[v] >= own_lo && labels[v] < own_hi) TS_PREFETCH(&acc_[labels[v]]);
        for (int v = 0; v < 4; ++v) {
          const std::uint64_t l = labels[i + std::size_t(v)];
          Accum* a;
          if (points_.dense(l)) {
            if (l < own_lo || l >= own_hi) continue;
            a = &acc_[l];
          } else {
            if (!far_here) continue;
            a = &far_acc_[l];
          }
          if (!terms_) {
            a->volume += volumes_[t];
            ++a->tets;
            continue;
          }
          const TetTerms& c = contrib_[t];
          a->volume += c.geometry.volume;
          a->voronoi += c.geometry.voronoi[std::size_t(v)];
          a->hull += c.hull[v];  // mod 2^64: the order does not matter, only the sum
        }
      }
    }
  }

  // The dense labels' ranges of combine()'s threads, cut_[0] = 0 < cut_[1] < ... <
  // cut_[parts] = the dense end: about as many of the batch's vertex slots in each
  // (from a sample of the batch's labels; any cut gives the same sums).
  void split_ranges(int parts) {
    cut_.assign(std::size_t(parts) + 1, 0);
    cut_[std::size_t(parts)] = ~0ull;
    if (parts == 1) return;
    sample_.clear();
    for (std::size_t f = 0; f < batch_.frames(); ++f) {
      const std::vector<std::uint64_t>& labels = batch_.frame(f);
      for (std::size_t i = 0; i < labels.size(); i += 61) sample_.push_back(labels[i]);
    }
    std::sort(sample_.begin(), sample_.end());
    for (int r = 1; r < parts; ++r)
      cut_[std::size_t(r)] =
          std::max(cut_[std::size_t(r) - 1],
                   sample_.empty() ? 0 : sample_[sample_.size() * std::size_t(r) / std::size_t(parts)]);
  }

  // The batch's edges, radix-sorted and made unique, then both directions as (label,
  // neighbour's original) entries sorted by label, beside the entries of the labels
  // not retired yet (sorted by label too). A retiring label's entries are a run of
  // each: together, sorted by original and made unique (an edge whose tets lie in
  // several batches came once per batch) they are its row. Rows are whole and sorted
  // here, so the output only has to place them (field_neighbours.hpp).
  //
  // An edge is keyed (a - lo) << dbits | (c - a) (a < c its labels): the labels of a
  // tet are a few slabs apart, so c - a is small and the key fits in about 33 bits,
  // three radix passes instead of five or six for (a - lo) << 32 | (c - lo), whose low
  // word is as wide as the hull tets' reach. The rare edges that span more (under the
  // hull) skip the batch's de-duplication: the row's does it.
  void gather_rows(const FrameBatch& b) {
    const EdgeKeys keys = collect_edges(b);
    const std::size_t fresh = make_entries(keys);
    emit_rows(b, fresh);
  }

  // The batch's edges as keys (below), de-duplicated: the short keys sorted and unique
  // at the front of edges_, the long ones in long_.
  struct EdgeKeys {
    std::uint64_t lo, span, top;
    int dbits;
    std::size_t short_edges;
  };
  EdgeKeys collect_edges(const FrameBatch& b) {
    const std::size_t n = batch_.tets();
    // edges_ only grows, and is never zeroed: every slot is written before it is read.
    edges_.reserve(6 * n);
    const std::uint64_t lo = b.lo;  // every label of the batch is >= lo, and < lo + 2^32 (checked by the caller)
    // The key's widths come from the batch's retired range, known before any edge is
    // seen, so the packing is one pass: a beyond twice that range is a hull edge.
    const int abits = std::bit_width(b.retire_below - lo) + 1;
    const int dbits = std::clamp(33 - abits, 12, 32);
    const std::uint64_t span = std::uint64_t(1) << dbits, alimit = std::uint64_t(1) << abits;
    // Blocks of kBlock tets, taken dynamically (on a shared machine a thread that is
    // descheduled leaves its blocks to the others instead of making them wait at the
    // barrier). Block k writes its short keys from the front of its 6 kBlock slots and
    // its long edges from the back; the compaction below joins them in block order.
    const std::size_t blocks = (n + kBlock - 1) / kBlock;
    block_short_.assign(blocks, 0);
    block_long_.assign(blocks, 0);
    const int threads = omp_get_max_threads();
    if (seen_.size() < std::size_t(threads) * kSeen) seen_.assign(std::size_t(threads) * kSeen, 0);
    if (!terms_) volumes_.resize(n);
    std::uint64_t top = 0;
#pragma omp parallel reduction(max : top)
    {
      // A direct-mapped table of the edges this thread emitted, (a << 32 | c) in
      // absolute labels: the tets around an edge are mostly stored close together, so
      // most of an edge's repeats are dropped here instead of being sorted. Only a
      // filter: an edge it drops was emitted before (this batch or an earlier one,
      // whose entries are pending or in this batch), and what it misses the unique
      // below removes. No entry is ever 0 (that would be the edge (0, 0)).
      std::uint64_t* seen = seen_.data() + std::size_t(omp_get_thread_num()) * kSeen;
#pragma omp for schedule(dynamic, 1)
      for (std::size_t k = 0; k < blocks; ++k) {
        std::uint64_t* front = &edges_.data()[6 * kBlock * k];
        std::uint64_t* back = front + 6 * std::min(kBlock, n - kBlock * k);
        std::size_t ns = 0, nl = 0;
        for (std::size_t t = kBlock * k; t < std::min(n, kBlock * (k + 1)); ++t) {
          const std::uint64_t* q = batch_.tet(t);
          if (!terms_) {
            const double* p[4] = {points_.xyz(q[0]), points_.xyz(q[1]), points_.xyz(q[2]), points_.xyz(q[3])};
            volumes_[t] = tet_volume(p);
          }
          for (int i = 0; i < 4; ++i)
            for (int j = i + 1; j < 4; ++j) {
              const std::uint64_t a = std::min(q[i], q[j]), c = std::max(q[i], q[j]);
              const std::uint64_t raw = a << 32 | c;
              std::uint64_t& slot = seen[(raw * 0x9E3779B97F4A7C15ull) >> (64 - kSeenBits)];
              if (slot == raw) continue;
              slot = raw;
              const std::uint64_t ar = a - lo, cr = c - lo;
              top = std::max(top, cr);
              if (ar < alimit && c - a < span)
                front[ns++] = ar << dbits | (c - a);
              else
                *--back = ar << 32 | cr, ++nl;
            }
        }
        block_short_[k] = ns, block_long_[k] = nl;
      }
    }
    long_.clear();
    std::size_t kept = 0;
    for (std::size_t k = 0; k < blocks; ++k) {
      const std::uint64_t* front = &edges_.data()[6 * kBlock * k];
      const std::uint64_t* end = front + 6 * std::min(kBlock, n - kBlock * k);
      long_.insert(long_.end(), end - block_long_[k], end);
      if (kept != 6 * kBlock * k) std::copy(front, front + block_short_[k], &edges_.data()[kept]);
      kept += block_short_[k];
    }
    stats_.batch_edge_keys += kept + long_.size();
    radix_sort(edges_.data(), kept, radix_tmp_, abits + dbits, [](std::uint64_t x) { return x; });
    const std::size_t short_edges = std::size_t(std::unique(edges_.data(), edges_.data() + kept) - edges_.data());
    stats_.batch_edges += short_edges + long_.size();

    return EdgeKeys{lo, span, top, dbits, short_edges};
  }

  // Both directions of each edge as entries in fresh_, sorted by label; their count.
  std::size_t make_entries(const EdgeKeys& keys) {
    const std::uint64_t lo = keys.lo, span = keys.span, top = keys.top;
    const int dbits = keys.dbits;
    const std::size_t short_edges = keys.short_edges;
    // The batch's entries, label << 32 | the neighbour's original (labels and originals
    // are below 2^32, checked by the caller: 8 bytes instead of 16, half the sort's
    // traffic), both directions of each edge, sorted by label alone: radix on the
    // label's offset from lo, which is at most top.
    const std::size_t fresh = 2 * (short_edges + long_.size());
    fresh_.reserve(fresh);  // grows only; never zeroed (every entry is written first)
    const std::int64_t ne = std::int64_t(short_edges + long_.size());
#pragma omp parallel for schedule(dynamic, 16384)
    for (std::int64_t i = 0; i < ne; ++i) {
      std::uint64_t a, c;
      if (std::size_t(i) < short_edges) {
        const std::uint64_t e = edges_[std::size_t(i)];
        a = lo + (e >> dbits), c = a + (e & (span - 1));
      } else {
        const std::uint64_t e = long_[std::size_t(i) - short_edges];
        a = lo + (e >> 32), c = lo + (e & 0xffffffffu);
      }
      fresh_[2 * std::size_t(i)] = a << 32 | points_.original(c);
      fresh_[2 * std::size_t(i) + 1] = c << 32 | points_.original(a);
    }
    radix_sort(fresh_.data(), fresh, radix_tmp_, std::bit_width(top), [lo](std::uint64_t d) { return (d >> 32) - lo; });
    return fresh;
  }

  // The rows of the labels this batch retires, to the sink; the rest stays pending.
  void emit_rows(const FrameBatch& b, std::size_t fresh) {
    // The rows of the labels retired after this batch, [retired_, below): each label's
    // entries are a run of the pending ones (sorted by label, all >= retired_ == lo)
    // and a run of the batch's. Nothing is merged for them: a row gathers its two runs.
    const std::uint64_t* pending = pending_[current_].data();
    const std::uint64_t* batch = fresh_.data();
    const std::uint64_t below = b.retire_below;
    const std::size_t labels = std::size_t(below - retired_);
    pending_start_.assign(labels + 1, 0);
    fresh_start_.assign(labels + 1, 0);
    std::size_t pc = 0, fc = 0;
    for (std::size_t l = 0; l < labels; ++l) {
      pending_start_[l] = pc, fresh_start_[l] = fc;
      while (pc < pending_size_ && pending[pc] >> 32 == retired_ + l) ++pc;
      while (fc < fresh && batch[fc] >> 32 == retired_ + l) ++fc;
    }
    pending_start_[labels] = pc, fresh_start_[labels] = fc;
    row_others_.resize(pc + fc);
    row_length_.resize(labels);
    const std::int64_t nl = std::int64_t(labels);
#pragma omp parallel for schedule(dynamic, 1024)
    for (std::int64_t l = 0; l < nl; ++l) {
      const std::size_t ps = pending_start_[std::size_t(l)], pe = pending_start_[std::size_t(l) + 1];
      const std::size_t fs = fresh_start_[std::size_t(l)], fe = fresh_start_[std::size_t(l) + 1];
      std::uint32_t* const row = row_others_.data() + ps + fs;
      std::uint32_t* o = row;
      for (std::size_t i = ps; i < pe; ++i) *o++ = std::uint32_t(pending[i]);  // the original (low word)
      for (std::size_t i = fs; i < fe; ++i) *o++ = std::uint32_t(batch[i]);
      std::sort(row, o);
      row_length_[std::size_t(l)] = std::size_t(std::unique(row, o) - row);
    }
    for (std::size_t l = 0; l < labels; ++l)
      sinks_.row(
          points_.original(retired_ + l),
          std::span<const std::uint32_t>(row_others_.data() + pending_start_[l] + fresh_start_[l], row_length_[l]));

    // What stays pending (labels >= below) is the two runs' tails, merged by label into
    // the other pending buffer: each entry is sorted once, in its batch, and merged
    // once a batch until its label retires (sorting the pending entries again with
    // every batch would cost a sort of all of them each time).
    const std::size_t rest = (pending_size_ - pc) + (fresh - fc);
    core::PageArray<std::uint64_t>& next = pending_[1 - current_];
    next.reserve(rest);
    std::merge(pending + pc, pending + pending_size_, batch + fc, batch + fresh, next.data(),
               [](std::uint64_t x, std::uint64_t y) { return x >> 32 < y >> 32; });
    current_ = 1 - current_;
    pending_size_ = rest;
  }

  void retire(std::uint64_t below) {
    final_.resize(std::size_t(below - retired_));
    for (std::uint64_t l = retired_; l < below; ++l) {
      FinalPoint& p = final_[std::size_t(l - retired_)];
      p.label = l;
      p.original = points_.original(l);
      const double* x = points_.xyz(l);
      p.xyz[0] = x[0], p.xyz[1] = x[1], p.xyz[2] = x[2];
      const Accum& a = acc_[l];
      p.volume = a.volume;
      p.voronoi = a.voronoi;
      // Without hull terms the rows of [retired_, below) were just cut (gather_rows): T != 2 d - 4.
      p.hull = terms_ ? a.hull != 0 : a.tets + 4 != 2 * row_length_[std::size_t(l - retired_)];
    }
    if (sinks_.points) sinks_.points(final_);
    retired_ = below;
  }

  const io::TetReader& reader_;
  const BatchPlan& plan_;
  const AccumulateSinks& sinks_;
  Progress* progress_;
  bool voronoi_, terms_;
  WindowPoints points_;
  LabelRing<Accum> acc_;
  std::unordered_map<std::uint64_t, Accum> far_acc_;  // sums of the far labels
  DecodedBatch batch_;
  std::vector<TetTerms> contrib_;
  std::vector<FinalPoint> final_;         // the points a batch retires
  std::vector<double> volumes_;           // without hull terms: the tets' volumes
  core::PageArray<std::uint64_t> edges_;  // the batch's packed edges (its capacity: 6 a tet)
  std::vector<std::uint64_t> radix_tmp_, long_;
  // Tets ahead whose vertices' slots are prefetched: a tet's four labels are spread
  // over the window, so nearly every slot is a cache miss, and the loops would
  // otherwise wait for each in turn.
  static constexpr std::int64_t kAhead = 8;
  static constexpr std::size_t kBlock = 4096;         // tets a block of the edge packing
  static constexpr std::size_t kParallelTets = 1024;  // fewer tets: combine() on one thread
  std::vector<std::uint64_t> cut_, sample_;           // combine()'s label ranges, and the labels they are cut from
  static constexpr int kSeenBits = 14;  // 16384 entries, 128 KiB a thread (docs/fields.md: the sizes tried)
  static constexpr std::size_t kSeen = std::size_t(1) << kSeenBits;
  std::vector<std::uint64_t> seen_;  // the threads' tables of emitted edges
  std::vector<std::size_t> block_short_, block_long_;
  // Entries (label << 32 | the neighbour's original index) of the labels not retired
  // yet, sorted by label: pending_[current_][0, pending_size_) (the other buffer takes
  // the next batch's merge); and the batch's own, fresh_.
  core::PageArray<std::uint64_t> pending_[2], fresh_;
  std::size_t pending_size_ = 0;
  int current_ = 0;
  // A retiring label's runs: [pending_start_[l], pending_start_[l + 1]) of the pending
  // entries, [fresh_start_[l], fresh_start_[l + 1]) of the batch's.
  std::vector<std::size_t> pending_start_, fresh_start_, row_length_;
  std::vector<std::uint32_t> row_others_;  // originals: below 2^32 (field.cpp)
  std::uint64_t retired_ = 0;
  AccumulateStats stats_;
};

}  // namespace

AccumulateStats accumulate_fields(const io::TetReader& reader, const BatchPlan& plan, const AccumulateSinks& sinks,
                                  Progress* progress) {
  return Accumulator(reader, plan, sinks, progress).run();
}

}  // namespace tetstream::pipeline
