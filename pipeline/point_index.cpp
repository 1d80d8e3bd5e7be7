#include "pipeline/point_index.hpp"

#include "pipeline/temp_files.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace tetstream::pipeline {

namespace {
// The largest float f with f * scale <= x, and the smallest with f * scale >= x, as
// the query decodes them (x finite, x / scale within float range: block_scale). The
// division by a power of two is exact unless it underflows; the decode's product may
// round (to a subnormal) too, so the answer is checked against the decode itself,
// which is monotonic: a step or two of nextafter at most.
float float_below(double x, double scale) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  float f = float(scale == 1.0 ? x : x / scale);
  while (double(f) * scale > x) f = std::nextafter(f, -kInf);
  return f;
}
float float_above(double x, double scale) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  float f = float(scale == 1.0 ? x : x / scale);
  while (double(f) * scale < x) f = std::nextafter(f, kInf);
  return f;
}
}  // namespace

double PointIndex::block_scale(double max_magnitude) {
  if (max_magnitude == 0 || (max_magnitude >= 0x1p-100 && max_magnitude <= 0x1p100)) return 1.0;
  // max_magnitude / 2^e in [2^60, 2^61); e within the normal exponents, so that the
  // scale itself is a normal double (subnormal blocks: the largest becomes >= 2^8).
  const int e = std::clamp(std::ilogb(max_magnitude) - 60, -1022, 1023);
  return std::ldexp(1.0, e);
}

std::uint32_t PointIndex::block_points_for(std::uint64_t count, double axis_extent, double volume) {
  constexpr double kSpacings = 8;
  const double n = double(count);
  // Points per unit of axis length, times the mean spacing cbrt(volume / n).
  const double slab = axis_extent > 0 && volume > 0 ? n / axis_extent * std::cbrt(volume / n) : n;
  return std::uint32_t(std::clamp(kSpacings * slab, double(kMinBlockPoints), double(kMaxBlockPoints)));
}

template <class R>
void PointIndex::build_block(const R* points, std::uint64_t b, std::uint64_t count, std::vector<Node>& nodes,
                             double& block_scale_out, bool release_file_pages) {
  const double inf = std::numeric_limits<double>::infinity();
  const std::uint64_t base = b * block_points_;
  const std::uint32_t n = std::uint32_t(std::min<std::uint64_t>(block_points_, count - base));
  std::uint32_t* o = &entries_[base];  // the offsets alone until a leaf adds the cells
  for (std::uint32_t i = 0; i < n; ++i) o[i] = i;
  double max_magnitude = 0;
  for (std::uint32_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) max_magnitude = std::max(max_magnitude, std::fabs(points[base + i].coord(k)));
  const double scale = block_scale(max_magnitude);
  block_scale_out = scale;
  // Recursive median splits, written in preorder. `next` of a node is set when its
  // subtree is complete: the build recurses on the left half, then the right.
  auto build_node = [&](auto&& self, std::uint32_t begin, std::uint32_t end) -> void {
    double lo[3] = {inf, inf, inf}, hi[3] = {-inf, -inf, -inf};  // the points' box
    for (std::uint32_t j = begin; j < end; ++j)
      for (int k = 0; k < 3; ++k) {
        const double x = points[base + o[j]].coord(k);
        lo[k] = std::min(lo[k], x);
        hi[k] = std::max(hi[k], x);
      }
    const std::uint32_t id = std::uint32_t(nodes.size());
    const bool leaf = end - begin <= kLeafPoints;
    Node node{};
    for (int k = 0; k < 3; ++k)
      node.box.lo[k] = float_below(lo[k], scale), node.box.hi[k] = float_above(hi[k], scale);
    node.begin = begin, node.end = end, node.leaf = leaf ? 1u : 0u;
    nodes.push_back(node);
    if (!leaf) {
      int widest = 0;
      for (int k = 1; k < 3; ++k)
        if (hi[k] - lo[k] > hi[widest] - lo[widest]) widest = k;
      const std::uint32_t mid = begin + (end - begin) / 2;
      std::nth_element(o + begin, o + mid, o + end, [&](std::uint32_t a, std::uint32_t c) {
        return points[base + a].coord(widest) < points[base + c].coord(widest);
      });
      self(self, begin, mid);
      self(self, mid, end);
    } else {
      std::sort(o + begin, o + end);  // a leaf reads its points in file order
      double box_lo[3], box_hi[3];  // as the queries decode it, so that they find the same cells
      decode<true>(node.box, scale, box_lo, box_hi);
      const CellGrid grid(box_lo, box_hi, kSlices * kSlices);
      std::uint16_t* f = &fine_[base];
      for (std::uint32_t j = begin; j < end; ++j) {
        double p[3];
        points[base + o[j]].xyz(p);
        const std::uint32_t cell = grid.cell_of(p);  // 8 bits an axis
        std::uint32_t high = 0, low = 0;
        for (int k = 0; k < 3; ++k) {
          high |= (cell >> (2 * kSliceBits * k + kSliceBits) & (kSlices - 1)) << (kSliceBits * k);
          low |= (cell >> (2 * kSliceBits * k) & (kSlices - 1)) << (kSliceBits * k);
        }
        o[j] |= high << kOffsetBits;
        f[j] = std::uint16_t(low);
      }
    }
    nodes[id].next = std::uint32_t(nodes.size());
  };
  build_node(build_node, 0, n);
  if (release_file_pages) release_mapped_pages(points + base, n * sizeof(R));
}

