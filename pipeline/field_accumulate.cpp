#include "pipeline/field_accumulate.hpp"

#include "core/error.hpp"
#include "pipeline/external_sort.hpp"
#include "pipeline/field_geometry.hpp"
#include "pipeline/field_points.hpp"
#include "pipeline/interrupt.hpp"
#include "pipeline/progress.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <unordered_map>
#include <vector>

namespace tetstream::pipeline {
namespace {

struct Accum {
  double volume = 0.0, voronoi = 0.0, angle = 0.0;
};

// A neighbour entry of the window: point `label` has the neighbour whose original
// index is `other`. Sorted by (label, other), unique.
struct Pair {
  std::uint64_t label, other;
  bool operator<(const Pair& o) const { return label != o.label ? label < o.label : other < o.other; }
  bool operator==(const Pair& o) const = default;
};

class Accumulator {
 public:
  Accumulator(const io::TetReader& reader, const BatchPlan& plan, const AccumulateSinks& sinks, Progress* progress)
      : reader_(reader), plan_(plan), sinks_(sinks), progress_(progress), points_(reader, plan.ring_labels),
        acc_(plan.ring_labels) {}

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
      combine();
      if (sinks_.neighbours) gather_edges(b);
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
    contrib_.resize(n);
    const std::int64_t nn = std::int64_t(n);
#pragma omp parallel for schedule(static, 4096)
    for (std::int64_t t = 0; t < nn; ++t) {
      const std::uint64_t* q = batch_.tet(std::size_t(t));
      const double* p[4] = {points_.xyz(q[0]), points_.xyz(q[1]), points_.xyz(q[2]), points_.xyz(q[3])};
      contrib_[std::size_t(t)] = tet_contribution(p);
    }
  }

  // One thread, fixed order: the bits of every sum do not depend on the threads.
  void combine() {
    std::size_t t = 0;
    for (std::size_t f = 0; f < batch_.frames(); ++f) {
      const std::vector<std::uint64_t>& labels = batch_.frame(f);
      for (std::size_t i = 0; i < labels.size(); i += 4, ++t) {
        const TetContribution& c = contrib_[t];
        for (int v = 0; v < 4; ++v) {
          const std::uint64_t l = labels[i + std::size_t(v)];
          Accum& a = points_.dense(l) ? acc_[l] : far_acc_[l];
          a.volume += c.volume;
          a.voronoi += c.voronoi[v];
          a.angle += c.angle[v];
        }
      }
    }
  }

  // The batch's edges as (smaller - lo) << 32 | (larger - lo), made unique, then
  // merged both ways into the window's pair list.
  void gather_edges(const FrameBatch& b) {
    const std::size_t n = batch_.tets();
    edges_.resize(6 * n);
    const std::int64_t nn = std::int64_t(n);
    const std::uint64_t lo = b.lo;  // every label of the batch is >= lo, and < lo + 2^32 (checked by the caller)
#pragma omp parallel for schedule(static, 4096)
    for (std::int64_t t = 0; t < nn; ++t) {
      const std::uint64_t* q = batch_.tet(std::size_t(t));
      std::uint64_t* e = &edges_[6 * std::size_t(t)];
      int k = 0;
      for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
          const std::uint64_t a = std::min(q[i], q[j]) - lo, c = std::max(q[i], q[j]) - lo;
          e[k++] = a << 32 | c;
        }
    }
    parallel_sort(edges_.data(), edges_.data() + edges_.size(), std::less<std::uint64_t>());
    edges_.erase(std::unique(edges_.begin(), edges_.end()), edges_.end());
    fresh_.clear();
    fresh_.reserve(2 * edges_.size());
    for (const std::uint64_t e : edges_) {
      const std::uint64_t a = lo + (e >> 32), c = lo + (e & 0xffffffffu);
      fresh_.push_back({a, points_.original(c)});
      fresh_.push_back({c, points_.original(a)});
    }
    parallel_sort(fresh_.data(), fresh_.data() + fresh_.size(), std::less<Pair>());
    merged_.clear();
    merged_.reserve(pairs_.size() - pairs_head_ + fresh_.size());
    std::merge(pairs_.begin() + std::ptrdiff_t(pairs_head_), pairs_.end(), fresh_.begin(), fresh_.end(),
               std::back_inserter(merged_));
    merged_.erase(std::unique(merged_.begin(), merged_.end()), merged_.end());
    pairs_.swap(merged_);
    pairs_head_ = 0;
    stats_.peak_pairs = std::max<std::uint64_t>(stats_.peak_pairs, pairs_.size());
  }

  void retire(std::uint64_t below) {
    std::vector<std::uint64_t>& nb = scratch_;
    for (std::uint64_t l = retired_; l < below; ++l) {
      FinalPoint p;
      p.label = l;
      p.original = points_.original(l);
      const double* x = points_.xyz(l);
      p.xyz[0] = x[0], p.xyz[1] = x[1], p.xyz[2] = x[2];
      const Accum& a = acc_[l];
      p.volume = a.volume;
      p.voronoi = a.voronoi;
      p.hull = a.angle < kHullAngleThreshold;
      if (sinks_.point) sinks_.point(p);
      if (sinks_.neighbours) {
        nb.clear();
        while (pairs_head_ < pairs_.size() && pairs_[pairs_head_].label == l) nb.push_back(pairs_[pairs_head_++].other);
        stats_.neighbour_entries += nb.size();
        sinks_.neighbours(p, nb);
      }
    }
    retired_ = below;
  }

  const io::TetReader& reader_;
  const BatchPlan& plan_;
  const AccumulateSinks& sinks_;
  Progress* progress_;
  WindowPoints points_;
  LabelRing<Accum> acc_;
  std::unordered_map<std::uint64_t, Accum> far_acc_;  // sums of the far labels
  DecodedBatch batch_;
  std::vector<TetContribution> contrib_;
  std::vector<std::uint64_t> edges_, scratch_;
  std::vector<Pair> pairs_, fresh_, merged_;
  std::size_t pairs_head_ = 0;  // pairs_[0, head) were handed out
  std::uint64_t retired_ = 0;
  AccumulateStats stats_;
};

}  // namespace

AccumulateStats accumulate_fields(const io::TetReader& reader, const BatchPlan& plan, const AccumulateSinks& sinks,
                                  Progress* progress) {
  return Accumulator(reader, plan, sinks, progress).run();
}

}  // namespace tetstream::pipeline
