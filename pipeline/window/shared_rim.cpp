#include "pipeline/window/shared_rim.hpp"

#include <algorithm>
#include <bit>
#include <mutex>

namespace tetstream::pipeline {

namespace {
// The table is at most 3/4 full: linear probing stays short, and a table that doubles
// at that load is 3/8 full after, so it takes 32-85 bytes a tet.
constexpr std::size_t kMinSlots = 1024;
bool too_full(std::size_t size, std::size_t slots) { return 4 * size > 3 * slots; }
}  // namespace

std::size_t SharedRim::hash(const Labels& t) {
  std::uint64_t h = 0x9E3779B97F4A7C15ull;
  for (std::uint64_t l : t) {
    h ^= l + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
    h *= 0xBF58476D1CE4E5B9ull;
  }
  return std::size_t(h ^ (h >> 31));
}

bool SharedRim::contains(const Labels& tet) const {
  std::shared_lock lock(mutex_);
  if (slots_.empty()) return false;
  const std::size_t mask = slots_.size() - 1;
  for (std::size_t i = hash(tet) & mask;; i = (i + 1) & mask) {
    if (slots_[i][0] == kEmpty) return false;
    if (slots_[i] == tet) return true;
  }
}

bool SharedRim::insert_locked(const Labels& t) {
  const std::size_t mask = slots_.size() - 1;
  for (std::size_t i = hash(t) & mask;; i = (i + 1) & mask) {
    if (slots_[i][0] == kEmpty) {
      slots_[i] = t;
      ++size_;
      return true;
    }
    if (slots_[i] == t) return false;
  }
}

void SharedRim::rebuild_locked(std::size_t capacity, std::uint64_t keep_from) {
  std::vector<Labels> old(capacity, Labels{kEmpty, kEmpty, kEmpty, kEmpty});
  old.swap(slots_);
  size_ = 0;
  for (const Labels& t : old)
    if (t[0] != kEmpty && t[3] >= keep_from) insert_locked(t);
}

std::size_t SharedRim::publish(std::span<const Labels> tets) {
  std::unique_lock lock(mutex_);
  std::size_t published = 0;
  for (const Labels& t : tets) {
    if (too_full(size_ + 1, slots_.size())) {
      // The old table and the new one are both held while it grows (and while
      // forget_below rebuilds): together within the share.
      const std::size_t grown = std::max(kMinSlots, 2 * slots_.size());
      if ((grown + slots_.size()) * sizeof(Labels) > max_bytes_) break;
      rebuild_locked(grown, 0);
      peak_bytes_ = std::max(peak_bytes_, slots_.size() * sizeof(Labels));
    }
    published += insert_locked(t);
  }
  return published;
}

void SharedRim::forget_below(std::uint64_t label) {
  std::unique_lock lock(mutex_);
  if (slots_.empty()) return;
  std::size_t kept = 0;
  for (const Labels& t : slots_) kept += t[0] != kEmpty && t[3] >= label;
  // The smallest table that holds the rest below the load limit (memory goes back;
  // never larger than the old one, so the two fit the share together).
  std::size_t capacity = kMinSlots;
  while (too_full(kept, capacity)) capacity *= 2;
  rebuild_locked(kept == 0 ? 0 : std::min(capacity, slots_.size()), label);
}

std::size_t SharedRim::size() const {
  std::shared_lock lock(mutex_);
  return size_;
}

std::size_t SharedRim::bytes() const {
  std::shared_lock lock(mutex_);
  return slots_.size() * sizeof(Labels);
}

std::size_t SharedRim::peak_bytes() const {
  std::shared_lock lock(mutex_);
  return peak_bytes_;
}

std::shared_lock<std::shared_mutex> SharedRim::read_lock() const { return std::shared_lock(mutex_); }

}  // namespace tetstream::pipeline
