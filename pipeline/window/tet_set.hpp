#pragma once
// A set of tets keyed by their sorted vertex ids (128 bits): the zone's memo of tets
// its queries proved empty.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

// An open-addressing table (linear probing, at most half full): one cache line per
// lookup and no allocation per insert, where a node-based std::unordered_set chases a
// bucket and then a node.
class TetSet {
 public:
  bool contains(std::uint64_t a, std::uint64_t b) const {
    if (slots_.empty()) return false;
    for (std::size_t i = hash(a, b) & mask_;; i = (i + 1) & mask_) {
      if (slots_[i].a == a && slots_[i].b == b) return true;
      if (slots_[i].a == kEmpty) return false;
    }
  }
  void insert(std::uint64_t a, std::uint64_t b) {
    if (2 * (size_ + 1) > slots_.size()) grow();
    for (std::size_t i = hash(a, b) & mask_;; i = (i + 1) & mask_) {
      if (slots_[i].a == a && slots_[i].b == b) return;
      if (slots_[i].a == kEmpty) {
        slots_[i] = {a, b};
        ++size_;
        return;
      }
    }
  }
  void clear() {
    std::fill(slots_.begin(), slots_.end(), Slot{});
    size_ = 0;
  }

 private:
  // No key has a == kEmpty: its low half is a vertex id below kNoVertex.
  static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
  struct Slot {
    std::uint64_t a = kEmpty, b = 0;
  };
  static std::size_t hash(std::uint64_t a, std::uint64_t b) {
    std::uint64_t h = (a ^ (b * 0x9E3779B97F4A7C15ULL)) * 0xBF58476D1CE4E5B9ULL;
    return std::size_t(h ^ (h >> 29));
  }
  void grow() {
    std::vector<Slot> old(std::max<std::size_t>(1024, 2 * slots_.size()));
    old.swap(slots_);
    mask_ = slots_.size() - 1;
    size_ = 0;
    for (const Slot& s : old)
      if (s.a != kEmpty) insert(s.a, s.b);
  }
  std::vector<Slot> slots_;
  std::size_t mask_ = 0, size_ = 0;
};

}  // namespace tetstream::pipeline
