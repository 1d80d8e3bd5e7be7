#pragma once
// The points of the label window (pipeline/field_window.hpp): coordinates and original
// indices, in two rings over the dense window [lo, lo + size) read from the container's
// PNTS section as the window advances (each point read once; its mapped pages handed
// back at once, so a container larger than memory keeps a bounded resident set), and
// the few "far" labels beyond it that a batch's tets reach, read one by one and kept
// in a map until the window catches up with them.
//
// Far labels exist because a tet's labels are near each other in the sort order except
// under the convex hull: a hull facet of a uniform cube spans the whole cube, and the
// tets below it join labels from both ends of the file. They are a thin set (of the
// order of the hull's size), so they cost a hash lookup each, not a window of N.
#include "core/compiler.hpp"
#include "io/tet_reader.hpp"
#include "pipeline/field/window.hpp"

#include <array>
#include <cstdint>
#include <unordered_map>
#include <vector>

namespace tetstream::pipeline {

class WindowPoints {
 public:
  // ring_labels: a power of two, the dense window's size.
  WindowPoints(const io::TetReader& reader, std::uint64_t ring_labels);

  // Moves the dense window to [lo, min(N, lo + size)): loads the labels that enter it,
  // calling fresh(label) for each, in increasing order (before it, the label may still
  // be far: the caller moves what it kept for it). lo must not decrease.
  template <class Fresh>
  void advance(std::uint64_t lo, Fresh&& fresh) {
    const std::uint64_t end = std::min(reader_.point_count(), lo + xyz_.size());
    if (end > next_) {
      const std::uint64_t first = next_;
      load(first, end - first);
      for (std::uint64_t l = first; l < end; ++l) fresh(l);
      if (!far_.empty()) std::erase_if(far_, [end](const auto& kv) { return kv.first < end; });
    }
  }
  // Reads the far labels of the batch's tets not read yet (one thread).
  void fetch_far(const DecodedBatch& batch);
  // The dense loads throw InputError unless the points are in the order `run` writes
  // along `axis` (0..2): every point of a brick of `brick` labels (io::label_brick: 1
  // in version 1) at or above every point of the bricks before it. The grid retires
  // planes by it (axis_floor).
  void check_sorted_along(int axis, std::uint64_t brick) { axis_ = axis, brick_ = brick; }
  // With check_sorted_along: a coordinate along its axis that no point of label
  // `label` or above lies below, from the labels loaded so far (the largest coordinate
  // of the bricks before the label's; -infinity when none is loaded).
  double axis_floor(std::uint64_t label) const;

  bool dense(std::uint64_t label) const { return label < next_; }
  std::uint64_t dense_end() const { return next_; }
  const double* xyz(std::uint64_t label) const {
    return label < next_ ? xyz_[label].data() : far_.find(label)->second.xyz.data();
  }
  // Asks for a dense label's coordinates ahead of their use (a tet's vertices are
  // spread over the window: nearly every one misses the cache).
  void prefetch(std::uint64_t label) const {
    if (label < next_) TS_PREFETCH(xyz_[label].data());
  }
  std::uint64_t original(std::uint64_t label) const {
    return label < next_ ? ids_[label] : far_.find(label)->second.original;
  }
  std::size_t far_count() const { return far_.size(); }

 private:
  struct Far {
    std::array<double, 3> xyz;
    std::uint64_t original;
  };
  void load(std::uint64_t first, std::uint64_t n);

  const io::TetReader& reader_;
  LabelRing<std::array<double, 3>> xyz_;
  LabelRing<std::uint64_t> ids_;
  std::unordered_map<std::uint64_t, Far> far_;
  std::uint64_t next_ = 0;  // labels below were loaded into the rings
  int axis_ = -1;
  std::uint64_t brick_ = 1;
  // The largest coordinate on axis_ of bricks 0..k, for each brick k begun (the last
  // one may be partly loaded).
  std::vector<double> brick_top_;
};

}  // namespace tetstream::pipeline
