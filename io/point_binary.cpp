// Fixed-size binary records: raw float32/float64 dumps, PLY binary vertices, npy rows.
#include "io/point_detail.hpp"

#include <algorithm>
#include <cmath>

namespace tetstream::io::detail {

std::size_t scalar_size(Scalar s) {
  switch (s) {
    case Scalar::kI8:
    case Scalar::kU8:
      return 1;
    case Scalar::kI16:
    case Scalar::kU16:
      return 2;
    case Scalar::kI32:
    case Scalar::kU32:
    case Scalar::kF32:
      return 4;
    case Scalar::kF64:
      return 8;
  }
  return 0;
}

const char* scalar_name(Scalar s) {
  switch (s) {
    case Scalar::kI8:
      return "int8";
    case Scalar::kU8:
      return "uint8";
    case Scalar::kI16:
      return "int16";
    case Scalar::kU16:
      return "uint16";
    case Scalar::kI32:
      return "int32";
    case Scalar::kU32:
      return "uint32";
    case Scalar::kF32:
      return "float32";
    case Scalar::kF64:
      return "float64";
  }
  return "?";
}

namespace {

// Loads one scalar of type T at p, byte-swapping when the file's order is not the host's.
template <class T, bool Swap>
inline double load_as_double(const char* p) {
  if constexpr (sizeof(T) == 1) {
    T v;
    std::memcpy(&v, p, 1);
    return double(v);
  } else {
    using U = std::conditional_t<sizeof(T) == 2, std::uint16_t,
                                 std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>>;
    U bits;
    std::memcpy(&bits, p, sizeof(U));
    if constexpr (Swap) {
      if constexpr (sizeof(U) == 2)
        bits = __builtin_bswap16(bits);
      else if constexpr (sizeof(U) == 4)
        bits = __builtin_bswap32(bits);
      else
        bits = __builtin_bswap64(bits);
    }
    T v;
    std::memcpy(&v, &bits, sizeof(T));
    return double(v);
  }
}

// All three coordinates of one type: the common case, one tight loop per type.
template <class T, bool Swap>
void decode_same(const char* src, std::size_t stride, const std::uint64_t* off, std::size_t n, double* dst) {
  const std::size_t ox = off[0], oy = off[1], oz = off[2];
  for (std::size_t i = 0; i < n; ++i) {
    const char* r = src + i * stride;
    dst[3 * i + 0] = load_as_double<T, Swap>(r + ox);
    dst[3 * i + 1] = load_as_double<T, Swap>(r + oy);
    dst[3 * i + 2] = load_as_double<T, Swap>(r + oz);
  }
}

template <bool Swap>
double load_any(Scalar s, const char* p) {
  switch (s) {
    case Scalar::kI8:
      return load_as_double<std::int8_t, Swap>(p);
    case Scalar::kU8:
      return load_as_double<std::uint8_t, Swap>(p);
    case Scalar::kI16:
      return load_as_double<std::int16_t, Swap>(p);
    case Scalar::kU16:
      return load_as_double<std::uint16_t, Swap>(p);
    case Scalar::kI32:
      return load_as_double<std::int32_t, Swap>(p);
    case Scalar::kU32:
      return load_as_double<std::uint32_t, Swap>(p);
    case Scalar::kF32:
      return load_as_double<float, Swap>(p);
    case Scalar::kF64:
      return load_as_double<double, Swap>(p);
  }
  return 0;
}

using DecodeFn = void (*)(const char*, std::size_t, const std::uint64_t*, std::size_t, double*);

template <bool Swap>
DecodeFn pick_same(Scalar s) {
  switch (s) {
    case Scalar::kI8:
      return decode_same<std::int8_t, Swap>;
    case Scalar::kU8:
      return decode_same<std::uint8_t, Swap>;
    case Scalar::kI16:
      return decode_same<std::int16_t, Swap>;
    case Scalar::kU16:
      return decode_same<std::uint16_t, Swap>;
    case Scalar::kI32:
      return decode_same<std::int32_t, Swap>;
    case Scalar::kU32:
      return decode_same<std::uint32_t, Swap>;
    case Scalar::kF32:
      return decode_same<float, Swap>;
    case Scalar::kF64:
      return decode_same<double, Swap>;
  }
  return nullptr;
}

class BinaryPointReader final : public PointReader {
 public:
  BinaryPointReader(std::unique_ptr<ByteSource> src, BinaryLayout layout, std::optional<std::uint64_t> count,
                    bool promised, std::string format_name)
      : src_(std::move(src)), layout_(std::move(layout)), promised_(promised) {
    count_ = count;
    format_name_ = std::move(format_name);
    source_name_ = src_->name();
    swap_ = layout_.big_endian == kHostLittle;
    const Scalar t = layout_.type[0];
    same_type_ = layout_.type[1] == t && layout_.type[2] == t;
    if (same_type_) decode_ = swap_ ? pick_same<true>(t) : pick_same<false>(t);
    float32_ = same_type_ && t == Scalar::kF32;
    // Packed native float64 xyz: read(2) straight into the caller's chunk.
    direct_ = same_type_ && t == Scalar::kF64 && !swap_ && layout_.stride == 24 && layout_.offset[0] == 0 &&
              layout_.offset[1] == 8 && layout_.offset[2] == 16;
  }

