#pragma once
// The records of the sorted point file, in the layout of the container's PNTS record
// (docs/format.md section 3.4): x, y, z as float32 or float64, then the original index
// as a 32- or 64-bit integer, packed (3 x 8 + 4 = 28 bytes for float64 input below
// 2^32 points). Why the container's layout: the sorted file is then, byte for byte,
// the output's points section, and a point costs the disk what the input's precision
// needs (16 bytes for float32 input, against 32 for doubles and a 64-bit index).
//
// Invariant: a float32 coordinate is exactly a double, so every reader converts on
// read (coord(), xyz()) and the predicates still see the exact input.
//
// PointRecord<C, I> is the typed record (for code that loops over many records: sort,
// merge, index build, window load); PointRecords is a pointer to an array of them with
// the layout chosen at run time, and visit() hands a loop the typed array once.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <utility>

namespace tetstream::pipeline {

// One record. Packed: a 28-byte record puts half its doubles off 8-byte alignment,
// which x86 loads at full speed (members are read by value, never by reference).
template <class C, class I>
struct [[gnu::packed]] PointRecord {
  using Coord = C;
  using Id = I;
  C c[3];
  I id;
  double coord(int k) const { return double(c[k]); }
  void xyz(double* out) const { out[0] = double(c[0]), out[1] = double(c[1]), out[2] = double(c[2]); }
  std::uint64_t original() const { return std::uint64_t(id); }
  // From a point the caller knows fits: a float32 layout is only chosen for float32
  // input, and a 32-bit index only for inputs of at most 2^32 points.
  void set(const double* p, std::uint64_t original) {
    for (int k = 0; k < 3; ++k) c[k] = C(p[k]);
    id = I(original);
  }
};
static_assert(sizeof(PointRecord<float, std::uint32_t>) == 16 && sizeof(PointRecord<float, std::uint64_t>) == 20 &&
              sizeof(PointRecord<double, std::uint32_t>) == 28 && sizeof(PointRecord<double, std::uint64_t>) == 32);

// Which of the four records a file holds.
struct RecordLayout {
  bool float32 = false;  // coordinates as float32 (else float64)
  bool id64 = false;     // original indices as 64 bits (else 32)
  std::size_t bytes() const { return (float32 ? 12 : 24) + (id64 ? 8 : 4); }
  bool operator==(const RecordLayout&) const = default;
  // The container's choice for an input of `input_count` points (format.md 3.3:
  // id_width 32 when max(N, input_count) <= 2^32, and N <= input_count).
  static RecordLayout for_input(bool float32_input, std::uint64_t input_count) {
    return {float32_input, input_count > (std::uint64_t(1) << 32)};
  }
};

// Calls f(PointRecord<C, I>{}) with the record type of `layout`: the one place that
// turns the run-time layout into a type, so each loop is compiled for each record.
template <class F>
decltype(auto) with_record(RecordLayout layout, F&& f) {
  if (layout.float32)
    return layout.id64 ? f(PointRecord<float, std::uint64_t>{}) : f(PointRecord<float, std::uint32_t>{});
  return layout.id64 ? f(PointRecord<double, std::uint64_t>{}) : f(PointRecord<double, std::uint32_t>{});
}

// Read-only records addressed by label, their layout known at run time. Reads of one
// point branch on the layout (predictable: one layout a job); loops over many points
// take the typed array from visit() instead.
class PointRecords {
 public:
  PointRecords() = default;
  PointRecords(const void* data, RecordLayout layout)
      : data_(static_cast<const std::byte*>(data)), layout_(layout), bytes_(layout.bytes()) {}
  template <class R>
  explicit PointRecords(const R* records)
      : PointRecords(records, RecordLayout{sizeof(typename R::Coord) == 4, sizeof(typename R::Id) == 8}) {}

  explicit operator bool() const { return data_ != nullptr; }
  RecordLayout layout() const { return layout_; }
  std::size_t record_bytes() const { return bytes_; }
  const std::byte* data() const { return data_; }
  const std::byte* record(std::uint64_t label) const { return data_ + label * bytes_; }

  double coord(std::uint64_t label, int k) const {
    return with_record(layout_, [&](auto r) { return as(r)[label].coord(k); });
  }
  void xyz(std::uint64_t label, double* out) const {
    with_record(layout_, [&](auto r) { as(r)[label].xyz(out); });
  }
  std::uint64_t original(std::uint64_t label) const {
    return with_record(layout_, [&](auto r) { return as(r)[label].original(); });
  }
  // Decodes a record copied out of the array (scratch of record_bytes()).
  void decode(const void* record, double* out) const {
    with_record(layout_, [&](auto r) {
      decltype(r) copy;
      std::memcpy(&copy, record, sizeof copy);
      copy.xyz(out);
    });
  }
  // f(const PointRecord<C, I>* records): the array, typed.
  template <class F>
  decltype(auto) visit(F&& f) const {
    return with_record(layout_, [&](auto r) { return f(as(r)); });
  }

 private:
  template <class R>
  const R* as(R) const {
    return reinterpret_cast<const R*>(data_);
  }
  const std::byte* data_ = nullptr;
  RecordLayout layout_;
  std::size_t bytes_ = 32;
};

}  // namespace tetstream::pipeline
