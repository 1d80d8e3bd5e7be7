#include "pipeline/field/points.hpp"

#include "core/error.hpp"

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
        if (at + i > 0 && c < last_)
          throw InputError(reader_.path() + ": point " + std::to_string(at + i) + " is not sorted along axis " +
                           std::to_string(axis_) + " (the grid needs the order `run` writes)");
        last_ = c;
      }
    }
  });
  next_ = first + n;
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
