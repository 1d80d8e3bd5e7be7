#include "pipeline/field_accumulate.hpp"

#include "core/compiler.hpp"
#include "core/error.hpp"
#include "core/page_array.hpp"
#include "pipeline/external_sort.hpp"
#include "pipeline/field_geometry.hpp"
#include "pipeline/field_points.hpp"
#include "pipeline/interrupt.hpp"
#include "pipeline/progress.hpp"

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
      : reader_(reader), plan_(plan), sinks_(sinks), progress_(progress), voronoi_(sinks.voronoi),
        terms_(sinks.hull_terms || !sinks.row),
        points_(reader, plan.ring_labels), acc_(plan.ring_labels) {}

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

  // One thread, fixed order: the bits of every sum do not depend on the threads.
  void combine() {
    std::size_t t = 0;
    if (!terms_) {
      for (std::size_t f = 0; f < batch_.frames(); ++f) {
        const std::vector<std::uint64_t>& labels = batch_.frame(f);
        for (std::size_t i = 0; i < labels.size(); i += 4, ++t)
          for (int v = 0; v < 4; ++v) {
            const std::uint64_t l = labels[i + std::size_t(v)];
            Accum& a = points_.dense(l) ? acc_[l] : far_acc_[l];
            a.volume += volumes_[t];
            ++a.tets;
          }
      }
      return;
    }
    for (std::size_t f = 0; f < batch_.frames(); ++f) {
      const std::vector<std::uint64_t>& labels = batch_.frame(f);
      for (std::size_t i = 0; i < labels.size(); i += 4, ++t) {
        for (std::size_t v = i + 4 * kAhead; v < std::min(labels.size(), i + 4 * kAhead + 4); ++v)
          if (points_.dense(labels[v])) TS_PREFETCH(&acc_[labels[v]]);
        const TetTerms& c = contrib_[t];
        for (int v = 0; v < 4; ++v) {
          const std::uint64_t l = labels[i + std::size_t(v)];
          Accum& a = points_.dense(l) ? acc_[l] : far_acc_[l];
          a.volume += c.geometry.volume;
          a.voronoi += c.geometry.voronoi[v];
          a.hull += c.hull[v];  // mod 2^64: the order does not matter, only the sum
        }
      }
    }
  }

  // The batch's edges, radix-sorted and made unique, then both directions as (label,
  // neighbour's original) entries, behind the entries of the labels not retired yet.
  // Sorted by label, a retiring label's entries are contiguous: sorted by original and
  // made unique (an edge whose tets lie in several batches came once per batch) they
  // are its row. Rows are whole and sorted here, so the output only has to place them
  // (field_neighbours.hpp).
  //
  // An edge is keyed (a - lo) << dbits | (c - a) (a < c its labels): the labels of a
  // tet are a few slabs apart, so c - a is small and the key fits in about 33 bits,
  // three radix passes instead of five or six for (a - lo) << 32 | (c - lo), whose low
  // word is as wide as the hull tets' reach. The rare edges that span more (under the
  // hull) skip the batch's de-duplication: the row's does it.
  void gather_rows(const FrameBatch& b) {
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
              if (ar < alimit && c - a < span) front[ns++] = ar << dbits | (c - a);
              else *--back = ar << 32 | cr, ++nl;
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

    // Pending entries (labels >= retired_ == lo) stay in front; the new ones follow.
    // An entry is label << 32 | other (labels and originals are below 2^32, checked by
    // the caller): 8 bytes instead of 16, half the radix sort's traffic.
    const std::size_t pending = directed_size_;
    std::uint64_t reach = top;
    for (std::size_t i = 0; i < pending; ++i) reach = std::max(reach, (directed_[i] >> 32) - lo);
    directed_size_ = pending + 2 * (short_edges + long_.size());
    directed_.reserve(directed_size_);  // grows only; never zeroed (every entry is written first)
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
      directed_[pending + 2 * std::size_t(i)] = a << 32 | points_.original(c);
      directed_[pending + 2 * std::size_t(i) + 1] = c << 32 | points_.original(a);
    }
    radix_sort(directed_.data(), directed_size_, directed_tmp_, std::bit_width(reach),
               [lo](std::uint64_t d) { return (d >> 32) - lo; });

    // The rows of the labels retired after this batch: [retired_, below).
    const std::uint64_t below = b.retire_below;
    const std::size_t labels = std::size_t(below - retired_);
    row_start_.assign(labels + 1, 0);
    std::size_t cut = 0;
    for (std::size_t l = 0; l < labels; ++l) {
      row_start_[l] = cut;
      while (cut < directed_size_ && directed_[cut] >> 32 == retired_ + l) ++cut;
    }
    row_start_[labels] = cut;
    row_others_.resize(cut);
    row_length_.resize(labels);
    const std::int64_t nl = std::int64_t(labels);
#pragma omp parallel for schedule(dynamic, 1024)
    for (std::int64_t l = 0; l < nl; ++l) {
      const std::size_t s = row_start_[std::size_t(l)], e = row_start_[std::size_t(l) + 1];
      std::uint32_t* o = row_others_.data() + s;
      for (std::size_t i = s; i < e; ++i) o[i - s] = std::uint32_t(directed_[i]);  // the original (low word)
      std::sort(o, o + (e - s));
      row_length_[std::size_t(l)] = std::size_t(std::unique(o, o + (e - s)) - o);
    }
    for (std::size_t l = 0; l < labels; ++l)
      sinks_.row(points_.original(retired_ + l),
                 std::span<const std::uint32_t>(row_others_.data() + row_start_[l], row_length_[l]));
    std::copy(directed_.data() + cut, directed_.data() + directed_size_, directed_.data());
    directed_size_ -= cut;
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
  std::vector<FinalPoint> final_;  // the points a batch retires
  std::vector<double> volumes_;  // without hull terms: the tets' volumes
  core::PageArray<std::uint64_t> edges_;  // the batch's packed edges (its capacity: 6 a tet)
  std::vector<std::uint64_t> radix_tmp_, long_;
  // Tets ahead whose vertices' slots are prefetched: a tet's four labels are spread
  // over the window, so nearly every slot is a cache miss, and the loops would
  // otherwise wait for each in turn.
  static constexpr std::int64_t kAhead = 8;
  static constexpr std::size_t kBlock = 4096;  // tets a block of the edge packing
  static constexpr int kSeenBits = 14;         // 16384 entries, 128 KiB a thread (docs/fields.md: the sizes tried)
  static constexpr std::size_t kSeen = std::size_t(1) << kSeenBits;
  std::vector<std::uint64_t> seen_;            // the threads' tables of emitted edges
  std::vector<std::size_t> block_short_, block_long_;
  // Entries (label << 32 | the neighbour's original index) of the labels not retired
  // yet, then the batch's: [0, directed_size_).
  core::PageArray<std::uint64_t> directed_;
  std::size_t directed_size_ = 0;
  std::vector<std::uint64_t> directed_tmp_;
  std::vector<std::size_t> row_start_, row_length_;
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
