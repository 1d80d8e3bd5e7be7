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
#include <bit>
#include <unordered_map>
#include <vector>

namespace tetstream::pipeline {
namespace {

struct Accum {
  double volume = 0.0, voronoi = 0.0, angle = 0.0;
};

class Accumulator {
 public:
  Accumulator(const io::TetReader& reader, const BatchPlan& plan, const AccumulateSinks& sinks, Progress* progress)
      : reader_(reader), plan_(plan), sinks_(sinks), progress_(progress), voronoi_(sinks.voronoi),
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
      combine();
      if (sinks_.edge) gather_edges(b);
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
      contrib_[std::size_t(t)] = tet_contribution(p, voronoi_);
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

  // The batch's edges as (smaller - lo) << 32 | (larger - lo), radix-sorted and made
  // unique, handed out both ways as original indices. An edge whose tets lie in several
  // batches comes out once per batch: the caller's sort by original index drops the
  // copies, so no per-point neighbour set is held here.
  void gather_edges(const FrameBatch& b) {
    const std::size_t n = batch_.tets();
    edges_.resize(6 * n);
    const std::int64_t nn = std::int64_t(n);
    const std::uint64_t lo = b.lo;  // every label of the batch is >= lo, and < lo + 2^32 (checked by the caller)
    std::uint64_t top = 0;
#pragma omp parallel for schedule(static, 4096) reduction(max : top)
    for (std::int64_t t = 0; t < nn; ++t) {
      const std::uint64_t* q = batch_.tet(std::size_t(t));
      std::uint64_t* e = &edges_[6 * std::size_t(t)];
      int k = 0;
      for (int i = 0; i < 4; ++i)
        for (int j = i + 1; j < 4; ++j) {
          const std::uint64_t a = std::min(q[i], q[j]) - lo, c = std::max(q[i], q[j]) - lo;
          e[k++] = a << 32 | c;
          top = std::max(top, c);
        }
    }
    const int bits = 32 + std::bit_width(top);
    radix_sort(edges_.data(), edges_.size(), radix_tmp_, bits, [](std::uint64_t x) { return x; });
    edges_.erase(std::unique(edges_.begin(), edges_.end()), edges_.end());
    for (const std::uint64_t e : edges_) {
      const std::uint64_t a = lo + (e >> 32), c = lo + (e & 0xffffffffu);
      sinks_.edge(points_.original(a), points_.original(c));
    }
    stats_.batch_edges += edges_.size();
  }

  void retire(std::uint64_t below) {
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

    }
    retired_ = below;
  }

  const io::TetReader& reader_;
  const BatchPlan& plan_;
  const AccumulateSinks& sinks_;
  Progress* progress_;
  bool voronoi_;
  WindowPoints points_;
  LabelRing<Accum> acc_;
  std::unordered_map<std::uint64_t, Accum> far_acc_;  // sums of the far labels
  DecodedBatch batch_;
  std::vector<TetContribution> contrib_;
  std::vector<std::uint64_t> edges_, radix_tmp_;
  std::uint64_t retired_ = 0;
  AccumulateStats stats_;
};

}  // namespace

AccumulateStats accumulate_fields(const io::TetReader& reader, const BatchPlan& plan, const AccumulateSinks& sinks,
                                  Progress* progress) {
  return Accumulator(reader, plan, sinks, progress).run();
}

}  // namespace tetstream::pipeline
