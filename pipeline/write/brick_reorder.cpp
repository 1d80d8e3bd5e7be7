#include "pipeline/write/brick_reorder.hpp"

#include <stdexcept>

#include <algorithm>
#include <bit>
#include <string>

namespace tetstream::pipeline {

BrickReorder::BrickReorder(FrameCutter& cutter, LabelOrder& order)
    : cutter_(cutter), order_(order), wide_(order.point_count() > (std::uint64_t(1) << 32)) {}

std::uint64_t BrickReorder::bytes_for(std::uint64_t brick, bool wide) {
  const double tets = 7.5 * double(brick);
  return std::uint64_t(tets * double(4 * (wide ? 8 : 4) + 4)) + (brick + 1) * 4;
}

std::uint64_t BrickReorder::job_bytes(std::uint64_t points) {
  const std::uint64_t brick = std::min(brick_labels(points), points);
  return bytes_for(brick, points > (std::uint64_t(1) << 32)) + LabelOrder::kKeptBricks * brick * sizeof(std::uint32_t);
}

void BrickReorder::add(const ZoneTets& part, std::size_t begin, std::size_t end) {
  const std::uint64_t shift = std::uint64_t(std::countr_zero(order_.brick()));
  for (std::size_t i = begin; i < end; ++i) {
    const std::uint64_t b = part.min_label(i) >> shift;
    if (b != brick_) {
      emit();
      brick_ = b;
      // The coming tets' labels: in this brick and the next two (a brick is two slabs
      // of points thick; a tet reaches about 2.5 slabs). The last kept is looked up first.
      const std::uint64_t bricks = (order_.point_count() + order_.brick() - 1) / order_.brick();
      for (std::uint64_t k = std::min(bricks - 1, b + 2); k > b; --k) order_.keep(k);
      order_.keep(b);
    }
    for (int k = 0; k < 4; ++k) push(order_(part.label(i, k)));
  }
}

void BrickReorder::done_below(std::uint64_t label) {
  if (brick_ == ~std::uint64_t(0)) return;
  const std::uint64_t end = std::min(order_.point_count(), (brick_ + 1) * order_.brick());
  if (label >= end) {
    emit();
    brick_ = ~std::uint64_t(0);
  }
}

void BrickReorder::emit() {
  const std::size_t n = tets();
  if (n == 0) return;
  const std::uint64_t base = brick_ * order_.brick();
  const std::size_t span = std::size_t(std::min(order_.brick(), order_.point_count() - base));
  // Counting sort by smallest label: count_[k + 1] counts the tets of smallest label base + k.
  count_.assign(span + 1, 0);
  const auto min_of = [&](std::size_t t) {
    return std::min(std::min(label(4 * t), label(4 * t + 1)), std::min(label(4 * t + 2), label(4 * t + 3)));
  };
  for (std::size_t t = 0; t < n; ++t) {
    const std::uint64_t m = min_of(t);
    if (m < base || m - base >= span)
      throw std::logic_error("brick reorder: a tet of smallest label " + std::to_string(m) + " outside brick [" +
                             std::to_string(base) + ", " + std::to_string(base + span) + ")");
    ++count_[std::size_t(m - base) + 1];
  }
  for (std::size_t k = 1; k <= span; ++k) count_[k] += count_[k - 1];
  order_of_.resize(n);
  for (std::size_t t = 0; t < n; ++t) order_of_[count_[std::size_t(min_of(t) - base)]++] = std::uint32_t(t);
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t t = order_of_[k];
    const std::uint64_t q[4] = {label(4 * t), label(4 * t + 1), label(4 * t + 2), label(4 * t + 3)};
    cutter_.add(q);
  }
  held32_.clear();
  held64_.clear();
}

std::vector<std::uint64_t> BrickReorder::held() const {
  std::vector<std::uint64_t> out(4 * tets());
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = label(i);
  return out;
}

void BrickReorder::restore(const std::vector<std::uint64_t>& held) {
  held32_.clear();
  held64_.clear();
  brick_ = ~std::uint64_t(0);
  if (held.empty()) return;
  brick_ = tet_min_label(held.data()) / order_.brick();
  for (std::uint64_t l : held) push(l);
}

}  // namespace tetstream::pipeline
