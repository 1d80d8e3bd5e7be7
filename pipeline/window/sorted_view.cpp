#include "pipeline/window/sorted_view.hpp"

#include <algorithm>
#include <array>
#include <cstddef>
#include <limits>
#include <stdexcept>
#include <utility>

namespace tetstream::pipeline {

void SortedView::sample_keys(bool release_file_pages) {
  key_samples.clear();
  key_samples.reserve(std::size_t(count / kKeyStride + 1));
  ReleaseBehind release(points, 0, release_file_pages);
  for (std::uint64_t label = 0; label < count; label += kKeyStride) {
    key_samples.push_back(key(label));
    release.reached(label);
  }
}

namespace {
// The labels in [0, count) between which the first one for which `after(key)` holds
// lies (keys are sorted, and `after` is monotone along them), from the samples alone:
// [lo, hi], at most one stride apart.
template <class After>
std::pair<std::uint64_t, std::uint64_t> sample_bracket(const SortedView& view, After after) {
  if (view.key_samples.empty()) return {0, view.count};
  // Sample s is label s * kKeyStride: the answer lies after the last sample that is
  // not `after`, and at or before the first that is.
  const auto s = std::size_t(
      std::partition_point(view.key_samples.begin(), view.key_samples.end(), [&](double k) { return !after(k); }) -
      view.key_samples.begin());
  return {s == 0 ? 0 : (s - 1) * SortedView::kKeyStride + 1, std::min(view.count, s * SortedView::kKeyStride)};
}

// The first label for which `after(key)` holds: the samples' bracket, then a binary
// search of the file within it.
template <class After>
std::uint64_t partition_point(const SortedView& view, After after) {
  auto [lo, hi] = sample_bracket(view, after);
  while (lo < hi) {
    const std::uint64_t mid = lo + (hi - lo) / 2;
    if (after(view.read_key(mid)))
      hi = mid;
    else
      lo = mid + 1;
  }
  return lo;
}
auto at_or_after(double x) {
  return [x](double k) { return k >= x; };
}
auto after(double x) {
  return [x](double k) { return k > x; };
}
}  // namespace

double SortedView::read_key(std::uint64_t label) const {
  if (!query_regions) return key(label);
  std::array<std::byte, 64> record;
  if (points.record_bytes() > record.size()) throw std::logic_error("SortedView: a record over 64 bytes");
  query_regions->read(points.record(label), record.data(), points.record_bytes());
  double xyz[3];
  points.decode(record.data(), xyz);
  return xyz[axis];
}

std::uint64_t SortedView::lower_bound(double x) const { return partition_point(*this, at_or_after(x)); }
std::uint64_t SortedView::upper_bound(double x) const { return partition_point(*this, after(x)); }
KeyRange SortedView::key_range(std::uint64_t first, std::uint64_t last) const {
  if (key_samples.empty()) return {key(first), key(last - 1)};
  // Sample i is label i * kKeyStride, and keys grow with labels: the sample at or
  // before `first`, and the one at or after `last` - 1 (none: no bound).
  const std::size_t after = std::size_t((last - 1 + kKeyStride - 1) / kKeyStride);
  return {key_samples[std::size_t(first / kKeyStride)],
          after < key_samples.size() ? key_samples[after] : std::numeric_limits<double>::infinity()};
}

std::uint64_t SortedView::lower_bound_below(double x) const { return sample_bracket(*this, at_or_after(x)).first; }
std::uint64_t SortedView::upper_bound_above(double x) const { return sample_bracket(*this, after(x)).second; }

}  // namespace tetstream::pipeline
