#include "pipeline/point_index.hpp"

#include "pipeline/temp_files.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tetstream::pipeline {

void PointIndex::build(const SortedPoint* points, std::uint64_t count, int axis, bool release_file_pages) {
  (void)axis;
  offsets_.assign(count, 0);
  cells_.clear();
  blocks_.clear();
  const double inf = std::numeric_limits<double>::infinity();
  auto box_of = [&](std::uint64_t base, std::uint32_t begin, std::uint32_t end) {
    Box b{{inf, inf, inf}, {-inf, -inf, -inf}};
    for (std::uint32_t j = begin; j < end; ++j)
      for (int k = 0; k < 3; ++k) {
        const double x = points[base + offsets_[base + j]].xyz[k];
        b.lo[k] = std::min(b.lo[k], x);
        b.hi[k] = std::max(b.hi[k], x);
      }
    return b;
  };
  std::vector<std::pair<std::uint32_t, std::uint32_t>> stack;
  for (std::uint64_t base = 0; base < count; base += kBlockPoints) {
    const std::uint32_t n = std::uint32_t(std::min<std::uint64_t>(kBlockPoints, count - base));
    for (std::uint32_t i = 0; i < n; ++i) offsets_[base + i] = std::uint16_t(i);
    Block block{box_of(base, 0, n), std::uint32_t(cells_.size()), 0};
    // Cells: the leaves of a median split on the widest side, down to kCellPoints
    // points. Leaves hold few points however the block's points are spread (a dense
    // filament or a thin shell falls into many small cells, not one crowded one),
    // and their boxes are tight.
    stack.assign(1, {0u, n});
    while (!stack.empty()) {
      const auto [begin, end] = stack.back();
      stack.pop_back();
      const Box box = box_of(base, begin, end);
      if (end - begin <= kCellPoints) {
        cells_.push_back(Cell{box, begin, end});
        ++block.cells;
        continue;
      }
      int widest = 0;
      for (int k = 1; k < 3; ++k)
        if (box.hi[k] - box.lo[k] > box.hi[widest] - box.lo[widest]) widest = k;
      const std::uint32_t mid = begin + (end - begin) / 2;
      std::uint16_t* o = &offsets_[base];
      std::nth_element(o + begin, o + mid, o + end, [&](std::uint16_t a, std::uint16_t b) {
        return points[base + a].xyz[widest] < points[base + b].xyz[widest];
      });
      // Right half first on the stack, so the cells come out left to right.
      stack.push_back({mid, end});
      stack.push_back({begin, mid});
    }
    blocks_.push_back(block);
    if (release_file_pages) release_mapped_pages(points + base, n * sizeof(SortedPoint));
  }
}

}  // namespace tetstream::pipeline
