#pragma once
// A spatial index over the sorted point file, for the emptiness queries of the
// segment check (DESIGN.md section 3): "is any point outside the window inside this
// ball?" must be cheap even for the huge, thin balls of flat tets on the hull, which
// span much of the axis but touch few points.
//
// The sorted file is cut into blocks of consecutive labels (thin slabs across the
// axis). Each block is split into cells of at most kCellPoints points by median splits
// on the widest side of their box (a kd-tree's leaves); a cell stores its points'
// labels (as 16-bit offsets in the block) and their tight bounding box. A query visits
// the blocks of its axis range whose box meets the ball, then the cells whose box
// meets it, and tests only their points. (A fixed grid per block put the points of a
// dense filament into one crowded cell, which every ball touching the filament had to
// scan: 10^7 points of the `mixed` distribution took 9x longer than uniform ones.)
//
// Memory: 2 bytes per point plus 56 bytes per cell (a cell holds 32 to 64 points):
// about 3.5 bytes per point.
#include "pipeline/point_sort.hpp"

#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

class PointIndex {
 public:
  static constexpr std::uint32_t kBlockPoints = 8192;  // labels per block (< 2^16)
  static constexpr std::uint32_t kCellPoints = 64;     // most points in a cell

  PointIndex() = default;
  // Builds the index over points[0, count) sorted along `axis`. When the points are
  // a read-only file mapping, release_file_pages hands each block's pages back to
  // the page cache once it is indexed (one pass, bounded resident set); never set it
  // for anonymous memory, whose pages MADV_DONTNEED would zero.
  void build(const SortedPoint* points, std::uint64_t count, int axis, bool release_file_pages = false);

  // Calls visit(label) for every label in [first, last) whose point may lie in the
  // closed ball (center, radius); points certainly outside are skipped. Stops early,
  // between cells, once stop() returns true.
  template <class Visit, class Stop>
  void for_each_candidate(const double* center, double radius, std::uint64_t first, std::uint64_t last,
                          Visit&& visit, Stop&& stop) const {
    if (first >= last) return;
    const std::uint64_t b0 = first / kBlockPoints, b1 = (last - 1) / kBlockPoints;
    for (std::uint64_t b = b0; b <= b1; ++b) {
      if (!box_meets_ball(blocks_[b].box, center, radius)) continue;
      const std::uint64_t base = b * kBlockPoints;
      const std::uint32_t c_end = blocks_[b].first_cell + blocks_[b].cells;
      for (std::uint32_t c = blocks_[b].first_cell; c < c_end; ++c) {
        const Cell& cell = cells_[c];
        if (!box_meets_ball(cell.box, center, radius)) continue;
        if (stop()) return;
        for (std::uint32_t i = cell.begin; i < cell.end; ++i) {
          const std::uint64_t label = base + offsets_[base + i];
          if (label >= first && label < last) visit(label);
        }
      }
    }
  }

  std::size_t memory_bytes() const {
    return offsets_.capacity() * sizeof(std::uint16_t) + cells_.capacity() * sizeof(Cell) +
           blocks_.capacity() * sizeof(Block);
  }

 private:
  struct Box {
    double lo[3], hi[3];
  };
  struct Cell {
    Box box;
    std::uint32_t begin, end;  // range in offsets_, relative to the block's base
  };
  struct Block {
    Box box;
    std::uint32_t first_cell, cells;
  };
  // Conservative: rounding may only say "meets" when it does not.
  static bool box_meets_ball(const Box& b, const double* c, double r) {
    double d2 = 0;
    for (int k = 0; k < 3; ++k) {
      double d = 0;
      if (c[k] < b.lo[k]) d = b.lo[k] - c[k];
      else if (c[k] > b.hi[k]) d = c[k] - b.hi[k];
      d2 += d * d;
    }
    return d2 <= r * r * (1 + 1e-12);
  }

  std::vector<std::uint16_t> offsets_;  // per block: offsets of its labels, grouped by cell
  std::vector<Cell> cells_;
  std::vector<Block> blocks_;
};

}  // namespace tetstream::pipeline
