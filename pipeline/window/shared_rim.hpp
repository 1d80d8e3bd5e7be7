#pragma once
// The rim tets that finished zones certified, for the zones still running
// (docs/certificate.md, "Neighbours").
//
// A tet with vertices in two zones is on the rim of both, and each used to prove it on
// its own: on a surface, where these tets' balls are wide, half of the emptiness
// queries proved again what a neighbour had proved. A zone that has finished has
// certified its whole rim: every one of those tets is a tet of DT(P) (a set of labels;
// the perturbation is the same in every window). So a running zone whose window has a
// tet with the same four labels knows it is Delaunay without a ball or a query.
//
// What is here never decides an output: a tet found here is Delaunay (true whichever
// zone published it, whenever), one not found is checked as before. The bytes are the
// same for any thread count, plan or timing; only the counters say which zone did the
// work. Thread-safe: published once a zone ends, looked up by the zones that run,
// forgotten once no zone that could hold the tet is left.
#include <array>
#include <cstdint>
#include <shared_mutex>
#include <span>
#include <vector>

namespace tetstream::pipeline {

class SharedRim {
 public:
  using Labels = std::array<std::uint64_t, 4>;  // increasing

  // At most `max_bytes` of table (the ledger's share), counting the old table while a
  // new one is filled: when the table is full at that size, a zone's tets are not published (its neighbours check them
  // themselves) until forget_below makes room.
  explicit SharedRim(std::size_t max_bytes) : max_bytes_(max_bytes) {}

  // Whether a finished zone certified the tet with these labels.
  bool contains(const Labels& tet) const;
  // A finished zone's rim tets; returns how many were published (the others: already
  // there, or no room; `no_room`, when given, counts the latter: those not here when
  // the table was full, and those whose labels a slot cannot hold).
  std::size_t publish(std::span<const Labels> tets, std::uint64_t* no_room = nullptr);
  // Calls visit(tet) for every tet here with a label in [begin, end) (with a zone's
  // labels: the finished neighbours of its points there), under the read lock.
  template <class Visit>
  void for_each_touching(std::uint64_t begin, std::uint64_t end, Visit&& visit) const {
    auto lock = read_lock();
    for (const Slot& slot : slots_) {
      if (empty(slot)) continue;
      const Labels t = unpack(slot);
      for (std::uint64_t l : t)
        if (l >= begin && l < end) {
          visit(t);
          break;
        }
    }
  }
  // Forgets the tets whose labels are all below `label`: every zone that could hold a
  // vertex of theirs has finished.
  void forget_below(std::uint64_t label);

  std::size_t size() const;
  std::size_t bytes() const;       // the table's now
  std::size_t peak_bytes() const;  // the most it took

 private:
  // A slot: the four labels in 48 bits each (2.8 * 10^14 points), 24 bytes where four
  // 64-bit labels took 32, so a share holds a third more tets (on `hills`, 10^6 points
  // at 128M on two threads, finished zones offered 1.87 M rim tets to a table that held
  // 0.11 M at a time, and 0.58 M of the 0.59 M taken were found by a later zone). All
  // ones in the first word: free (a label of all ones is never published).
  using Slot = std::array<std::uint64_t, 3>;
  static constexpr std::uint64_t kLabelLimit = (std::uint64_t(1) << 48) - 1;  // labels below it are kept
  static constexpr std::uint64_t kEmpty = ~std::uint64_t(0);
  static bool empty(const Slot& s) { return s[0] == kEmpty; }
  static Slot pack(const Labels& t) { return {t[0] | t[1] << 48, t[1] >> 16 | t[2] << 32, t[2] >> 32 | t[3] << 16}; }
  static Labels unpack(const Slot& s) {
    constexpr std::uint64_t m = kLabelLimit;
    return {s[0] & m, (s[0] >> 48 | s[1] << 16) & m, (s[1] >> 32 | s[2] << 32) & m, s[2] >> 16};
  }
  static std::uint64_t largest(const Slot& s) { return s[2] >> 16; }
  std::shared_lock<std::shared_mutex> read_lock() const;
  static std::size_t hash(const Slot& s);
  std::size_t home(const Slot& s) const;  // the first slot a tet's probe tries
  std::size_t next(std::size_t i) const { return i + 1 == slots_.size() ? 0 : i + 1; }
  bool find_locked(const Slot& s) const;
  bool insert_locked(const Slot& s);  // false: already there
  bool grow_locked();                 // false: the share holds no larger table
  std::size_t max_slots() const { return max_bytes_ / sizeof(Slot); }
  void erase_locked(std::size_t slot);
  void rebuild_locked(std::size_t capacity, std::uint64_t keep_from);

  const std::size_t max_bytes_;
  mutable std::shared_mutex mutex_;
  std::vector<Slot> slots_;  // open addressing, linear probing
  std::size_t size_ = 0;
  std::size_t peak_bytes_ = 0;
};

}  // namespace tetstream::pipeline