  std::size_t read(double* xyz, std::size_t max_points) override {
    std::size_t limit = max_points;
    if (count_) limit = static_cast<std::size_t>(std::min<std::uint64_t>(limit, *count_ - points_read_));
    std::size_t n = 0;
    if (limit > 0) n = direct_ ? read_direct(xyz, limit) : read_decoded(xyz, limit);
    const std::uint64_t first = points_read_;
    check_finite(xyz, n, source_name_,
                 [&](std::size_t i) { return "byte " + std::to_string(coordinate_offset(first + i / 3, i % 3)); });
    points_read_ += n;
    if (n == 0 && points_read_ == 0) {
      throw InputError::at_byte(source_name_, src_->offset(), "no points");
    }
    if (count_ && points_read_ == *count_ && !tail_checked_) {
      tail_checked_ = true;
      if (layout_.tail == BinaryLayout::Tail::kNothing) {
        expect_end(*src_, std::to_string(*count_) + " " + layout_.records + " the header declares");
      } else if (layout_.tail == BinaryLayout::Tail::kChecked) {
        layout_.after(*src_);
      }
    }
    return n;
  }

  // With a known count the records ahead are whole (checked when the reader was
  // made), so a seek passes them; the last rank's read still checks the tail.
  std::uint64_t skip(std::uint64_t n) override {
    if (!count_) return PointReader::skip(n);
    const std::uint64_t k = std::min<std::uint64_t>(n, *count_ - points_read_);
    if (src_->skip(k * layout_.stride) != k * layout_.stride) truncated(0, 0);
    points_read_ += k;
    return k;
  }

  std::uint64_t bytes_read() const override { return src_->offset(); }
  std::optional<std::uint64_t> source_size() const override { return src_->size(); }

  std::string location(std::uint64_t index) const override {
    return "byte " + std::to_string(coordinate_offset(index, 0));
  }

 private:
  std::uint64_t coordinate_offset(std::uint64_t index, int c) const {
    return layout_.data_start + index * layout_.stride + layout_.offset[c];
  }

  std::size_t read_direct(double* xyz, std::size_t limit) {
    const std::size_t got = src_->read_into(xyz, limit * 24);
    if (got % 24 != 0 || (got < limit * 24 && count_)) truncated(got / 24, got % 24);
    return got / 24;
  }

  std::size_t read_decoded(double* xyz, std::size_t limit) {
    const std::size_t stride = static_cast<std::size_t>(layout_.stride);
    std::size_t done = 0;
    while (done < limit) {
      if (src_->available() < stride && src_->ensure(stride) < stride) {
        if (src_->available() > 0 || count_) truncated(done, src_->available());
        break;
      }
      const std::size_t k = std::min(limit - done, src_->available() / stride);
      if (same_type_) {
        decode_(src_->data(), stride, layout_.offset, k, xyz + 3 * done);
      } else {
        decode_mixed(src_->data(), k, xyz + 3 * done);
      }
      src_->consume(k * stride);
      done += k;
    }
    return done;
  }

  void decode_mixed(const char* src, std::size_t n, double* dst) const {
    for (std::size_t i = 0; i < n; ++i) {
      const char* r = src + i * layout_.stride;
      for (int c = 0; c < 3; ++c) {
        dst[3 * i + c] = swap_ ? load_any<true>(layout_.type[c], r + layout_.offset[c])
                               : load_any<false>(layout_.type[c], r + layout_.offset[c]);
      }
    }
  }

  // The input ended inside a record, or before the records a header promised.
  [[noreturn]] void truncated(std::size_t whole_in_this_chunk, std::size_t partial_bytes) {
    const std::uint64_t index = points_read_ + whole_in_this_chunk;
    // The offset names the first missing byte: the start of the partial record, or
    // the end of the input after whole records.
    const std::uint64_t at = layout_.data_start + index * layout_.stride;
    std::string problem = "truncated: input ends ";
    problem += partial_bytes
                   ? "inside " + layout_.record + " " + std::to_string(index) + " (" + std::to_string(partial_bytes) +
                         " of " + std::to_string(layout_.stride) + " bytes present)"
                   : "after " + std::to_string(index) + " " + layout_.records;
    if (promised_) problem += ", but the header promises " + std::to_string(*count_);
    throw InputError::at_byte(source_name_, at, problem);
  }

