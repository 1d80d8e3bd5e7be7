#include "pipeline/write/label_order.hpp"

#include "core/error.hpp"
#include "io/output_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <exception>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tetstream::pipeline {

namespace {

// The position of cell (x, y) along the Hilbert curve of a side x side grid (side a
// power of two; x, y < side).
std::uint64_t hilbert_index(std::uint64_t side, std::uint64_t x, std::uint64_t y) {
  std::uint64_t d = 0;
  for (std::uint64_t s = side / 2; s > 0; s /= 2) {
    const std::uint64_t rx = (x & s) != 0, ry = (y & s) != 0;
    d += s * s * ((3 * rx) ^ ry);
    if (ry == 0) {
      if (rx == 1) x = s - 1 - x, y = s - 1 - y;
      std::swap(x, y);
    }
  }
  return d;
}

// Bits 0..9 of v spread to every third bit.
std::uint32_t spread3(std::uint32_t v) {
  v &= 0x3ffu;
  v = (v | v << 16) & 0x30000ffu;
  v = (v | v << 8) & 0x300f00fu;
  v = (v | v << 4) & 0x30c30c3u;
  v = (v | v << 2) & 0x9249249u;
  return v;
}

struct Item {
  std::uint64_t column;
  std::uint32_t cell, old;
};

// Orders items by column, ties by `old` (the items come in increasing `old`): a
// least-significant-digit radix sort, stable, over the bits the columns of a side x side
// grid use (2 log2(side); 8 to 24 for the bricks of uniform points), 11 a pass. A
// comparison sort of the brick was most of the label order's time.
void sort_by_column(std::vector<Item>& items, std::uint64_t side) {
  const int bits = 2 * std::countr_zero(side);
  constexpr int kDigit = 11;
  constexpr std::size_t kBuckets = std::size_t(1) << kDigit;
  std::vector<Item> other(items.size());
  std::vector<std::size_t> count(kBuckets);
  for (int shift = 0; shift < bits; shift += kDigit) {
    std::fill(count.begin(), count.end(), 0);
    for (const Item& it : items) ++count[std::size_t(it.column >> shift) & (kBuckets - 1)];
    std::size_t at = 0;
    for (std::size_t& c : count) {
      const std::size_t here = c;
      c = at;
      at += here;
    }
    for (const Item& it : items) other[count[std::size_t(it.column >> shift) & (kBuckets - 1)]++] = it;
    items.swap(other);
  }
}

}  // namespace

void brick_permutation(const double* xyz, std::size_t n, int axis, std::vector<std::uint32_t>& new_of_old) {
  new_of_old.resize(n);
  if (n == 0) return;
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;
  double lo[3], hi[3];
  for (int k = 0; k < 3; ++k) lo[k] = hi[k] = xyz[k];
  for (std::size_t i = 1; i < n; ++i)
    for (int k = 0; k < 3; ++k)
      lo[k] = std::min(lo[k], xyz[3 * i + std::size_t(k)]), hi[k] = std::max(hi[k], xyz[3 * i + std::size_t(k)]);
  const double thickness = hi[axis] - lo[axis];
  // Columns as wide as the brick is thick; no more than 2^20 an axis (a brick of one
  // plane of points: columns of ~a point each, which the curve then orders).
  const double across = std::max(hi[u] - lo[u], hi[v] - lo[v]);
  double cell = std::max(thickness, across * 0x1p-20);
  if (!(cell > 0)) cell = 1;
  const auto column_of = [&](double x, double origin) {
    const double c = std::floor((x - origin) / cell);
    return std::uint64_t(std::clamp(c, 0.0, double((1 << 21) - 1)));
  };
  const std::uint64_t side = std::bit_ceil(std::max(column_of(hi[u], lo[u]), column_of(hi[v], lo[v])) + 1);
  // The Morton code of a point in its column at the deepest level (10 bits an axis),
  // computed here while the points are read in order: the code of level k is its top
  // 3k bits (floor(f 2^k) = floor(f 2^10) >> (10 - k), exactly, as both products are
  // exact), so the sort inside the columns needs no coordinates (reading them there, in
  // the columns' order, missed the cache at every point).
  constexpr int kMaxLevels = 10;
  const double deepest = double(1 << kMaxLevels);
  const auto cell_of = [&](double f) { return std::uint32_t(std::clamp(std::floor(f * deepest), 0.0, deepest - 1)); };
  std::vector<Item> items(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double* p = xyz + 3 * i;
    const double fa = thickness > 0 ? (p[axis] - lo[axis]) / thickness : 0.0;
    const double fu = (p[u] - lo[u]) / cell - std::floor((p[u] - lo[u]) / cell);
    const double fv = (p[v] - lo[v]) / cell - std::floor((p[v] - lo[v]) / cell);
    items[i] = {hilbert_index(side, column_of(p[u], lo[u]), column_of(p[v], lo[v])),
                spread3(cell_of(fa)) | spread3(cell_of(fu)) << 1 | spread3(cell_of(fv)) << 2, std::uint32_t(i)};
  }
  sort_by_column(items, side);
  std::size_t columns = 1;
  for (std::size_t i = 1; i < n; ++i) columns += items[i].column != items[i - 1].column;
  const double per_column = double(n) / double(columns);
  int levels = 0;
  while (levels < kMaxLevels && 2.0 * std::pow(8.0, levels) < per_column) ++levels;
  if (levels > 0) {
    const int drop = 3 * (kMaxLevels - levels);
    for (std::size_t begin = 0; begin < n;) {
      std::size_t end = begin + 1;
      while (end < n && items[end].column == items[begin].column) ++end;
      std::sort(items.begin() + std::ptrdiff_t(begin), items.begin() + std::ptrdiff_t(end),
                [drop](const Item& a, const Item& b) {
                  const std::uint32_t ca = a.cell >> drop, cb = b.cell >> drop;
                  return ca != cb ? ca < cb : a.old < b.old;
                });
      begin = end;
    }
  }
  for (std::size_t k = 0; k < n; ++k) new_of_old[items[k].old] = std::uint32_t(k);
}

