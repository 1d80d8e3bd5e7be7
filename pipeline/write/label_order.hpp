#pragma once
// The labels of a container of format 2 (docs/format.md §3.4): the sort's order cut into
// bricks, each brick reordered along a space-filling curve.
//
// Why: the pipeline works on labels sorted along one axis, where a tet's upper vertices
// lie about N^(2/3) labels above its smallest one. The frame codec remembers neighbours
// within 65535 labels and within its frame (2^18 tets, ~39,000 labels), so past 10^7
// points nearly every upper vertex is new to it: 3.51 bytes a tet at 10^8, 3.975 at
// 10^9. Inside a brick of ~2 slabs of points (2 N^(2/3) labels, a power of two) the
// curve keeps a frame's labels in a compact block of space, and the tet's vertices
// among them: 1.634 -> 1.543 bytes a tet at 10^6 and 2.212 -> 1.731 at 10^7 uniform
// (docs/benchmarks.md, with 10^8).
//
// The order, for the points of a brick (given in the sort's order):
//   - columns: the cross-section (the two axes other than the sort axis) cut into
//     squares as wide as the brick is thick along the sort axis (its last point's key
//     less its first's), ordered along a Hilbert curve;
//   - inside a column: a Morton order of 2^k cells an axis, k the least with 2 * 8^k at
//     least the brick's mean points per non-empty column (at most 10);
//   - ties: the sort's order.
// It depends only on the brick's points and their sort order, so on the input alone:
// not on --memory, the threads, the segments or the ranks, and every writer of a job
// (the frames, the points section, standard output, each rank) computes the same one.
//
// A brick maps its label range onto itself, so a tet's smallest label stays in the brick
// of its smallest sorted label: the tets of a brick are those of its sorted labels.
#include "io/tet_container.hpp"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace tetstream::pipeline {

// Labels a brick: io::brick_labels (format.md §3.4).
using io::brick_labels;

// The permutation of one brick: new_of_old[i] is the position in the brick, in format
// 2's order, of its i-th point in the sort's order. `xyz`: 3 doubles a point, in the
// sort's order along `axis`.
void brick_permutation(const double* xyz, std::size_t n, int axis, std::vector<std::uint32_t>& new_of_old);

// Writes every brick's permutation (brick_permutation) to `path`, 4 bytes a label in
// the sort's order (new_of_old, brick after brick), the bricks on `threads` threads;
// read(first, n, xyz) gives the coordinates of the sorted labels [first, first + n)
// and is called from those threads. A work file of the job (4 bytes a point): the
// tets' labels are mapped through it (LabelOrder), far ones included.
using ReadPoints = std::function<void(std::uint64_t first, std::size_t n, double* xyz)>;
void write_label_order(const std::string& path, std::uint64_t point_count, int axis, const ReadPoints& read,
                       int threads);

// Sorted labels to format 2's labels through the file write_label_order made: a window
// of the bricks the coming tets are in, kept whole and contiguous (one comparison a
// label), any other label read on its own (the far vertex of a long tet: the convex
// hull's, a surface's sky edges). One caller at a time.
class LabelOrder {
 public:
  // The bricks of the window: the one a tet's smallest label is in and the next two (a
  // brick is two slabs of points thick; a tet reaches about 2.5 slabs).
  static constexpr std::size_t kKeptBricks = 3;
  LabelOrder(const std::string& path, std::uint64_t point_count);
  ~LabelOrder();
  LabelOrder(const LabelOrder&) = delete;
  LabelOrder& operator=(const LabelOrder&) = delete;

  std::uint64_t brick() const { return brick_; }
  std::uint64_t point_count() const { return count_; }
  // The format 2 label of sorted label `l` (< point_count()).
  std::uint64_t operator()(std::uint64_t l) {
    const std::uint64_t d = l - window_first_;  // below the window: wraps past its size
    if (d < window_.size()) return (l & ~(brick_ - 1)) + window_[std::size_t(d)];
    return far(l);
  }
  // Moves the window to bricks [b, b + kKeptBricks) (b never decreasing): the bricks
  // the coming tets are in.
  void keep_from(std::uint64_t b);
  // Brick b's permutation (brick_permutation's new_of_old), read from the file; safe
  // beside another thread's lookups (the points section's writers read it).
  void read_brick(std::uint64_t b, std::vector<std::uint32_t>& new_of_old) const;

 private:
  std::uint64_t far(std::uint64_t l) const;

  std::string path_;
  int fd_ = -1;
  std::uint64_t count_, brick_;
  int shift_;
  // new_of_old of the window's bricks, one after the other, from label window_first_.
  std::vector<std::uint32_t> window_;
  std::uint64_t window_first_ = 0;
  std::vector<std::uint32_t> scratch_;
};

}  // namespace tetstream::pipeline
