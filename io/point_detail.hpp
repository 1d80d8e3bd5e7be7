#pragma once
// Internals shared by the point readers (io/point_*.cpp); not part of the io/ API.
#include "io/point_reader.hpp"
#include "io/point_source.hpp"

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>

namespace tetstream::io::detail {

// Scalar types a binary record may hold (PLY property types; raw and npy use the floats).
enum class Scalar : std::uint8_t { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };
std::size_t scalar_size(Scalar s);
const char* scalar_name(Scalar s);

constexpr bool kHostLittle = std::endian::native == std::endian::little;

// Where x, y, z sit in a fixed-size binary record, and how to decode them.
struct BinaryLayout {
  std::uint64_t data_start = 0;  // absolute byte offset of record 0
  std::uint64_t stride = 24;     // bytes per record
  std::uint64_t offset[3] = {0, 8, 16};  // byte offset of x, y, z within a record
  Scalar type[3] = {Scalar::kF64, Scalar::kF64, Scalar::kF64};
  bool big_endian = false;
  std::string record = "record";    // what error messages call one record ("vertex", "row")
  std::string records = "records";  // and several
};

// Reads fixed-size records (raw, PLY binary, npy). `count` is the number of records the
// header promises (nullopt: until the end of the input, whole records only); when
// `promised`, a regular file shorter than that is rejected here, and 0 records too.
std::unique_ptr<PointReader> make_binary_reader(std::unique_ptr<ByteSource> src, BinaryLayout layout,
                                                std::optional<std::uint64_t> count, bool promised,
                                                std::string format_name);

std::unique_ptr<PointReader> open_raw(std::unique_ptr<ByteSource> src, ScalarType type,
                                      const PointReadOptions& options);
std::unique_ptr<PointReader> open_ply(std::unique_ptr<ByteSource> src);
std::unique_ptr<PointReader> open_npy(std::unique_ptr<ByteSource> src);
std::unique_ptr<PointReader> open_text(std::unique_ptr<ByteSource> src);

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

// Splits a text line into numbers separated by blanks, or by a comma or semicolon with
// optional blanks around it; '#' starts a comment. Stores up to `cap` values and returns
// how many fields the line has, or -1 when a field is not a number (`bad` is set to it).
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
                       (std::isnan(xyz[i]) ? "nan" : xyz[i] > 0 ? "inf" : "-inf") + ")");
    }
  }
}

}  // namespace tetstream::io::detail