  std::unique_ptr<ByteSource> src_;
  BinaryLayout layout_;
  bool promised_ = false;
  bool swap_ = false, same_type_ = false, direct_ = false;
  bool tail_checked_ = false;
  DecodeFn decode_ = nullptr;
};

}  // namespace

void expect_end(ByteSource& src, const std::string& what_ended) {
  if (src.at_end()) return;
  const std::uint64_t at = src.offset();
  std::string amount = "trailing data";
  if (src.size()) amount = std::to_string(*src.size() - at) + " bytes of trailing data";
  throw InputError::at_byte(src.name(), at, amount + " after the " + what_ended + " (a wrong count in the header?)");
}

std::unique_ptr<PointReader> make_binary_reader(std::unique_ptr<ByteSource> src, BinaryLayout layout,
                                                std::optional<std::uint64_t> count, bool promised,
                                                std::string format_name) {
  if (layout.stride == 0 || layout.stride > PointReadOptions::kMaxRecordBytes) {
    throw InputError::at_byte(src->name(), layout.data_start,
                              "a " + layout.record + " of " + std::to_string(layout.stride) +
                                  " bytes: more than the largest record we read (" +
                                  std::to_string(PointReadOptions::kMaxRecordBytes) + " bytes)");
  }
  if (!promised)
    return std::make_unique<BinaryPointReader>(std::move(src), std::move(layout), count, false, std::move(format_name));
  // A regular file must hold every record the header promises: check before any work.
  if (count && src->size()) {
    const std::uint64_t have = *src->size() > layout.data_start ? *src->size() - layout.data_start : 0;
    if (*count > have / layout.stride) {
      throw InputError::at_byte(src->name(), *src->size(),
                                "truncated: the header promises " + std::to_string(*count) + " " + layout.records +
                                    " of " + std::to_string(layout.stride) + " bytes from byte " +
                                    std::to_string(layout.data_start) + " but the file holds " + std::to_string(have) +
                                    " bytes of data (" + std::to_string(have / layout.stride) + " " + layout.records +
                                    ")");
    }
  }
  std::uint64_t bytes = 0;  // (on stdin the count is not checked against a size above)
  if (count && (!checked_mul(*count, layout.stride, bytes) || !checked_add(bytes, layout.data_start, bytes))) {
    throw InputError::at_byte(src->name(), layout.data_start,
                              "the header declares " + std::to_string(*count) + " " + layout.records + " of " +
                                  std::to_string(layout.stride) + " bytes: more than any file can hold");
  }
  if (count && *count == 0) {
    throw InputError::at_byte(src->name(), layout.data_start,
                              "the header declares 0 " + layout.records + ": no points");
  }
  // Nothing may follow the records: on a regular file, refuse before any work.
  if (count && src->size() && layout.tail == BinaryLayout::Tail::kNothing) {
    const std::uint64_t end = layout.data_start + *count * layout.stride;  // <= size: checked above
    if (*src->size() > end) {
      throw InputError::at_byte(src->name(), end,
                                std::to_string(*src->size() - end) + " bytes of trailing data after the " +
                                    std::to_string(*count) + " " + layout.records +
                                    " the header declares (a wrong count in the header?)");
    }
  }
  return std::make_unique<BinaryPointReader>(std::move(src), std::move(layout), count, true, std::move(format_name));
}

std::unique_ptr<PointReader> open_raw(std::unique_ptr<ByteSource> src, ScalarType type,
                                      const PointReadOptions& options) {
  const std::uint64_t w = type == ScalarType::kFloat32 ? 4 : 8;
  BinaryLayout layout;
  layout.data_start = 0;
  layout.stride = options.stride ? options.stride : 3 * w;
  std::uint64_t end = 0;
  if (!checked_add(options.offset, 3 * w, end) || end > layout.stride) {
    throw UsageError("--offset " + std::to_string(options.offset) + " + 3 coordinates of " + std::to_string(w) +
                     " bytes do not fit in a record of --stride " + std::to_string(layout.stride) + " bytes");
  }
  for (int c = 0; c < 3; ++c) {
    layout.offset[c] = options.offset + c * w;
    layout.type[c] = w == 4 ? Scalar::kF32 : Scalar::kF64;
  }
  layout.big_endian = options.byte_order == ByteOrder::kBig;
  layout.record = "record";
  std::string name =
      std::string("raw ") + (w == 4 ? "f32 " : "f64 ") + (layout.big_endian ? "big-endian" : "little-endian");
  if (layout.stride != 3 * w || options.offset)
    name += ", stride " + std::to_string(layout.stride) + ", offset " + std::to_string(options.offset);

  std::optional<std::uint64_t> count;
  if (src->size()) {
    const std::uint64_t size = *src->size();
    if (size == 0) throw InputError::at_byte(src->name(), 0, "empty file: no points");
    if (size % layout.stride != 0) {
      throw InputError::at_byte(src->name(), size - size % layout.stride,
                                "truncated: file size " + std::to_string(size) + " is not a multiple of the " +
                                    std::to_string(layout.stride) + "-byte record (" +
                                    std::to_string(size / layout.stride) + " records and " +
                                    std::to_string(size % layout.stride) + " bytes)");
    }
    count = size / layout.stride;
  }
  // The size-derived count is exact but not a header's promise.
  return make_binary_reader(std::move(src), layout, count, /*promised=*/false, std::move(name));
}

}  // namespace tetstream::io::detail
