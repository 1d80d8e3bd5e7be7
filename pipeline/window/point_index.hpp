#pragma once
// A spatial index over the sorted point file, for the emptiness queries of the
// certificate's emptiness query (docs/certificate.md): "is any point outside the window inside this
// ball?" must be cheap even for the huge, thin balls of flat tets on the hull, which
// span much of the axis but touch few points.
//
// The sorted file is cut into blocks of consecutive labels: slabs across the sort
// axis, each a few point spacings thick (block_points_for). Each block holds a kd-tree:
// median splits on the widest side of the box, down to leaves of at most kLeafPoints
// points, every node with the tight box of its points, the leaves' labels stored as
// offsets in the block (with each point's cell, below). A query visits the blocks of its label range, and in
// each the nodes whose box meets the ball (and, along the axis, the coordinates of
// that label range), skipping a whole subtree when its box does not; it tests only
// the points of the leaves it reaches.
//
// Why thick blocks: a query ball is a point spacing or two across. Blocks of a fixed
// 8192 labels were a fifth of a spacing thick at 10^7 uniform points, so a ball
// crossed some 20 of them, descending 20 trees to reach leaves that were flat tiles
// of 64 points, most of them outside the ball. A block a few spacings thick is
// crossed by one or two balls' worth, and its leaves are compact cells. Why at most
// 2^18 labels: the huge balls of clustered inputs and shells cross many blocks, and
// each block's tree is descended from its root: at 10^7 points, 2^16-label blocks
// visited 845 M nodes on `mixed` and 805 M on the ellipsoid shell, 2^18-label blocks
// 467 M and 536 M (the shell's checks 38.3 -> 28.0 s summed), 2^20 411 M on `mixed`
// but more leaf points outside the label range, and no faster; a leaf's points are
// scattered over its block's span of the file (8 MiB at 2^18), and 2^21-label blocks
// once made the strip queries, which filter leaf points one by one, miss on every
// point.
// (Before the trees, a fixed 12x12 grid per block put a dense filament into one
// crowded cell: `mixed` 10^7 took 336 s against 39 s for uniform.)
//
// A leaf also keeps each point's cell in its box (16 slices an axis, in the 14 bits
// its 18-bit offset leaves of a 32-bit entry), so a query tests the cells of the
// leaves it reaches and reads from the file only the points whose cell meets the
// ball: on `mixed` 10^7 the queries' leaves held 534 M points, of which 5.6 M were in
// the balls, and reading them all from the mapped file (a cache miss each, and the
// OS's page mapping as the pages came and went) made the checks 48 s of 90 (summed).
//
// Memory, by the layout: a 4-byte entry per point plus a 36-byte node per 16 points
// (2^18-label blocks split into leaves of 32): about 6 bytes per point.
#include "pipeline/files/temp_files.hpp"
#include "pipeline/sort/point_record.hpp"
#include "pipeline/window/ball_bounds.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

namespace tetstream::pipeline {

// A slab whose points a query does not want (a strip window's own, which are not
// missing): index nodes whose box lies inside it are skipped. axis < 0: none.
struct ExcludedSlab {
  int axis = -1;
  double lo = 0, hi = 0;
  bool contains(const double* box_lo, const double* box_hi) const {
    return axis >= 0 && box_lo[axis] >= lo && box_hi[axis] <= hi;
  }
};

// Bounds on the sort-axis keys of a label range: lo <= every key <= hi.
struct KeyRange {
  double lo, hi;
};

class PointIndex {
 public:
  // Most points in a leaf. With the cells a leaf's points cost little: leaves of 48
  // rather than 24 halve the nodes (about 2 bytes a point) and the queries did not
  // slow (mixed 10^7, with an earlier 3-byte form of the cells: 37.6 s against 37.9).
  static constexpr std::uint32_t kLeafPoints = 48;
  static constexpr std::uint32_t kMinBlockPoints = 1u << 13, kMaxBlockPoints = 1u << 18;

