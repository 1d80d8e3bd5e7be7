#include "pipeline/point_index.hpp"

#include "pipeline/temp_files.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tetstream::pipeline {

std::uint32_t PointIndex::block_points_for(std::uint64_t count, double axis_extent, double volume) {
  constexpr double kSpacings = 8;
  const double n = double(count);
  // Points per unit of axis length, times the mean spacing cbrt(volume / n).
  const double slab = axis_extent > 0 && volume > 0 ? n / axis_extent * std::cbrt(volume / n) : n;
  return std::uint32_t(std::clamp(kSpacings * slab, double(kMinBlockPoints), double(kMaxBlockPoints)));
}

void PointIndex::build(const SortedPoint* points, std::uint64_t count, int axis, std::uint32_t block_points,
                       bool release_file_pages) {
  points_ = points;
  axis_ = axis;
  block_points_ = std::clamp<std::uint32_t>(block_points, 1, kMaxBlockPoints);
  offsets_.assign(count, 0);
  nodes_.clear();
  blocks_.clear();
  const double inf = std::numeric_limits<double>::infinity();
  for (std::uint64_t base = 0; base < count; base += block_points_) {
    const std::uint32_t n = std::uint32_t(std::min<std::uint64_t>(block_points_, count - base));
    std::uint16_t* o = &offsets_[base];
    for (std::uint32_t i = 0; i < n; ++i) o[i] = std::uint16_t(i);
    Block block{std::uint32_t(nodes_.size()), 0};
    // Recursive median splits, written in preorder. `next` of a node is set when its
    // subtree is complete: the build recurses on the left half, then the right.
    auto build_node = [&](auto&& self, std::uint32_t begin, std::uint32_t end) -> void {
      Box box{{inf, inf, inf}, {-inf, -inf, -inf}};
      for (std::uint32_t j = begin; j < end; ++j)
        for (int k = 0; k < 3; ++k) {
          const double x = points[base + o[j]].xyz[k];
          box.lo[k] = std::min(box.lo[k], x);
          box.hi[k] = std::max(box.hi[k], x);
        }
      const std::uint32_t id = std::uint32_t(nodes_.size());
      const bool leaf = end - begin <= kLeafPoints;
      nodes_.push_back(Node{box, begin, end, 0, leaf ? 1u : 0u});
      if (!leaf) {
        int widest = 0;
        for (int k = 1; k < 3; ++k)
          if (box.hi[k] - box.lo[k] > box.hi[widest] - box.lo[widest]) widest = k;
        const std::uint32_t mid = begin + (end - begin) / 2;
        std::nth_element(o + begin, o + mid, o + end, [&](std::uint16_t a, std::uint16_t b) {
          return points[base + a].xyz[widest] < points[base + b].xyz[widest];
        });
        self(self, begin, mid);
        self(self, mid, end);
      } else {
        std::sort(o + begin, o + end);  // a leaf reads its points in file order
      }
      nodes_[id].next = std::uint32_t(nodes_.size());
    };
    build_node(build_node, 0, n);
    block.nodes = std::uint32_t(nodes_.size()) - block.first_node;
    blocks_.push_back(block);
    if (release_file_pages) release_mapped_pages(points + base, n * sizeof(SortedPoint));
  }
}

}  // namespace tetstream::pipeline
