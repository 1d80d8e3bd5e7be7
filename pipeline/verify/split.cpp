// How a distributed verify shares the frames and the labels (pipeline/verify/split.hpp).
#include "pipeline/verify/split.hpp"

#include <algorithm>
#include <stdexcept>

namespace tetstream::pipeline {

int VerifySplit::owner(std::uint64_t label) const {
  // low[0] = 0 <= label: the result is at least 0. Ranks without frames have
  // low = ~0 and are skipped unless label is ~0 itself (no label is: labels < N).
  const auto it = std::upper_bound(low.begin(), low.end() - 1, label);
  return int(it - low.begin()) - 1;
}

VerifySplit split_frames(const std::vector<std::uint64_t>& min_labels, const std::vector<std::uint64_t>& tets,
                         int ranks) {
  if (ranks < 1 || min_labels.size() != tets.size()) throw std::invalid_argument("split_frames");
  const std::size_t frames = min_labels.size();
  std::vector<std::uint64_t> prefix(frames + 1, 0);  // tets before position j
  for (std::size_t j = 0; j < frames; ++j) prefix[j + 1] = prefix[j] + tets[j];
  const std::uint64_t total = prefix[frames];
  VerifySplit s;
  s.first.assign(std::size_t(ranks) + 1, frames);
  s.low.assign(std::size_t(ranks) + 1, ~0ull);
  s.first[0] = 0;
  s.low[0] = 0;
  for (int r = 1; r < ranks; ++r) {
    // The first position whose tets before it reach r/K of the total (the target, in
    // 128 bits: total * r may not fit 64), moved past frames of the same smallest
    // label (a label's frames stay on one rank, so the label ranges do not overlap).
    const unsigned __int128 target =
        (static_cast<unsigned __int128>(total) * unsigned(r) + unsigned(ranks) - 1) / unsigned(ranks);
    std::size_t j = s.first[std::size_t(r) - 1];
    while (j < frames && prefix[j] < target) ++j;
    while (j > 0 && j < frames && min_labels[j] == min_labels[j - 1]) ++j;
    s.first[std::size_t(r)] = j;
    s.low[std::size_t(r)] = j < frames ? min_labels[j] : ~0ull;
  }
  // A rank whose run starts where the next one does has no frames: it owns nothing
  // (its low equals the next rank's, and owner() picks the later one).
  return s;
}

}  // namespace tetstream::pipeline
