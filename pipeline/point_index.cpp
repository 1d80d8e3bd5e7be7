#include "pipeline/point_index.hpp"

#include "pipeline/temp_files.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tetstream::pipeline {

void PointIndex::build(const SortedPoint* points, std::uint64_t count, int axis, bool release_file_pages) {
  offsets_.assign(count, 0);
  cells_.clear();
  blocks_.clear();
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<std::uint32_t> cell_of(kBlockPoints);
  std::vector<std::uint32_t> fill(kGrid * kGrid + 1);
  for (std::uint64_t base = 0; base < count; base += kBlockPoints) {
    const std::uint32_t n = std::uint32_t(std::min<std::uint64_t>(kBlockPoints, count - base));
    Block block{{{inf, inf, inf}, {-inf, -inf, -inf}}, std::uint32_t(cells_.size()), 0};
    for (std::uint32_t i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        block.box.lo[k] = std::min(block.box.lo[k], points[base + i].xyz[k]);
        block.box.hi[k] = std::max(block.box.hi[k], points[base + i].xyz[k]);
      }
    // Grid over the block's own extent in the two other axes; counting sort by cell.
    const double su = block.box.hi[u] > block.box.lo[u] ? kGrid / (block.box.hi[u] - block.box.lo[u]) : 0;
    const double sv = block.box.hi[v] > block.box.lo[v] ? kGrid / (block.box.hi[v] - block.box.lo[v]) : 0;
    std::fill(fill.begin(), fill.end(), 0);
    for (std::uint32_t i = 0; i < n; ++i) {
      const double* p = points[base + i].xyz;
      const std::uint32_t cu = std::min<std::uint32_t>(kGrid - 1, std::uint32_t((p[u] - block.box.lo[u]) * su));
      const std::uint32_t cv = std::min<std::uint32_t>(kGrid - 1, std::uint32_t((p[v] - block.box.lo[v]) * sv));
      cell_of[i] = cu * kGrid + cv;
      ++fill[cell_of[i] + 1];
    }
    for (std::uint32_t c = 0; c < kGrid * kGrid; ++c) fill[c + 1] += fill[c];
    std::vector<std::uint32_t> start(fill.begin(), fill.end());
    for (std::uint32_t i = 0; i < n; ++i) offsets_[base + fill[cell_of[i]]++] = std::uint16_t(i);
    for (std::uint32_t c = 0; c < kGrid * kGrid; ++c) {
      if (start[c] == start[c + 1]) continue;
      Cell cell{{{inf, inf, inf}, {-inf, -inf, -inf}}, start[c], start[c + 1]};
      for (std::uint32_t j = cell.begin; j < cell.end; ++j)
        for (int k = 0; k < 3; ++k) {
          const double x = points[base + offsets_[base + j]].xyz[k];
          cell.box.lo[k] = std::min(cell.box.lo[k], x);
          cell.box.hi[k] = std::max(cell.box.hi[k], x);
        }
      cells_.push_back(cell);
      ++block.cells;
    }
    blocks_.push_back(block);
    if (release_file_pages) release_mapped_pages(points + base, n * sizeof(SortedPoint));
  }
}

}  // namespace tetstream::pipeline
