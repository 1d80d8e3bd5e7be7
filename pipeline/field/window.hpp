#pragma once
// The sliding label window of `tetstream field`: which frames are processed together,
// and which points are final after them.
//
// Invariant (docs/format.md, docs/fields.md): frames are stored in non-decreasing order
// of base_label (their smallest label; `run` cuts them by minimum label), and every tet
// of frame k has all four labels >= base_k. So after frames 0..k have been combined, no
// later frame touches a label below base_{k+1}: those points are final and are retired.
// The frame index alone gives every retirement point, before any frame is decoded.
//
// What a batch holds: the dense window [lo, lo + R) of R labels (a ring sized from the
// budget) with the labels it retires, [lo, retire_below), inside it; the labels its
// tets reach beyond the ring are "far" (pipeline/field_points.hpp). For points sorted
// along an axis a tet's labels are a few slabs apart (~2.5 N^(2/3) labels for uniform
// points) except under the convex hull, whose long facets join the two ends of the
// file: the frame index's max_label is N - 1 within the first frames of a uniform cube,
// so the index cannot bound the window, and the few hull-spanning labels go to a map.
#include "io/tet_container.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::pipeline {

struct FrameBatch {
  std::size_t first_frame = 0, end_frame = 0;  // frames [first, end)
  std::uint64_t lo = 0;                        // base label of the first frame: the window's start
  std::uint64_t hi = 0;            // the batch's largest label (frames' max_label), at least retire_below - 1
  std::uint64_t retire_below = 0;  // labels < this are final after the batch (next batch's lo, or N)
  std::uint64_t tets = 0;
};

struct BatchPlan {
  std::vector<FrameBatch> batches;
  std::uint64_t window_labels = 0;  // largest retired range retire_below - lo of a batch
  std::uint64_t ring_labels = 0;    // the dense window's size R: max_labels, or N rounded up when smaller
  std::uint64_t largest_batch_tets = 0;
};

// Groups the frames into batches of at most max_tets tets (a frame is never split; a
// bigger frame is a batch of its own) that retire at most max_labels (a power of two)
// labels. Throws
// InputError naming `path` when the frames are not ordered by base label or a frame's
// labels are out of range, and UsageError when one frame alone needs a window wider
// than max_labels (the message gives the labels needed).
BatchPlan plan_batches(const std::vector<io::FrameEntry>& frames, std::uint64_t point_count, std::uint64_t max_tets,
                       std::uint64_t max_labels, const std::string& path);

// A ring of per-label slots of T for the labels [lo, hi] of the window: slot of label l
// is l & (size - 1). Labels leave from the front (retire) and enter at the back (load);
// the caller keeps hi - lo < size.
template <class T>
class LabelRing {
 public:
  explicit LabelRing(std::uint64_t size = 0) : mask_(size ? size - 1 : 0), slots_(size) {}
  T& operator[](std::uint64_t label) { return slots_[label & mask_]; }
  const T& operator[](std::uint64_t label) const { return slots_[label & mask_]; }
  std::uint64_t size() const { return slots_.size(); }
  // Contiguous runs of slots for the labels [first, first + n): at most two (the wrap).
  template <class F>
  void for_runs(std::uint64_t first, std::uint64_t n, F&& f) {
    while (n > 0) {
      const std::uint64_t at = first & mask_;
      const std::uint64_t run = std::min<std::uint64_t>(n, slots_.size() - at);
      f(first, &slots_[at], std::size_t(run));
      first += run;
      n -= run;
    }
  }

 private:
  std::uint64_t mask_;
  std::vector<T> slots_;
};

}  // namespace tetstream::pipeline

namespace tetstream::io {
class TetReader;
}

namespace tetstream::pipeline {

// The frames of one batch, decoded on all OpenMP threads (a frame per thread), with
// their tets addressable by their ordinal in the batch (frames in order, then stored
// order).
class DecodedBatch {
 public:
  void decode(const io::TetReader& reader, const FrameBatch& b);
  std::size_t tets() const { return first_[frames_used_]; }
  std::size_t frames() const { return frames_used_; }
  const std::vector<std::uint64_t>& frame(std::size_t i) const { return frames_[i]; }
  const std::uint64_t* tet(std::size_t t) const {
    std::size_t f = 0;
    while (first_[f + 1] <= t) ++f;  // a batch holds a handful of frames
    return frames_[f].data() + 4 * (t - first_[f]);
  }

 private:
  std::vector<std::vector<std::uint64_t>> frames_;
  std::vector<std::size_t> first_{0};
  std::size_t frames_used_ = 0;
};

}  // namespace tetstream::pipeline
