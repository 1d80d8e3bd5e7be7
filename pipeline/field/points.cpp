#include "pipeline/field/points.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <limits>
#include <vector>

namespace tetstream::pipeline {

WindowPoints::WindowPoints(const io::TetReader& reader, std::uint64_t ring_labels)
    : reader_(reader), xyz_(ring_labels), ids_(ring_labels) {}

void WindowPoints::load(std::uint64_t first, std::uint64_t n) {
  // Both rings have the same size, so a label's slots are at the same position.
  std::vector<std::uint64_t> ids;
  xyz_.for_runs(first, n, [&](std::uint64_t at, std::array<double, 3>* slots, std::size_t run) {
    ids.resize(run);
    reader_.read_points(at, run, slots->data(), ids.data());
    reader_.release_point_pages(at, run);
    for (std::size_t i = 0; i < run; ++i) {
      ids_[at + i] = ids[i];
      if (axis_ >= 0) {
        const double c = slots[i][std::size_t(axis_)];
        const std::uint64_t k = (at + i) / brick_;
        const double below = k == 0 ? -std::numeric_limits<double>::infinity() : brick_top_[std::size_t(k - 1)];
        if (c < below)
          throw InputError(reader_.path() + ": point " + std::to_string(at + i) + " is not sorted along axis " +
                           std::to_string(axis_) + " (the grid needs the order `run` writes)");
        if (brick_top_.size() == k) brick_top_.push_back(below);
        brick_top_.back() = std::max(brick_top_.back(), c);
      }
    }
  });
  next_ = first + n;
}

double WindowPoints::axis_floor(std::uint64_t label) const {
  // Bricks before the label's, as far as loaded: a partly loaded brick's top is still
  // a floor for the bricks after it.
  const std::uint64_t before = std::min<std::uint64_t>(label / brick_, brick_top_.size());
  return before == 0 ? -std::numeric_limits<double>::infinity() : brick_top_[std::size_t(before - 1)];
}

void WindowPoints::fetch_far(const DecodedBatch& batch) {
  for (std::size_t f = 0; f < batch.frames(); ++f)
    for (const std::uint64_t l : batch.frame(f)) {
      if (l < next_ || far_.count(l)) continue;
      Far p;
      reader_.read_points(l, 1, p.xyz.data(), &p.original);
      far_.emplace(l, p);
    }
}

}  // namespace tetstream::pipeline
