#include "pipeline/window/point_index.hpp"

#include "pipeline/files/temp_files.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>
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
void PointIndex::build_block(const R* points, std::uint64_t b, std::uint64_t count, std::uint32_t* entries,
                             std::uint16_t* fine, std::vector<Node>& nodes, double& block_scale_out,
                             bool release_file_pages) {
  const double inf = std::numeric_limits<double>::infinity();
  const std::uint64_t base = b * block_points_;
  const std::uint32_t n = std::uint32_t(std::min<std::uint64_t>(block_points_, count - base));
  std::uint32_t* o = entries;  // the offsets alone until a leaf adds the cells
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
    for (int k = 0; k < 3; ++k) node.box.lo[k] = float_below(lo[k], scale), node.box.hi[k] = float_above(hi[k], scale);
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
      double box_lo[3], box_hi[3];    // as the queries decode it, so that they find the same cells
      decode<true>(node.box, scale, box_lo, box_hi);
      const CellGrid grid(box_lo, box_hi, kSlices * kSlices);
      std::uint16_t* f = fine;
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
  build_part(points, count, axis, block_points, 0, blocks_for(count, block_points), release_file_pages);
  entries_ = own_entries_;
  fine_ = own_fine_;
  nodes_ = own_nodes_;
  blocks_ = own_blocks_;
}

void PointIndex::build_part(const PointRecords& points, std::uint64_t count, int axis, std::uint32_t block_points,
                            std::uint64_t first_block, std::uint64_t end_block, bool release_file_pages) {
  points_ = points;
  axis_ = axis;
  block_points_ = std::clamp<std::uint32_t>(block_points, 1, kMaxBlockPoints);
  count_ = count;
  first_block_ = first_block;
  end_block = std::min(end_block, blocks_for(count, block_points_));
  const std::uint64_t first = std::min(count, first_block * block_points_);
  const std::uint64_t end = std::min(count, end_block * block_points_);
  own_entries_.assign(end - first, 0);
  own_fine_.assign(end - first, 0);
  const std::uint64_t block_count = end_block > first_block ? end_block - first_block : 0;
  // The blocks are independent: each is built into its own node list (ids local to
  // the block) on all threads, then the lists are laid end to end. On one thread it
  // was 2.8% of a 10^7-point run's perf samples, with the other core idle. The
  // records are typed once, outside the loop (pipeline/point_record.hpp). A block at a
  // time: blocks hold 2^13 to 2^18 points, and a 10^7-point run has 39 of them, which
  // chunks of 8 dealt 24 to one thread and 15 to the other of two (the index stage's
  // time at 2 threads 0.70x its time at 1).
  std::vector<std::vector<Node>> block_nodes(block_count);
  std::vector<double> block_scales(block_count, 1.0);
  points.visit([&](const auto* records) {
#pragma omp parallel for schedule(dynamic, 1)
    for (std::int64_t i = 0; i < std::int64_t(block_count); ++i) {
      const std::uint64_t b = first_block + std::uint64_t(i), at = b * block_points_ - first;
      build_block(records, b, count, &own_entries_[at], &own_fine_[at], block_nodes[std::size_t(i)],
                  block_scales[std::size_t(i)], release_file_pages);
    }
  });
  std::size_t total = 0;
  for (const auto& nodes : block_nodes) total += nodes.size();
  // Node numbers are 31-bit (Node::next): more nodes (about 3 10^10 points) cannot be linked.
  if (total >= (std::size_t(1) << 31))
    throw std::length_error("the point index would have " + std::to_string(total) + " nodes, more than 2^31");
  own_nodes_.clear();
  own_nodes_.reserve(total);
  own_blocks_.clear();
  own_blocks_.reserve(block_count);
  for (std::size_t b = 0; b < block_count; ++b) {
    std::vector<Node>& nodes = block_nodes[b];
    const std::uint32_t first_node = std::uint32_t(own_nodes_.size());
    for (Node node : nodes) {
      node.next += first_node;
      own_nodes_.push_back(node);
    }
    own_blocks_.push_back(Block{first_node, std::uint32_t(nodes.size()), block_scales[b]});
    std::vector<Node>().swap(nodes);
  }
}

std::uint64_t PointIndex::node_count_for(std::uint64_t count, std::uint32_t block_points) {
  const std::uint64_t bp = std::clamp<std::uint32_t>(block_points, 1, kMaxBlockPoints);
  // build_block's recursion: one node for a range of n points, and when n exceeds
  // kLeafPoints, the nodes of its halves n / 2 and n - n / 2. The sizes at one depth
  // differ by at most one, so each depth has at most two, and a small table suffices.
  auto nodes = [](std::uint64_t n) {
    std::vector<std::pair<std::uint64_t, std::uint64_t>> level{{n, 1}}, next;  // (size, how many)
    std::uint64_t total = 0;
    while (!level.empty()) {
      next.clear();
      for (auto [size, times] : level) {
        total += times;
        if (size <= kLeafPoints) continue;
        for (std::uint64_t half : {size / 2, size - size / 2}) {
          auto it = std::find_if(next.begin(), next.end(), [&](const auto& e) { return e.first == half; });
          if (it == next.end())
            next.emplace_back(half, times);
          else
            it->second += times;
        }
      }
      level.swap(next);
    }
    return total;
  };
  if (count == 0) return 0;
  const std::uint64_t full = count / bp, rest = count % bp;
  return full * nodes(bp) + (rest > 0 ? nodes(rest) : 0);
}

