#pragma once
// The keep step's kept tets (keep.cpp), which come in the padded job's frame order, to
// the output in the stored order (format.md §4.1) without sorting them all.
//
// The padded order is the periodic one but for the images across the sort axis' lower
// face (docs/periodic.md, "Write"): the caller tells, with each frame's tets, a
// *frontier* F that no tet still to come goes below, and a tet is written once it is
// below the frontier, sorted with the others written then. The tets from `deferred_from`
// on (kept at an image below 0 on the sort axis: found among the first frames, the last
// to be written) wait in the external sort, which spills. When the buffer of tets
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

  KeptStream(Write write, std::uint64_t deferred_from, std::size_t buffer_bytes,
             ExternalSorter<KeptTet, KeptTetLess>& sorter, int label_bits)
      : write_(std::move(write)),
        deferred_from_(deferred_from),
        buffer_cap_(std::max<std::size_t>(buffer_bytes / sizeof(KeptTet), 1)),
        sorter_(sorter),
        label_bits_(label_bits) {}

  // A frame's kept tets; `frontier`: no tet to come has a smaller smallest label.
  void add(std::span<const KeptTet> kept, std::uint64_t frontier) {
    for (const KeptTet& t : kept) {
      if (spilling_ || t.v[0] >= deferred_from_)
        sorter_.push(t);
      else
        buffer_.push_back(t);
    }
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
      sorter_.push(std::span<const KeptTet>(buffer_));
      buffer_.clear();
      buffer_.shrink_to_fit();
      spilling_ = true;
      spdlog::debug("periodic keep: tets far out of order, the rest through the external sort");
    }
  }

  // The tets still waiting, then the external sort's.
  void finish() {
    write(buffer_);
    sorter_.merge([&](std::span<const KeptTet> batch) { check_and_write(batch); });
  }

  bool spilled() const { return spilling_; }

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
  ExternalSorter<KeptTet, KeptTetLess>& sorter_;
  int label_bits_;
  std::vector<KeptTet> buffer_, ready_;
  std::uint64_t last_ = 0;
  bool spilling_ = false;
};

}  // namespace tetstream::pipeline::periodic
