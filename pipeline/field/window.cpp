#include "pipeline/field/window.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <bit>
#include <exception>
#include <mutex>

namespace tetstream::pipeline {

BatchPlan plan_batches(const std::vector<io::FrameEntry>& frames, std::uint64_t point_count, std::uint64_t max_tets,
                       std::uint64_t max_labels, const std::string& path) {
  BatchPlan plan;
  const std::size_t nf = frames.size();
  for (std::size_t k = 0; k < nf; ++k) {
    const io::FrameEntry& f = frames[k];
    if (f.max_label >= point_count || f.base_label > f.max_label)
      throw InputError::at_byte(path, f.offset,
                                "frame " + std::to_string(k) + ": label range [" + std::to_string(f.base_label) + ", " +
                                    std::to_string(f.max_label) + "] outside the " + std::to_string(point_count) +
                                    " points");
    if (k > 0 && f.base_label < frames[k - 1].base_label)
      throw InputError::at_byte(path, f.offset,
                                "frame " + std::to_string(k) + ": base label " + std::to_string(f.base_label) +
                                    " below the previous frame's " + std::to_string(frames[k - 1].base_label) +
                                    " (field needs frames ordered by minimum label, as `run` writes them)");
  }
  // Labels below the first frame's base are in no tet; they join the first batch.
  // A batch ends before its retired range [lo, retire_below) would outgrow the ring,
  // so every retired label is dense; labels the tets reach beyond the ring are far.
  std::uint64_t retired = 0;  // labels below it were retired by earlier batches
  std::size_t k = 0;
  while (k < nf) {
    FrameBatch b;
    b.first_frame = k;
    b.lo = retired;
    do {
      const io::FrameEntry& f = frames[k];
      const std::uint64_t next_retire = k + 1 < nf ? frames[k + 1].base_label : point_count;
      const std::uint64_t span = next_retire - b.lo;
      const bool first = k == b.first_frame;
      if (!first && (b.tets + f.tet_count > max_tets || span > max_labels)) break;
      if (first && span > max_labels)
        throw UsageError(path + ": frame " + std::to_string(k) + " needs a window of " + std::to_string(span) +
                         " labels, more than the " + std::to_string(max_labels) +
                         " the memory budget holds: raise --memory");
      b.tets += f.tet_count;
      b.retire_below = next_retire;
      b.hi = std::max(f.max_label, next_retire - 1);
      ++k;
    } while (k < nf);
    b.end_frame = k;
    retired = b.retire_below;
    plan.window_labels = std::max(plan.window_labels, b.retire_below - b.lo);
    plan.largest_batch_tets = std::max(plan.largest_batch_tets, b.tets);
    plan.batches.push_back(b);
  }
  if (plan.batches.empty()) plan.batches.push_back({0, 0, 0, point_count - 1, point_count, 0});
  if (plan.batches.back().retire_below != point_count) plan.batches.back().retire_below = point_count;
  plan.window_labels = std::max(plan.window_labels, plan.batches.back().retire_below - plan.batches.back().lo);
  plan.ring_labels = std::min(max_labels, std::bit_ceil(point_count));
  return plan;
}

}  // namespace tetstream::pipeline

#include "io/tet_reader.hpp"

namespace tetstream::pipeline {

void DecodedBatch::decode(const io::TetReader& reader, const FrameBatch& b) {
  const std::size_t nf = b.end_frame - b.first_frame;
  if (frames_.size() < nf) frames_.resize(nf);
  first_.assign(nf + 1, 0);
  // A damaged frame throws: the exception must not leave the parallel region (that
  // terminates the process), so the first one is kept and rethrown after it.
  std::exception_ptr failure;
  std::mutex failure_mutex;
#pragma omp parallel for schedule(dynamic, 1) if (nf > 1)
  for (std::size_t i = 0; i < nf; ++i) {
    try {
      reader.read_frame(b.first_frame + i, frames_[i]);
    } catch (...) {
      std::lock_guard lock(failure_mutex);
      if (!failure) failure = std::current_exception();
    }
  }
  if (failure) std::rethrow_exception(failure);
  for (std::size_t i = 0; i < nf; ++i) first_[i + 1] = first_[i] + frames_[i].size() / 4;
  frames_used_ = nf;
}

}  // namespace tetstream::pipeline
