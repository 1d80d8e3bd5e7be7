#pragma once
// Internals shared by the point readers (io/point_*.cpp); not part of the io/ API.
#include "io/point_reader.hpp"
#include "io/point_source.hpp"

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

namespace tetstream::io::detail {

// Overflow-checked arithmetic for every size that comes from a header or an option:
// one rule in one place. Each returns false (and leaves r unspecified) when the exact
// result does not fit in 64 bits.
inline bool checked_add(std::uint64_t a, std::uint64_t b, std::uint64_t& r) {
  return !__builtin_add_overflow(a, b, &r);
}
inline bool checked_mul(std::uint64_t a, std::uint64_t b, std::uint64_t& r) {
  return !__builtin_mul_overflow(a, b, &r);
}

// Scalar types a binary record may hold (PLY property types; raw and npy use the floats).
enum class Scalar : std::uint8_t { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };
std::size_t scalar_size(Scalar s);
const char* scalar_name(Scalar s);

constexpr bool kHostLittle = std::endian::native == std::endian::little;

// Where x, y, z sit in a fixed-size binary record, and how to decode them.
struct BinaryLayout {
  std::uint64_t data_start = 0;          // absolute byte offset of record 0
  std::uint64_t stride = 24;             // bytes per record
  std::uint64_t offset[3] = {0, 8, 16};  // byte offset of x, y, z within a record
  Scalar type[3] = {Scalar::kF64, Scalar::kF64, Scalar::kF64};
  bool big_endian = false;
  std::string record = "record";    // what error messages call one record ("vertex", "row")
  std::string records = "records";  // and several
  // What may follow the last record. kNothing: the input must end there (checked before
  // reading on regular files, after the last record on streams). kChecked: `after` runs
  // once the last record has been consumed and judges the rest (PLY elements after
  // vertex, LAS extended records). kAnything: not looked at (raw: no count).
  enum class Tail { kAnything, kNothing, kChecked } tail = Tail::kAnything;
  std::function<void(ByteSource&)> after;
};

// Throws "FILE: byte OFFSET: N bytes of trailing data after the K RECORDS the header
// declares" unless `src` is at its end.
void expect_end(ByteSource& src, const std::string& what_ended);

// Reads fixed-size records (raw, PLY binary, npy). `count` is the number of records the
// header promises (nullopt: until the end of the input, whole records only); when
// `promised`, a regular file shorter than that is rejected here, and 0 records too.
std::unique_ptr<PointReader> make_binary_reader(std::unique_ptr<ByteSource> src, BinaryLayout layout,
                                                std::optional<std::uint64_t> count, bool promised,
                                                std::string format_name);

std::unique_ptr<PointReader> open_raw(std::unique_ptr<ByteSource> src, ScalarType type,
                                      const PointReadOptions& options);
std::unique_ptr<PointReader> open_ply(std::unique_ptr<ByteSource> src, const PointReadOptions& options);
std::unique_ptr<PointReader> open_npy(std::unique_ptr<ByteSource> src, const PointReadOptions& options);
std::unique_ptr<PointReader> open_text(std::unique_ptr<ByteSource> src, const PointReadOptions& options);
// The fields of one LAS point record besides x, y, z (those a filter or an attribute needs).
struct LasFields {
  std::uint16_t intensity = 0;
  std::uint8_t return_number = 0, number_of_returns = 0, classification = 0;
  double gps_time = 0;  // 0 when the point format has none
};
using LasFieldSink = std::function<void(const LasFields&)>;
// `sink`, when set, is called for each point kept, in order.
std::unique_ptr<PointReader> open_las(std::unique_ptr<ByteSource> src, const PointReadOptions& options,
                                      LasFieldSink sink = {});
// HDF5 reads by path (the library does its own I/O). `one_of_many`: the file is one of
// several of a snapshot, so a dataset whose group it lacks holds 0 points here.
std::unique_ptr<PointReader> open_hdf5(const std::string& path, const PointReadOptions& options, bool one_of_many);
// Several files as one input; each opened by `open_one` when its turn comes.
using OpenOne = std::function<std::unique_ptr<PointReader>(const std::string& path)>;
std::unique_ptr<PointReader> open_concat(std::vector<std::string> paths, OpenOne open_one);

// Complete lines of a ByteSource, without the '\n' (and a '\r' before it). A line is
// valid until the next call. Lines longer than kMaxLine are an InputError.
class LineSource {
 public:
  static constexpr std::size_t kMaxLine = std::size_t(1) << 20;
  explicit LineSource(ByteSource& src) : src_(src) {}
  bool next(std::string_view& line);
  std::uint64_t line_number() const { return line_; }  // 1-based, of the last line returned

 private:
  ByteSource& src_;
  std::uint64_t line_ = 0;
};

// The fields of a text line: separated by blanks, or by a comma or semicolon with
// optional blanks around it; '#' starts a comment; a trailing separator is allowed.
class FieldSplitter {
 public:
  explicit FieldSplitter(std::string_view line) : p_(line.data()), end_(line.data() + line.size()) {}
  bool next(std::string_view& field);  // false after the last field

 private:
  const char* p_;
  const char* end_;
  bool first_ = true;
};

// Parses a whole field as a double (std::from_chars; a leading '+' allowed; overflow
// gives +-inf, underflow 0). False when the field is not exactly one number.
bool parse_double(std::string_view field, double& v);

// Splits a text line into numbers (FieldSplitter's rules). Stores up to `cap` values and
// returns how many fields the line has, or -1 when a field is not a number (`bad` is set
// to it).
int parse_numbers(std::string_view line, double* out, int cap, std::string_view& bad);

// Throws "FILE: byte OFFSET: non-finite coordinate" (or line) if any of xyz[0..3n) is NaN
// or Inf; `where(i)` gives the location of coordinate i. Vectorised scan first.
template <class Where>
inline void check_finite(const double* xyz, std::size_t n, const std::string& file, Where&& where) {
  // Branch-free scan in SSE2-friendly 64-bit integer ops: the exponent field is all ones
  // (NaN or Inf) exactly when adding 1 to it carries into the sign bit; 4 independent
  // lanes so the loop vectorises without -ffast-math.
  constexpr std::uint64_t kExp = 0x7ff0000000000000ULL, kOne = 0x0010000000000000ULL;
  std::uint64_t lane[4] = {0, 0, 0, 0};
  const std::size_t m = 3 * n;
  std::size_t i = 0;
  for (; i + 4 <= m; i += 4) {
    std::uint64_t b[4];
    std::memcpy(b, xyz + i, sizeof b);
    for (int k = 0; k < 4; ++k) lane[k] |= (b[k] & kExp) + kOne;
  }
  for (; i < m; ++i) {
    std::uint64_t b;
    std::memcpy(&b, xyz + i, 8);
    lane[0] |= (b & kExp) + kOne;
  }
  const std::uint64_t bad = (lane[0] | lane[1] | lane[2] | lane[3]) >> 63;
  if (!bad) return;
  for (std::size_t i = 0; i < 3 * n; ++i) {
    if (!std::isfinite(xyz[i])) {
      const char* axis = i % 3 == 0 ? "x" : i % 3 == 1 ? "y" : "z";
      throw InputError(file + ": " + where(i) + ": non-finite coordinate (" + axis + " = " +
                       (std::isnan(xyz[i]) ? "nan"
                        : xyz[i] > 0       ? "inf"
                                           : "-inf") +
                       ")");
    }
  }
}

}  // namespace tetstream::io::detail