void write_label_order(const std::string& path, std::uint64_t point_count, int axis, const ReadPoints& read,
                       int threads) {
  const int fd = io::create_work_file(path);
  const std::uint64_t brick = brick_labels(point_count);
  const std::int64_t bricks = std::int64_t((point_count + brick - 1) / brick);
  std::exception_ptr failed;
#pragma omp parallel num_threads(std::max(1, threads))
  {
    std::vector<double> xyz;
    std::vector<std::uint32_t> new_of_old;
#pragma omp for schedule(dynamic, 1)
    for (std::int64_t b = 0; b < bricks; ++b) {
      try {
        const std::uint64_t first = std::uint64_t(b) * brick;
        const std::size_t n = std::size_t(std::min(brick, point_count - first));
        xyz.resize(3 * n);
        read(first, n, xyz.data());
        brick_permutation(xyz.data(), n, axis, new_of_old);
        if (!io::pwrite_exactly(fd, new_of_old.data(), n * sizeof(std::uint32_t), first * sizeof(std::uint32_t)))
          throw IoError(path + ": write failed: " + std::strerror(errno));
      } catch (...) {
#pragma omp critical(label_order_failure)
        if (!failed) failed = std::current_exception();
      }
    }
  }
  ::close(fd);
  if (failed) std::rethrow_exception(failed);
}

LabelOrder::LabelOrder(const std::string& path, std::uint64_t point_count)
    : path_(path), count_(point_count), brick_(brick_labels(point_count)), shift_(std::countr_zero(brick_)) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd_ < 0) throw IoError(path + ": cannot open: " + std::strerror(errno));
}

LabelOrder::~LabelOrder() {
  if (fd_ >= 0) ::close(fd_);
}

void LabelOrder::read_brick(std::uint64_t b, std::vector<std::uint32_t>& new_of_old) const {
  const std::uint64_t first = b << shift_;
  new_of_old.resize(std::size_t(std::min(brick_, count_ - first)));
  if (!io::pread_exactly(fd_, new_of_old.data(), new_of_old.size() * sizeof(std::uint32_t),
                         first * sizeof(std::uint32_t)))
    throw IoError(path_ + ": read failed: " + std::strerror(errno));
}

void LabelOrder::keep_from(std::uint64_t b) {
  const std::uint64_t first = b << shift_;
  if (first >= count_) throw std::logic_error("label order: brick " + std::to_string(b) + " past the points");
  if (!window_.empty() && first == window_first_) return;
  const std::uint64_t end = std::min(count_, first + kKeptBricks * brick_);
  // The bricks already in the window move to its front; the others are read.
  std::uint64_t have = first;
  if (!window_.empty() && first > window_first_ && first < window_first_ + window_.size()) {
    const std::size_t drop = std::size_t(first - window_first_);
    window_.erase(window_.begin(), window_.begin() + std::ptrdiff_t(drop));
    have = first + window_.size();
  } else {
    window_.clear();
  }
  window_first_ = first;
  for (; have < end; have += brick_) {
    read_brick(have >> shift_, scratch_);
    window_.insert(window_.end(), scratch_.begin(), scratch_.end());
  }
}

std::uint64_t LabelOrder::far(std::uint64_t l) const {
  std::uint32_t at = 0;
  if (!io::pread_exactly(fd_, &at, sizeof at, l * sizeof(std::uint32_t)))
    throw IoError(path_ + ": read failed: " + std::strerror(errno));
  return (l & ~(brick_ - 1)) + at;
}

}  // namespace tetstream::pipeline
