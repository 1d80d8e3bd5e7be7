#include "pipeline/write/brick_reorder.hpp"

#include <stdexcept>

#include <algorithm>
#include <bit>
#include <iterator>
#include <string>

namespace tetstream::pipeline {

BrickReorder::BrickReorder(FrameCutter& cutter, LabelOrder& order)
    : cutter_(cutter), order_(order), wide_(order.point_count() > (std::uint64_t(1) << 32)) {}

std::uint64_t BrickReorder::bytes_for(std::uint64_t brick, bool wide) {
  // Per tet: its labels and its smallest label's offset, twice (the radix sort's
  // other buffer).
  const double tets = 7.5 * double(brick);
  return std::uint64_t(tets * double(2 * (wide ? sizeof(Held<std::uint64_t>) : sizeof(Held<std::uint32_t>)))) +
         (std::uint64_t(1) << 11) * sizeof(std::size_t);
}

std::uint64_t BrickReorder::job_bytes(std::uint64_t points) {
  const std::uint64_t brick = std::min(brick_labels(points), points);
  return bytes_for(brick, points > (std::uint64_t(1) << 32)) + LabelOrder::kKeptBricks * brick * sizeof(std::uint32_t);
}

void BrickReorder::add(const ZoneTets& part, std::size_t begin, std::size_t end) {
  const std::uint64_t shift = std::uint64_t(std::countr_zero(order_.brick()));
  for (std::size_t i = begin; i < end; ++i) {
    const std::uint64_t b = part.min_label(i) >> shift;
    if (b != brick_) start_brick(b);
    std::uint64_t q[4], m = ~std::uint64_t(0);
    for (int k = 0; k < 4; ++k) q[k] = order_(part.label(i, k)), m = std::min(m, q[k]);
    // A brick maps its labels onto themselves: the smallest new label is in it too.
    if (m - base_ >= span_)
      throw std::logic_error("brick reorder: a tet of smallest label " + std::to_string(m) + " outside brick [" +
                             std::to_string(base_) + ", " + std::to_string(base_ + span_) + ")");
    push(q, m);
  }
}

void BrickReorder::start_brick(std::uint64_t b) {
  emit();
  brick_ = b;
  base_ = b * order_.brick();
  span_ = std::min(order_.brick(), order_.point_count() - base_);
  order_.keep_from(b);
}

void BrickReorder::done_below(std::uint64_t label) {
  if (brick_ == ~std::uint64_t(0)) return;
  if (label >= base_ + span_) {
    emit();
    brick_ = ~std::uint64_t(0);
  }
}

void BrickReorder::push(const std::uint64_t* q, std::uint64_t m) {
  if (wide_)
    held64_.push_back({{q[0], q[1], q[2], q[3]}, std::uint32_t(m - base_)});
  else
    held32_.push_back({{std::uint32_t(q[0]), std::uint32_t(q[1]), std::uint32_t(q[2]), std::uint32_t(q[3])},
                       std::uint32_t(m - base_)});
}

void BrickReorder::emit() {
  if (wide_)
    emit(held64_, scratch64_);
  else
    emit(held32_, scratch32_);
}

template <class L>
void BrickReorder::emit(std::vector<Held<L>>& held, std::vector<Held<L>>& scratch) {
  if (held.empty()) return;
  // By smallest label, ties in the order they came (stable): digits of at most 11 bits
  // over the bits of the brick's offsets.
  const int bits = std::max(1, int(std::bit_width(span_ - 1)));
  const int passes = (bits + 10) / 11, digit = (bits + passes - 1) / passes;
  const std::size_t buckets = std::size_t(1) << digit;
  scratch.resize(held.size());
  for (int shift = 0; shift < bits; shift += digit) {
    count_.assign(buckets, 0);
    for (const Held<L>& h : held) ++count_[(h.min >> shift) & (buckets - 1)];
    std::size_t at = 0;
    for (std::size_t& c : count_) {
      const std::size_t here = c;
      c = at;
      at += here;
    }
    for (const Held<L>& h : held) scratch[count_[(h.min >> shift) & (buckets - 1)]++] = h;
    held.swap(scratch);
  }
  for (const Held<L>& h : held) {
    const std::uint64_t q[4] = {h.label[0], h.label[1], h.label[2], h.label[3]};
    cutter_.add(q, base_ + h.min);
  }
  held.clear();
}

std::vector<std::uint64_t> BrickReorder::held() const {
  std::vector<std::uint64_t> out;
  out.reserve(4 * tets());
  const auto flatten = [&out](const auto& held) {
    for (const auto& h : held) out.insert(out.end(), std::begin(h.label), std::end(h.label));
  };
  if (wide_)
    flatten(held64_);
  else
    flatten(held32_);
  return out;
}

void BrickReorder::restore(const std::vector<std::uint64_t>& held) {
  held32_.clear();
  held64_.clear();
  brick_ = ~std::uint64_t(0);
  if (held.empty()) return;
  start_brick(tet_min_label(held.data()) / order_.brick());
  for (std::size_t i = 0; i < held.size(); i += 4) push(&held[i], tet_min_label(&held[i]));
}

}  // namespace tetstream::pipeline
