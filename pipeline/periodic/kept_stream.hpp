#pragma once
// The keep step's kept tets (keep.cpp), which come in the padded job's frame order, to
// the output in the stored order (format.md §4.1) without sorting them all.
//
// The padded order is the periodic one but for the images across the sort axis' lower
// face (docs/periodic.md, "Write"): the caller tells, with each frame's tets, a
// *frontier* F that no tet still to come goes below, and a tet is written once it is
// below the frontier, sorted with the others written then. The tets from `deferred_from`
// on (kept at an image below 0 on the sort axis: found among the first frames, the last
// to be written) wait in the external sort, which spills (or, in a resumable keep, in a
// file that the external sort reads at the end). When the buffer of tets
// waiting for the frontier outgrows its share (a shape whose tets come far out of
// order), it and everything after go through the external sort, which then writes the
// rest in order: the same sequence either way.
#include "pipeline/files/external_sort.hpp"
#include "pipeline/periodic/tet_records.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdint>
#include <functional>
#include <span>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace tetstream::pipeline::periodic {

class KeptStream {
 public:
  using Write = std::function<void(std::span<const KeptTet>)>;
  // Where the tets that go through the external sort wait: `defer` takes them as they
  // come, `merge(write)` hands them back sorted at the end.
  using Defer = std::function<void(std::span<const KeptTet>)>;
  using Merge = std::function<void(const Write&)>;

  KeptStream(Write write, std::uint64_t deferred_from, std::size_t buffer_bytes, Defer defer, Merge merge,
             int label_bits)
      : write_(std::move(write)),
        deferred_from_(deferred_from),
        buffer_cap_(std::max<std::size_t>(buffer_bytes / sizeof(KeptTet), 1)),
        defer_(std::move(defer)),
        merge_(std::move(merge)),
        label_bits_(label_bits) {}
  // The external sort itself as that store (the keep step after the padded job: keep.cpp).
  KeptStream(Write write, std::uint64_t deferred_from, std::size_t buffer_bytes,
             ExternalSorter<KeptTet, KeptTetLess>& sorter, int label_bits)
      : KeptStream(
            std::move(write), deferred_from, buffer_bytes, [&sorter](std::span<const KeptTet> t) { sorter.push(t); },
            [&sorter](const Write& w) { sorter.merge([&w](std::span<const KeptTet> batch) { w(batch); }); },
            label_bits) {}

  // A frame's kept tets; `frontier`: no tet to come has a smaller smallest label.
  void add(std::span<const KeptTet> kept, std::uint64_t frontier) {
    deferred_.clear();
    for (const KeptTet& t : kept) {
      if (spilling_ || t.v[0] >= deferred_from_)
        deferred_.push_back(t);
      else
        buffer_.push_back(t);
    }
    if (!deferred_.empty()) defer_(deferred_);
    if (spilling_) return;
    ready_.clear();
    std::size_t keep = 0;
    for (const KeptTet& t : buffer_) {
      if (t.v[0] < frontier)
        ready_.push_back(t);
      else
        buffer_[keep++] = t;
    }
    buffer_.resize(keep);
    write(ready_);
    if (buffer_.size() > buffer_cap_) {
      defer_(buffer_);
      buffer_.clear();
      buffer_.shrink_to_fit();
      spilling_ = true;
      spdlog::debug("periodic keep: tets far out of order, the rest through the external sort");
    }
  }

  // The tets still waiting, then the external sort's.
  void finish() {
    write(buffer_);
    merge_([this](std::span<const KeptTet> batch) { check_and_write(batch); });
  }

  bool spilled() const { return spilling_; }

  // What a checkpoint keeps of the stream (keep_stage.cpp): the tets waiting for the
  // frontier, the last smallest label written, whether it spills; and a resumed
  // stream's state, from them.
  const std::vector<KeptTet>& waiting() const { return buffer_; }
  std::uint64_t last() const { return last_; }
  void restore(std::vector<KeptTet> waiting, std::uint64_t last, bool spilling) {
    buffer_ = std::move(waiting);
    last_ = last;
    spilling_ = spilling;
  }

 private:
  void write(std::vector<KeptTet>& tets) {
    radix_sort_kept(tets.data(), tets.size(), label_bits_);
    check_and_write(tets);
  }

  // A frontier the caller got wrong would put a tet out of order: refused, never written.
  void check_and_write(std::span<const KeptTet> tets) {
    if (tets.empty()) return;
    if (tets.front().v[0] < last_)
      throw std::logic_error("periodic keep: a tet of label " + std::to_string(tets.front().v[0]) +
                             " came after the frontier passed it");
    last_ = tets.back().v[0];
    write_(tets);
  }

  Write write_;
  std::uint64_t deferred_from_;
  std::size_t buffer_cap_;
  Defer defer_;
  Merge merge_;
  int label_bits_;
  std::vector<KeptTet> buffer_, ready_, deferred_;
  std::uint64_t last_ = 0;
  bool spilling_ = false;
};

}  // namespace tetstream::pipeline::periodic