  // Labels per block for `count` points sorted along an axis of length `axis_extent`
  // in a bounding box of `volume`: the points of a slab about 8 mean spacings thick,
  // within [kMinBlockPoints, kMaxBlockPoints].
  static std::uint32_t block_points_for(std::uint64_t count, double axis_extent, double volume);

  PointIndex() = default;
  // Builds the index over points[0, count), sorted along `axis`, in blocks of
  // `block_points` labels. When the points are a read-only file mapping,
  // release_file_pages hands each block's pages back to the page cache once it is
  // indexed (one pass, bounded resident set); never set it for anonymous memory,
  // whose pages MADV_DONTNEED would zero.
  void build(const PointRecords& points, std::uint64_t count, int axis, std::uint32_t block_points,
             bool release_file_pages = false);

  // ---- one index built by the ranks of a job in parts, shared through one file ----
  // The file: every point's entry (4 bytes) and then every point's fine cell (2 bytes),
  // in label order; every node (36 bytes) in block order; every block (16 bytes). A
  // rank builds the blocks [first_block, end_block) (build_part), writes them at their
  // places with its nodes renumbered after the nodes of the parts before it
  // (write_part), and every rank maps the whole file (attach): the same index as
  // build() makes, node for node, held by the page cache rather than by each rank.
  struct FileLayout {
    std::uint64_t entries = 0, fine = 0, nodes = 0, blocks = 0, bytes = 0;  // offsets, and the file's size
  };
  static FileLayout file_layout(std::uint64_t count, std::uint64_t node_count, std::uint64_t block_count);
  static std::uint64_t blocks_for(std::uint64_t count, std::uint32_t block_points) {
    const std::uint64_t bp = std::clamp<std::uint32_t>(block_points, 1, kMaxBlockPoints);
    return (count + bp - 1) / bp;
  }
  // The nodes build() makes for `count` points in blocks of `block_points`: a block's
  // tree has a shape fixed by its point count (median splits down to kLeafPoints), so
  // a file can be laid out before any block is built (the single-process index on
  // disk, which writes its blocks a chunk at a time).
  static std::uint64_t node_count_for(std::uint64_t count, std::uint32_t block_points);
  // Builds blocks [first_block, end_block) as build() would (release_file_pages as
  // there); part_nodes() nodes, numbered from 0. The index cannot answer queries until
  // attach().
  void build_part(const PointRecords& points, std::uint64_t count, int axis, std::uint32_t block_points,
                  std::uint64_t first_block, std::uint64_t end_block, bool release_file_pages = false);
  std::uint64_t part_nodes() const { return own_nodes_.size(); }
  // Writes the part with pwrite into `fd` (`path` for errors), laid out for
  // `total_nodes` nodes, its nodes numbered from `first_node`; then frees the part.
  void write_part(int fd, const std::string& path, std::uint64_t total_nodes, std::uint64_t first_node);
  // The index from a mapping of the whole file (read-only; it outlives this index),
  // for `count` points, `total_nodes` nodes. `resident_bytes`: what memory_bytes()
  // reports, the share of the mapping the caller plans for (its pages are the page
  // cache's; the caller hands them back, see stage_index.hpp).
  void attach(const std::byte* mapping, const PointRecords& points, std::uint64_t count, int axis,
              std::uint32_t block_points, std::uint64_t total_nodes, std::uint64_t resident_bytes);

  // An attached index read through a mapping whose resident pages are bounded by
  // `regions` (MappedRegions, 2 MiB regions held least recently used first): every
  // read of a block (a query's, the spacing estimate's, a sample's) touches the
  // regions of its entries, cells and nodes first. Null (the default): no tracking.
  void track_regions(MappedRegions* regions) { regions_ = regions; }

  // Calls visit(label) for every label in [first, last) whose point may lie in the
  // closed ball (center, radius), except some inside `exclude`; points certainly
  // outside the ball are skipped. Stops early, between leaves, once stop() returns
  // true.
  template <class Visit, class Stop>
  void for_each_candidate(const double* center, double radius, std::uint64_t first, std::uint64_t last, Visit&& visit,
                          Stop&& stop, const ExcludedSlab& exclude = {}) const {
    for_each_candidate_where(BallRegion{center, radius}, first, last, visit, stop, exclude);
  }

