#include "pipeline/window/shared_rim.hpp"

#include <algorithm>
#include <bit>
#include <mutex>

namespace tetstream::pipeline {

namespace {
// The table is at most 3/4 full: linear probing stays short. Its slots need not be a
// power of two (a tet's first slot is its hash scaled to the table, home()), so it
// grows to what its share holds: growing holds the old table and the new one, and a
// table of powers of two stopped at a third to two thirds of its share (5 MiB held 2:
// on `hills`, 10^6 points at 128M on two threads, finished zones published half the
// rim tets they did on one thread with a 6 MiB share, the same plan).
// It grows fourfold, and at the last step to what the old one leaves of the share:
// at least 4/5 of it.
constexpr std::size_t kMinSlots = 1024;
bool too_full(std::size_t size, std::size_t slots) { return 4 * size > 3 * slots; }
}  // namespace

std::size_t SharedRim::hash(const Slot& t) {
  std::uint64_t h = 0x9E3779B97F4A7C15ull;
  for (std::uint64_t l : t) {
    h ^= l + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
    h *= 0xBF58476D1CE4E5B9ull;
  }
  return std::size_t(h ^ (h >> 31));
}

std::size_t SharedRim::home(const Slot& t) const {
  return std::size_t((unsigned __int128)hash(t) * slots_.size() >> 64);
}

bool SharedRim::find_locked(const Slot& slot) const {
  if (slots_.empty()) return false;
  for (std::size_t i = home(slot);; i = next(i)) {
    if (empty(slots_[i])) return false;
    if (slots_[i] == slot) return true;
  }
}

bool SharedRim::contains(const Labels& tet) const {
  if (tet[3] >= kLabelLimit) return false;  // never published
  const Slot slot = pack(tet);
  std::shared_lock lock(mutex_);
  return find_locked(slot);
}

bool SharedRim::insert_locked(const Slot& t) {
  for (std::size_t i = home(t);; i = next(i)) {
    if (empty(slots_[i])) {
      slots_[i] = t;
      ++size_;
      return true;
    }
    if (slots_[i] == t) return false;
  }
}

// Empties slot `hole` and moves up the tets after it whose probe passed it
// (backward-shift deletion: every tet stays reachable from its home without
// markers for the removed ones).
void SharedRim::erase_locked(std::size_t hole) {
  for (std::size_t p = next(hole); !empty(slots_[p]); p = next(p)) {
    const std::size_t q = home(slots_[p]);
    // The tet at p may fill the hole unless its home lies in (hole, p], cyclically.
    const bool after_hole = hole <= p ? (hole < q && q <= p) : (hole < q || q <= p);
    if (!after_hole) {
      slots_[hole] = slots_[p];
      hole = p;
    }
  }
  slots_[hole][0] = kEmpty;
  --size_;
}

void SharedRim::rebuild_locked(std::size_t capacity, std::uint64_t keep_from) {
  std::vector<Slot> old(capacity, Slot{kEmpty, kEmpty, kEmpty});
  old.swap(slots_);
  size_ = 0;
  for (const Slot& t : old)
    if (!empty(t) && largest(t) >= keep_from) insert_locked(t);
}

bool SharedRim::grow_locked() {
  // The old table and the new one are both held while it grows: together within the
  // share.
  const std::size_t old = slots_.size(), most = max_slots(), room = most > old ? most - old : 0;
  std::size_t grown = std::max(kMinSlots, 4 * old);
  if (5 * grown > most) grown = room;  // the last step: no fourfold one would follow
  if (grown <= old || too_full(size_ + 1, grown)) return false;
  rebuild_locked(grown, 0);
  peak_bytes_ = std::max(peak_bytes_, slots_.size() * sizeof(Slot));
  return true;
}

std::size_t SharedRim::publish(std::span<const Labels> tets, std::uint64_t* no_room) {
  // A label past what a slot holds: the zones check that tet themselves.
  const auto fits = [](const Labels& t) { return t[3] < kLabelLimit; };
  std::unique_lock lock(mutex_);
  std::size_t published = 0;
  for (std::size_t i = 0; i < tets.size(); ++i) {
    if (!fits(tets[i])) {
      if (no_room) ++*no_room;
      continue;
    }
    if (too_full(size_ + 1, slots_.size()) && !grow_locked()) {
      // Full: the tets left that are not here already found no room.
      if (no_room)
        for (std::size_t j = i; j < tets.size(); ++j) *no_room += !fits(tets[j]) || !find_locked(pack(tets[j]));
      break;
    }
    published += insert_locked(pack(tets[i]));
  }
  return published;
}

void SharedRim::forget_below(std::uint64_t label) {
  std::unique_lock lock(mutex_);
  if (slots_.empty()) return;
  std::size_t kept = 0;
  for (const Slot& t : slots_) kept += !empty(t) && largest(t) >= label;
  // Few left: a smaller table (memory goes back; with the old one within the share).
  // Otherwise the tets go where they are, and the table keeps its size for the
  // zones to come.
  std::size_t capacity = kMinSlots;
  while (too_full(kept, capacity)) capacity *= 2;
  if (kept == 0) {
    std::vector<Slot>().swap(slots_);
    size_ = 0;
  } else if (4 * capacity <= slots_.size() && capacity + slots_.size() <= max_slots()) {
    rebuild_locked(capacity, label);
  } else {
    for (std::size_t i = 0; i < slots_.size(); ++i)
      while (!empty(slots_[i]) && largest(slots_[i]) < label) erase_locked(i);
  }
}

std::size_t SharedRim::size() const {
  std::shared_lock lock(mutex_);
  return size_;
}

std::size_t SharedRim::bytes() const {
  std::shared_lock lock(mutex_);
  return slots_.size() * sizeof(Slot);
}

std::size_t SharedRim::peak_bytes() const {
  std::shared_lock lock(mutex_);
  return peak_bytes_;
}

std::shared_lock<std::shared_mutex> SharedRim::read_lock() const { return std::shared_lock(mutex_); }

}  // namespace tetstream::pipeline
