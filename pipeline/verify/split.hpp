#pragma once
// How a distributed verify shares the work (pipeline/verify.hpp): the frames, sorted by
// their smallest label as the engine visits them, cut into K runs of about the same
// number of tets, each cut where the smallest label changes. Rank r checks the frames
// of run r; it owns the labels [low[r], low[r+1]): every key (a facet's or an edge's
// smallest label) in that range is finalized by rank r, whoever's tets made the record.
// Pure logic, unit-tested (tests/unit/verify_split_test.cpp).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

struct VerifySplit {
  // first[r]: position (in the sorted order) of rank r's first frame; first[K] = frames.
  std::vector<std::size_t> first;
  // low[r]: the smallest label rank r owns. low[0] = 0; low[r] = the smallest label of
  // rank r's first frame, or ~0 for a rank without frames (it owns nothing); low[K] = ~0.
  std::vector<std::uint64_t> low;
  int ranks() const { return int(first.size()) - 1; }
  // The rank that owns `label`: the last r with low[r] <= label.
  int owner(std::uint64_t label) const;
};

// min_labels: each frame's smallest label, in the visiting order (non-decreasing);
// tets: each frame's tet count, same order.
VerifySplit split_frames(const std::vector<std::uint64_t>& min_labels, const std::vector<std::uint64_t>& tets,
                         int ranks);

}  // namespace tetstream::pipeline
