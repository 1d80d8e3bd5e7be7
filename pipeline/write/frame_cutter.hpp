#pragma once
// Frames of the output: where the tets of the zones become the container's frames.
#include "pipeline/write/async_tet_writer.hpp"
#include "pipeline/util/memory_budget.hpp"
#include "pipeline/window/zone_triangulator.hpp"

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace tetstream::pipeline {

// The frame size (kFrameTets, MemoryBudget::frame_tets_for) is in
// pipeline/memory_budget.hpp, which sizes the writer's share from it.

// Frames never span two blocks of frame_block_labels(frame_tets) labels (by minimum
// label): the frames of a block depend only on the tets of that block, so processes
// that triangulate block-aligned label ranges (ranks under MPI, docs/scaling.md) cut
// the same frames as one process does, each on its own. A block holds about 6.7
// frames (a label has ~6.7 tets); its last frame is cut short (about 4% more frames
// than without blocks).
inline std::uint64_t frame_block_labels(std::size_t frame_tets) { return frame_tets; }

// The last stage before the writer: turns the zones' output, in minimum-label order,
// into frames of about `frame_tets` tets, cut where the minimum label changes, and
// where it enters a new block of frame_block_labels(frame_tets) labels.
class FrameCutter {
 public:
  FrameCutter(AsyncTetWriter& writer, std::size_t frame_tets)
      : writer_(writer), frame_tets_(frame_tets), block_labels_(frame_block_labels(frame_tets)), frame_(next_frame()) {}

  // Appends the tets [begin, end) of a zone's output, translated to labels straight
  // into the frame being filled (they come in increasing minimum-label order; a group
  // may go on in the next call). A frame is handed to the writer, not copied, at the
  // first change of minimum label after frame_tets tets.
  void add(const ZoneTets& part, std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const std::uint64_t q[4] = {part.label(i, 0), part.label(i, 1), part.label(i, 2), part.label(i, 3)};
      add(q);
    }
  }
  // One tet, its smallest label not below the previous tet's.
  void add(const std::uint64_t* q) { add(q, tet_min_label(q)); }
  // The same, with its smallest label `m` known.
  void add(const std::uint64_t* q, std::uint64_t m) {
    if (m != last_min_ && !frame_.empty() &&
        (frame_.size() >= 4 * frame_tets_ || m / block_labels_ != last_min_ / block_labels_))
      write();
    // Four stores, not insert(): that was a call to memmove a tet.
    const std::size_t at = frame_.size();
    frame_.resize(at + 4);
    for (std::size_t k = 0; k < 4; ++k) frame_[at + k] = q[k];
    last_min_ = m;
  }
  void flush() {
    if (!frame_.empty()) write();
  }
  // The tets of the frame being filled: a checkpoint saves them, a resumed job
  // restores them, and its frames come out as an uninterrupted job's.
  const std::vector<std::uint64_t>& pending() const { return frame_; }
  void restore(std::vector<std::uint64_t> pending) {
    frame_ = std::move(pending);
    if (!frame_.empty()) last_min_ = tet_min_label(&frame_[frame_.size() - 4]);
  }

 private:
  void write() {
    writer_.add_tets(std::move(frame_));
    frame_ = next_frame();
  }
  // An empty frame with room for frame_tets tets and a group's overrun (a recycled
  // buffer keeps its capacity).
  std::vector<std::uint64_t> next_frame() {
    std::vector<std::uint64_t> f = writer_.take_buffer();
    f.reserve(4 * frame_tets_ + 4096);
    return f;
  }

  AsyncTetWriter& writer_;
  const std::size_t frame_tets_;
  const std::uint64_t block_labels_;
  std::vector<std::uint64_t> frame_;
  std::uint64_t last_min_ = ~std::uint64_t(0);
};

}  // namespace tetstream::pipeline