void PointIndex::build(const PointRecords& points, std::uint64_t count, int axis, std::uint32_t block_points,
                       bool release_file_pages) {
  points_ = points;
  axis_ = axis;
  block_points_ = std::clamp<std::uint32_t>(block_points, 1, kMaxBlockPoints);
  entries_.assign(count, 0);
  fine_.assign(count, 0);
  const std::uint64_t block_count = (count + block_points_ - 1) / block_points_;
  // The blocks are independent: each is built into its own node list (ids local to
  // the block) on all threads, then the lists are laid end to end. On one thread it
  // was 2.8% of a 10^7-point run's perf samples, with the other core idle. The
  // records are typed once, outside the loop (pipeline/point_record.hpp).
  std::vector<std::vector<Node>> block_nodes(block_count);
  std::vector<double> block_scales(block_count, 1.0);
  points.visit([&](const auto* records) {
#pragma omp parallel for schedule(dynamic, 8)
    for (std::int64_t b = 0; b < std::int64_t(block_count); ++b)
      build_block(records, std::uint64_t(b), count, block_nodes[std::size_t(b)], block_scales[std::size_t(b)],
                  release_file_pages);
  });
  std::size_t total = 0;
  for (const auto& nodes : block_nodes) total += nodes.size();
  nodes_.clear();
  nodes_.reserve(total);
  blocks_.clear();
  blocks_.reserve(block_count);
  for (std::size_t b = 0; b < block_count; ++b) {
    std::vector<Node>& nodes = block_nodes[b];
    const std::uint32_t first = std::uint32_t(nodes_.size());
    for (Node node : nodes) {
      node.next += first;
      nodes_.push_back(node);
    }
    blocks_.push_back(Block{first, std::uint32_t(nodes.size()), block_scales[b]});
    std::vector<Node>().swap(nodes);
  }
}

double PointIndex::leaf_spacing_quantile(double q, std::uint64_t first, std::uint64_t last) const {
  std::vector<double> spacing;
  if (blocks_.empty() || first >= last) return 0;
  const std::size_t b0 = std::size_t(std::min<std::uint64_t>(first / block_points_, blocks_.size() - 1));
  const std::size_t b1 = std::size_t(std::min<std::uint64_t>((last - 1) / block_points_, blocks_.size() - 1));
  for (std::size_t b = b0; b <= b1; ++b) {
    const Block& block = blocks_[b];
    for (std::uint32_t i = block.first_node; i < block.first_node + block.nodes; ++i) {
      const Node& node = nodes_[i];
      if (!node.leaf || node.end - node.begin < 8) continue;
      // In the block's own units (the stored floats), where the volume neither
      // overflows nor underflows; the spacing is then scaled back.
      double volume = 1;
      for (int k = 0; k < 3; ++k) volume *= double(node.box.hi[k]) - double(node.box.lo[k]);
      if (volume > 0) spacing.push_back(std::cbrt(volume / double(node.end - node.begin)) * block.scale);
    }
  }
  if (spacing.empty()) return 0;
  const auto nth = spacing.begin() + std::ptrdiff_t(std::clamp(q, 0.0, 1.0) * double(spacing.size() - 1));
  std::nth_element(spacing.begin(), nth, spacing.end());
  return *nth;
}

}  // namespace tetstream::pipeline