  // The same for any region: may_meet(lo, hi) says whether the box [lo, hi] may hold
  // a point of it (conservatively: never false when it does).
  // `keys`, when given, bounds the keys of [first, last) (otherwise they are read
  // from the points at both ends).
  template <class MayMeet, class Visit, class Stop>
  void for_each_candidate_where(MayMeet&& may_meet, std::uint64_t first, std::uint64_t last, Visit&& visit, Stop&& stop,
                                const ExcludedSlab& exclude = {}, const KeyRange* keys = nullptr) const {
    if (first >= last) return;
    // The labels [first, last) have axis coordinates in [axis_lo, axis_hi] (the file
    // is sorted): a node entirely outside that interval holds none of them.
    const double axis_lo = keys ? keys->lo : points_.coord(first, axis_);
    const double axis_hi = keys ? keys->hi : points_.coord(last - 1, axis_);
    const std::uint64_t b0 = first / block_points_, b1 = (last - 1) / block_points_;
    // The choice between the scaled and the plain boxes is made once a block, not
    // once a node (see Block).
    for (std::uint64_t b = b0; b <= b1; ++b) {
      const bool stopped = blocks_[b].scale == 1.0
                               ? scan_block<false>(b, may_meet, first, last, axis_lo, axis_hi, visit, stop, exclude)
                               : scan_block<true>(b, may_meet, first, last, axis_lo, axis_hi, visit, stop, exclude);
      if (stopped) return;
    }
  }

  // The local point spacing, from the leaves: cbrt(box volume / points) of each leaf
  // with a solid box, and the q-quantile of those (0 when no leaf has volume: flat
  // inputs). On uniform points it is about the mean spacing cbrt(volume / n); on a
  // thin shell or in clusters it is the spacing where the points are, which the
  // bounding box's mean overestimates many times. [first, last): only the leaves of
  // the blocks holding those labels (the spacing of a segment's own points).
  double leaf_spacing_quantile(double q, std::uint64_t first = 0, std::uint64_t last = ~std::uint64_t(0)) const;

  // A spatially compact sample of block b: the labels of the subtree reached from the
  // block's root by taking the first child, then the second, and so on (`last`: the
  // second first), down to the first node of at most max_points points. For estimates
  // (pipeline/rank_cost.hpp).
  std::vector<std::uint64_t> compact_sample(std::uint64_t b, std::uint32_t max_points, bool last) const;
  std::uint64_t block_count() const { return blocks_.size(); }
  std::uint32_t block_points() const { return block_points_; }

  std::size_t memory_bytes() const {
    return own_entries_.capacity() * sizeof(std::uint32_t) + own_fine_.capacity() * sizeof(std::uint16_t) +
           own_nodes_.capacity() * sizeof(Node) + own_blocks_.capacity() * sizeof(Block) + resident_bytes_;
  }

  // Whether the box [lo, hi] meets the closed ball (c, r), conservatively
  // (pipeline/window/ball_bounds.hpp).
  static bool box_meets_ball(const double* lo, const double* hi, const double* c, double r) {
    return pipeline::box_meets_ball(lo, hi, c, r);
  }