PointIndex::FileLayout PointIndex::file_layout(std::uint64_t count, std::uint64_t node_count,
                                               std::uint64_t block_count) {
  FileLayout l;
  l.entries = 0;
  l.fine = count * sizeof(std::uint32_t);
  // Nodes and blocks at 8-byte boundaries: a block's scale is a double.
  l.nodes = (l.fine + count * sizeof(std::uint16_t) + 7) / 8 * 8;
  l.blocks = (l.nodes + node_count * sizeof(Node) + 7) / 8 * 8;
  l.bytes = l.blocks + block_count * sizeof(Block);
  return l;
}

void PointIndex::write_part(int fd, const std::string& path, std::uint64_t total_nodes, std::uint64_t first_node) {
  // Node numbers are 31-bit (Node::next), as in build_part: the parts together too.
  if (total_nodes >= (std::uint64_t(1) << 31))
    throw std::length_error("the point index would have " + std::to_string(total_nodes) + " nodes, more than 2^31");
  const FileLayout layout = file_layout(count_, total_nodes, blocks_for(count_, block_points_));
  const std::uint64_t first_label = std::min(count_, first_block_ * block_points_);
  for (Node& node : own_nodes_) node.next += std::uint32_t(first_node);
  for (Block& block : own_blocks_) block.first_node += std::uint32_t(first_node);
  auto put = [&](const void* data, std::size_t bytes, std::uint64_t offset) {
    if (!io::pwrite_exactly(fd, data, bytes, offset)) throw IoError(path + ": write failed: " + std::strerror(errno));
  };
  put(own_entries_.data(), own_entries_.size() * sizeof(std::uint32_t),
      layout.entries + first_label * sizeof(std::uint32_t));
  put(own_fine_.data(), own_fine_.size() * sizeof(std::uint16_t), layout.fine + first_label * sizeof(std::uint16_t));
  put(own_nodes_.data(), own_nodes_.size() * sizeof(Node), layout.nodes + first_node * sizeof(Node));
  put(own_blocks_.data(), own_blocks_.size() * sizeof(Block), layout.blocks + first_block_ * sizeof(Block));
  std::vector<std::uint32_t>().swap(own_entries_);
  std::vector<std::uint16_t>().swap(own_fine_);
  std::vector<Node>().swap(own_nodes_);
  std::vector<Block>().swap(own_blocks_);
}

void PointIndex::attach(const std::byte* mapping, const PointRecords& points, std::uint64_t count, int axis,
                        std::uint32_t block_points, std::uint64_t total_nodes, std::uint64_t resident_bytes) {
  points_ = points;
  axis_ = axis;
  block_points_ = std::clamp<std::uint32_t>(block_points, 1, kMaxBlockPoints);
  count_ = count;
  const std::uint64_t block_count = blocks_for(count, block_points_);
  const FileLayout layout = file_layout(count, total_nodes, block_count);
  entries_ = {reinterpret_cast<const std::uint32_t*>(mapping + layout.entries), std::size_t(count)};
  fine_ = {reinterpret_cast<const std::uint16_t*>(mapping + layout.fine), std::size_t(count)};
  nodes_ = {reinterpret_cast<const Node*>(mapping + layout.nodes), std::size_t(total_nodes)};
  blocks_ = {reinterpret_cast<const Block*>(mapping + layout.blocks), std::size_t(block_count)};
  resident_bytes_ = resident_bytes;
}

double PointIndex::leaf_spacing_quantile(double q, std::uint64_t first, std::uint64_t last) const {
  std::vector<double> spacing;
  if (blocks_.empty() || first >= last) return 0;
  const std::size_t b0 = std::size_t(std::min<std::uint64_t>(first / block_points_, blocks_.size() - 1));
  const std::size_t b1 = std::size_t(std::min<std::uint64_t>((last - 1) / block_points_, blocks_.size() - 1));
  for (std::size_t b = b0; b <= b1; ++b) {
    touch_block(b);
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

std::vector<std::uint64_t> PointIndex::compact_sample(std::uint64_t b, std::uint32_t max_points, bool last) const {
  std::vector<std::uint64_t> labels;
  if (b >= blocks_.size()) return labels;
  touch_block(b);
  const Block& block = blocks_[std::size_t(b)];
  if (block.nodes == 0) return labels;
  std::uint32_t i = block.first_node;
  // Preorder: node i's first child is i + 1, its second begins where the first's
  // subtree ends.
  // Alternating children, so that the sample lies inside the block's region rather
  // than in a corner of it (the data's own edge there).
  for (bool second = last; !nodes_[i].leaf && nodes_[i].end - nodes_[i].begin > max_points; second = !second)
    i = second ? nodes_[i + 1].next : i + 1;
  const std::uint64_t base = b * block_points_;
  for (std::uint32_t j = nodes_[i].begin; j < nodes_[i].end; ++j)
    labels.push_back(base + (entries_[std::size_t(base + j)] & kOffsetMask));
  return labels;
}

}  // namespace tetstream::pipeline