 private:
  // A node's box in floats rounded outward: it contains the points' box, so every
  // test against it stays conservative, in 36 bytes a node instead of 64. The floats
  // hold the coordinates divided by the block's scale (Block), rounded outward so
  // that float * scale, as the query computes it, still bounds the box.
  struct Box {
    float lo[3], hi[3];
  };
  struct Node {
    Box box;
    std::uint32_t begin, end;  // range in entries_, relative to the block's base
    std::uint32_t next : 31;   // the first node after this one's subtree (absolute)
    std::uint32_t leaf : 1;    // a leaf: its points are [begin, end)
  };
  static_assert(sizeof(Node) == 36);
  // A block's boxes are stored as they are (scale 1) when its points' largest
  // magnitude lies in [2^-100, 2^100] (or is 0): floats hold such coordinates without
  // overflow and with their full precision down to 2^-149 away. Otherwise (coordinates
  // past FLT_MAX ~ 2^128, or so small that floats would round them all to 0 or to a
  // few subnormal steps, which makes every box meet every ball) they are stored as
  // multiples of scale = 2^e, a normal double chosen so that the largest magnitude
  // becomes about 2^60: any finite double input gets finite, tight float boxes
  // (points 2^-200 times smaller than the block's largest still collapse to 0, which
  // costs queries time, never answers). The choice is per block, so the query's
  // branch is taken once a block.
  struct Block {
    std::uint32_t first_node, nodes;
    double scale = 1.0;
  };
  static double block_scale(double max_magnitude);
  // A node's box in doubles, as every query and the build's cells see it.
  template <bool kScaled>
  static void decode(const Box& box, double scale, double* lo, double* hi) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = kScaled ? double(box.lo[k]) * scale : double(box.lo[k]);
      hi[k] = kScaled ? double(box.hi[k]) * scale : double(box.hi[k]);
    }
  }
  // Visits the candidates of block b (for_each_candidate_where); true when stop() said so.
  template <bool kScaled, class MayMeet, class Visit, class Stop>
  bool scan_block(std::uint64_t b, MayMeet& may_meet, std::uint64_t first, std::uint64_t last, double axis_lo,
                  double axis_hi, Visit& visit, Stop& stop, const ExcludedSlab& exclude) const {
    touch_block(b);
    const std::uint64_t base = b * block_points_;
    const double scale = blocks_[b].scale;
    // Nodes in preorder; `next` of a node is the first node after its subtree, so
    // a node whose box misses the ball is skipped with its whole subtree, and one
    // that meets it is entered by moving to the node that follows it.
    const std::uint32_t end = blocks_[b].first_node + blocks_[b].nodes;
    for (std::uint32_t i = blocks_[b].first_node; i < end;) {
      const Node& node = nodes_[i];
      double lo[3], hi[3];
      decode<kScaled>(node.box, scale, lo, hi);
      if (!may_meet(lo, hi) || hi[axis_] < axis_lo || lo[axis_] > axis_hi || exclude.contains(lo, hi)) {
        i = node.next;
        continue;
      }
      if (!node.leaf) {
        ++i;
        continue;
      }
      if (stop()) return true;
      // Each point's cell first: most points of a leaf that a huge ball grazes are
      // outside it, and the cell says so without reading the file. The coarse cell
      // (16 slices an axis) settles most; a point whose coarse cell meets the region
      // is tested again in its fine cell (256 slices), which is nearly the point
      // itself: a terrain's queries read 17 points each past the coarse cells, of
      // which 3 were in the ball.
      const CellGrid coarse(lo, hi, kSlices), fine(lo, hi, kSlices * kSlices);
      // For a ball, the coarse cells' test from tables: each axis' 16 slices' squared
      // gaps, summed in box_meets_ball's order (the same answer), and whether the
      // excluded slab holds each slice. A leaf a huge ball grazes is scanned whole
      // for the few points near the sphere: on `hills` 10^6, 760 entries a query.
      [[maybe_unused]] CoarseTable table;
      if constexpr (kIsBall<MayMeet>) table.fill(coarse, may_meet, exclude);
      for (std::uint32_t j = node.begin; j < node.end; ++j) {
        const std::uint32_t entry = entries_[base + j];
        const std::uint64_t label = base + (entry & kOffsetMask);
        if (label < first || label >= last) continue;
        double cell_lo[3], cell_hi[3];
        const std::uint32_t cell = entry >> kOffsetBits;
        if constexpr (kIsBall<MayMeet>) {
          if (!table.may_meet(cell)) continue;
        } else {
          coarse.cell(cell, cell_lo, cell_hi);
          if (!may_meet(cell_lo, cell_hi) || exclude.contains(cell_lo, cell_hi)) continue;
        }
        fine.cell(fine_cell(cell, fine_[base + j]), cell_lo, cell_hi);
        if (may_meet(cell_lo, cell_hi) && !exclude.contains(cell_lo, cell_hi)) visit(label);
      }
      i = node.next;
    }
    return false;
  }
  // Registers block b's regions with regions_ (track_regions). Each of its three
  // ranges (entries, cells, nodes) is under 2 MiB, so its first and last bytes name
  // every region it spans.
  void touch_block(std::uint64_t b) const {
    if (!regions_) return;
    const std::uint64_t base = b * block_points_, n = std::min<std::uint64_t>(block_points_, count_ - base);
    const Block& block = blocks_[b];
    regions_->touch(&block);
    regions_->touch(&entries_[base]);
    regions_->touch(&entries_[base + n - 1]);
    regions_->touch(&fine_[base]);
    regions_->touch(&fine_[base + n - 1]);
    if (block.nodes > 0) {
      regions_->touch(&nodes_[block.first_node]);
      regions_->touch(&nodes_[block.first_node + block.nodes - 1]);
    }
  }
  // A leaf's entry for a point: its label's offset in the block (kOffsetBits) and its
  // cell in the leaf's box above it: the box cut into 256 slices along each axis, the
  // high 4 bits of the point's slice numbers in the entry (its coarse cell, 16
  // slices an axis), the low 4 bits in fine_ (2 bytes a point more than the coarse
  // cells alone). Conservative: a cell, widened by a sixteenth of its slice and by
  // the rounding of the box's coordinates, contains the point (the slice numbers'
  // own rounding is below 2^-40 of a slice; 2^-1070 covers the absolute rounding of
  // subnormal bounds; a coarse cell holds its 16 fine ones exactly). A box too wide
  // for a finite slice (its decoded bounds infinite, or their difference past
  // DBL_MAX) has one cell on that axis: the whole box.
  static constexpr int kOffsetBits = 18, kSliceBits = 4;
  static constexpr std::uint32_t kOffsetMask = (1u << kOffsetBits) - 1, kSlices = 1u << kSliceBits;
  static_assert(kOffsetBits + 3 * kSliceBits <= 32 && kMaxBlockPoints <= (1u << kOffsetBits));
  // The fine cell (8 bits an axis) from the coarse one and the fine bits.
  static std::uint32_t fine_cell(std::uint32_t coarse, std::uint16_t fine) {
    std::uint32_t c = 0;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t high = coarse >> (kSliceBits * k) & (kSlices - 1),
                          low = fine >> (kSliceBits * k) & (kSlices - 1);
      c |= (high << kSliceBits | low) << (2 * kSliceBits * k);
    }
    return c;
  }
  struct CellGrid {
    // `slices` a power of two up to 256: cell numbers hold log2(slices) bits an axis.
    CellGrid(const double* box_lo, const double* box_hi, std::uint32_t slices)
        : bits(std::countr_zero(slices)), mask(slices - 1) {
      for (int k = 0; k < 3; ++k) {
        lo[k] = box_lo[k];
        step[k] = (box_hi[k] - lo[k]) / slices;
        if (std::isfinite(step[k])) {
          first_hi[k] = lo[k] + step[k];
          pad[k] = step[k] / 16 + (std::fabs(lo[k]) + std::fabs(box_hi[k])) * 0x1p-50 + 0x1p-1070;
        } else {
          step[k] = 0, first_hi[k] = box_hi[k], pad[k] = 0;
        }
      }
    }
    std::uint32_t cell_of(const double* p) const {
      std::uint32_t c = 0;
      for (int k = 0; k < 3; ++k) {
        const double slice = step[k] > 0 ? std::clamp((p[k] - lo[k]) / step[k], 0.0, double(mask)) : 0.0;
        c |= std::uint32_t(slice) << (bits * k);
      }
      return c;
    }
    void cell(std::uint32_t c, double* cell_lo, double* cell_hi) const {
      for (int k = 0; k < 3; ++k) {
        const double slice = double(c >> (bits * k) & mask);
        cell_lo[k] = lo[k] + slice * step[k] - pad[k];
        cell_hi[k] = first_hi[k] + slice * step[k] + pad[k];
      }
    }
    int bits;            // of a slice number
    std::uint32_t mask;  // slices - 1
    double lo[3], step[3], first_hi[3], pad[3];
  };
  template <class MayMeet>
  static constexpr bool kIsBall = std::is_same_v<std::remove_cvref_t<MayMeet>, BallRegion>;
  // A ball's test of one leaf's coarse cells (scan_block): by axis and slice, the
  // squared gap from the centre to the cell's extent, and whether the excluded slab
  // holds the slice (its axis only decides).
  struct CoarseTable {
    double gap2[3][kSlices];
    bool excluded[kSlices];
    double r2;
    int exclude_axis;
    // The slices' bounds as CellGrid::cell computes them.
    void fill(const CellGrid& grid, const BallRegion& ball, const ExcludedSlab& exclude) {
      for (int k = 0; k < 3; ++k) {
        const double lo = grid.lo[k], first_hi = grid.first_hi[k], step = grid.step[k], pad = grid.pad[k],
                     c = ball.center[k];
        for (std::uint32_t s = 0; s < kSlices; ++s)
          gap2[k][s] = axis_gap_square(lo + double(s) * step - pad, first_hi + double(s) * step + pad, c);
      }
      exclude_axis = exclude.axis;
      if (exclude_axis >= 0) {
        const int k = exclude_axis;
        for (std::uint32_t s = 0; s < kSlices; ++s)
          excluded[s] = grid.lo[k] + double(s) * grid.step[k] - grid.pad[k] >= exclude.lo &&
                        grid.first_hi[k] + double(s) * grid.step[k] + grid.pad[k] <= exclude.hi;
      }
      r2 = conservative_square(ball.radius);
    }
    bool may_meet(std::uint32_t cell) const {
      const std::uint32_t s0 = cell & (kSlices - 1), s1 = cell >> kSliceBits & (kSlices - 1),
                          s2 = cell >> 2 * kSliceBits & (kSlices - 1);
      double d2 = 0;
      d2 += gap2[0][s0];
      d2 += gap2[1][s1];
      d2 += gap2[2][s2];
      if (!may_reach(d2, r2)) return false;
      return exclude_axis < 0 || !excluded[cell >> kSliceBits * exclude_axis & (kSlices - 1)];
    }
  };
  // Builds block b (its entries, fine cells and nodes) over typed records; `entries`
  // and `fine` point at the block's first point's.
  template <class R>
  void build_block(const R* points, std::uint64_t b, std::uint64_t count, std::uint32_t* entries, std::uint16_t* fine,
                   std::vector<Node>& nodes, double& block_scale_out, bool release_file_pages);
  PointRecords points_;
  int axis_ = 0;
  std::uint32_t block_points_ = kMinBlockPoints;
  // What the queries read: the vectors below (build), or a shared file's mapping (attach).
  std::span<const std::uint32_t> entries_;  // per block: its points' entries, grouped by leaf
  std::span<const std::uint16_t> fine_;     // per entry: the low bits of its fine cell
  std::span<const Node> nodes_;
  std::span<const Block> blocks_;
  // The index this process built (all of it, or its part until write_part), each
  // with the labels of blocks [first_block_, ...) and the nodes numbered from 0.
  std::vector<std::uint32_t> own_entries_;
  std::vector<std::uint16_t> own_fine_;
  std::vector<Node> own_nodes_;
  std::vector<Block> own_blocks_;
  std::uint64_t count_ = 0;  // the points the whole index covers
  std::uint64_t first_block_ = 0;
  std::uint64_t resident_bytes_ = 0;  // an attached index's share (attach)
  MappedRegions* regions_ = nullptr;  // track_regions
};

}  // namespace tetstream::pipeline
