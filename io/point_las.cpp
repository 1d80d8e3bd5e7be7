// LAS 1.0-1.4 (ASPRS), point data record formats 0-10, read by us: the public header is
// a documented fixed layout (all little-endian), and every record format starts with
// int32 X, Y, Z. A coordinate is  x = X * x_scale + x_offset  in double arithmetic (one
// rounding for the product, one for the sum, no FMA); the reader counts the coordinates
// where either rounding changed the value, so `info` can say whether the conversion was
// exact (docs/inputs.md says what that means for the triangulation).
//
//   offset size  field (public header block)
//     0     4    "LASF"
//    24     1    version major (1)         25   1  version minor (0-4)
//    94     2    header size               96   4  offset to point data
//   104     1    point data format (bit 7 or 6 set: LASzip-compressed)
//   105     2    point data record length 107   4  legacy number of point records
//   131    24    x, y, z scale (double)   155  24  x, y, z offset (double)
//   227     8    start of waveform data (1.3+)
//   235     8    start of first EVLR (1.4) 243  4  number of EVLRs
//   247     8    number of point records (1.4, 64-bit)            375: end of the 1.4 header
#include "io/point_detail.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <vector>

namespace tetstream::io::detail {
namespace {

// The shortest record of each point data format (ASPRS LAS 1.4 R15, table of formats).
constexpr std::uint16_t kMinRecord[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};

template <class T>
T le_at(const char* p) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if constexpr (!kHostLittle) {
    for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
  }
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

std::string shortest(double v) {
  char buf[32];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

// x = X * scale + offset for one coordinate (X an int32, exact in a double), counting
// in `rounded` whether either rounding changed the value.
inline double scaled(double X, int c, const double* scale, const double* offset, std::uint64_t& rounded) {
  const double p = X * scale[c];
  const double r = p + offset[c];
  // Exact product: the fused X*s - p is 0. Exact sum: the two-sum error is 0.
  const double bv = r - p, av = r - bv;
  if (std::fma(X, scale[c], -p) != 0 || (p - av) + (offset[c] - bv) != 0) ++rounded;
  return r;
}

std::string exactness(std::uint64_t rounded, std::uint64_t points) {
  // A decimal scale (0.01, 0.001) is no binary fraction, so X * scale + offset is
  // usually not a double: the nearest one is read. That is the tile's quantisation as
  // every LAS reader sees it, not a fault, and it is said so in the same line.
  return rounded == 0 ? "yes (every X * scale + offset is exact)"
                      : "no (" + std::to_string(rounded) + " of " + std::to_string(3 * points) +
                            " coordinates are X * scale + offset rounded to the nearest double: the "
                            "file's own quantisation, as with any decimal scale; not damage, and the "
                            "points read are triangulated exactly)";
}

std::string triple(const double* v) { return shortest(v[0]) + " " + shortest(v[1]) + " " + shortest(v[2]); }

// The int32 records through the binary reader, then x = X * scale + offset per axis.
class LasPointReader final : public PointReader {
 public:
  LasPointReader(std::unique_ptr<PointReader> records, const double scale[3], const double offset[3],
                 std::string format_name)
      : records_(std::move(records)) {
    count_ = records_->count();
    format_name_ = std::move(format_name);
    source_name_ = records_->source_name();
    for (int c = 0; c < 3; ++c) scale_[c] = scale[c], offset_[c] = offset[c];
  }

  std::size_t read(double* xyz, std::size_t max_points) override {
    const std::size_t n = records_->read(xyz, max_points);
    for (std::size_t i = 0; i < 3 * n; ++i) xyz[i] = scaled(xyz[i], int(i % 3), scale_, offset_, rounded_);
    const std::uint64_t first = points_read_;
    check_finite(xyz, n, source_name_, [&](std::size_t i) { return records_->location(first + i / 3); });
    points_read_ += n;
    return n;
  }

  // The records are fixed-length: the binary reader seeks past them.
  std::uint64_t skip(std::uint64_t n) override {
    const std::uint64_t k = records_->skip(n);
    points_read_ += k;
    return k;
  }

  std::uint64_t bytes_read() const override { return records_->bytes_read(); }
  std::optional<std::uint64_t> source_size() const override { return records_->source_size(); }
  std::string location(std::uint64_t index) const override { return records_->location(index); }

  std::vector<std::pair<std::string, std::string>> details() const override {
    return {{"scale", triple(scale_)}, {"offset", triple(offset_)}, {"exact", exactness(rounded_, points_read_)}};
  }

 private:
  std::unique_ptr<PointReader> records_;
  double scale_[3], offset_[3];
  std::uint64_t rounded_ = 0;
};

// The fields a filter (and `convert --las-attributes`) looks at, by point format: 0-5
// keep the return number and count in 3 bits each of byte 14 and the class in bits 0-4
// of byte 15 (the rest are flags); 6-10 have 4 bits each in byte 14 and a whole class
// byte at 16. GPS time: a double at 20 (formats 1, 3, 4, 5) or 22 (6-10); 0 and 2 have none.
LasFields las_fields_of(const char* record, int format) {
  LasFields f;
  f.intensity = le_at<std::uint16_t>(record + 12);
  const std::uint8_t returns = std::uint8_t(record[14]);
  if (format < 6) {
    f.return_number = returns & 0x07;
    f.number_of_returns = (returns >> 3) & 0x07;
    f.classification = std::uint8_t(record[15]) & 0x1F;
  } else {
    f.return_number = returns & 0x0F;
    f.number_of_returns = returns >> 4;
    f.classification = std::uint8_t(record[16]);
  }
  if (format >= 6)
    f.gps_time = le_at<double>(record + 22);
  else if (format == 1 || format >= 3)
    f.gps_time = le_at<double>(record + 20);
  return f;
}

// With a filter the number of points is known only once the file has been read, and a
// point's index counts the kept points only: the records are read here, each tested,
// and only those kept are decoded (the binary reader numbers every record). The same
// reader hands the kept points' fields to a sink (`convert --las-attributes`).
class LasFilteredReader final : public PointReader {
 public:
  LasFilteredReader(std::unique_ptr<ByteSource> src, std::uint64_t records, std::uint64_t data_start,
                    std::size_t stride, int format, const double scale[3], const double offset[3],
                    std::string format_name, const PointReadOptions& options, std::function<void(ByteSource&)> after,
                    LasFieldSink sink)
      : src_(std::move(src)),
        records_(records),
        data_start_(data_start),
        stride_(stride),
        format_(format),
        returns_(options.las_returns),
        after_(std::move(after)),
        sink_(std::move(sink)) {
    format_name_ = std::move(format_name);
    source_name_ = src_->name();
    for (int c = 0; c < 3; ++c) scale_[c] = scale[c], offset_[c] = offset[c];
    for (auto c : options.las_classes) classes_[c] = true;
    any_class_ = options.las_classes.empty();
    filters_ = options.las_identity();
    if (!filters_.empty()) filters_.erase(0, 1);
  }

  std::size_t read(double* xyz, std::size_t max_points) override {
    std::size_t n = 0;
    kept_.clear();
    while (n < max_points && record_ < records_) {
      if (src_->available() < stride_ && src_->ensure(stride_) < stride_) {
        throw InputError::at_byte(source_name_, data_start_ + record_ * stride_,
                                  "truncated: input ends after " + std::to_string(record_) +
                                      " point records, but the header promises " + std::to_string(records_));
      }
      const std::size_t k = std::size_t(std::min<std::uint64_t>(records_ - record_, src_->available() / stride_));
      const char* r = src_->data();
      std::size_t i = 0;
      for (; i < k && n < max_points; ++i, r += stride_) {
        const LasFields f = las_fields_of(r, format_);
        if (!keep(f)) continue;
        for (int c = 0; c < 3; ++c)
          xyz[3 * n + c] = scaled(double(le_at<std::int32_t>(r + 4 * c)), c, scale_, offset_, rounded_);
        if (sink_) sink_(f);
        kept_.push_back(record_ + i);
        ++n;
      }
      src_->consume(i * stride_);
      record_ += i;
    }
    check_finite(xyz, n, source_name_, [&](std::size_t i) { return record_location(kept_[i / 3]); });
    points_read_ += n;
    if (record_ == records_ && !tail_checked_) {
      tail_checked_ = true;
      after_(*src_);
      if (points_read_ == 0) {
        throw InputError(source_name_ + ": none of its " + std::to_string(records_) + " points passes the filter (" +
                         filters_ + "): no points");
      }
    }
    return n;
  }

  std::uint64_t bytes_read() const override { return src_->offset(); }
  std::optional<std::uint64_t> source_size() const override { return src_->size(); }
  // The points of the last read() by their record; older ones by their index.
  std::string location(std::uint64_t index) const override {
    const std::uint64_t first = points_read_ - kept_.size();
    if (index >= first && index < points_read_) return record_location(kept_[std::size_t(index - first)]);
    return "point " + std::to_string(index) + " (after the filter " + filters_ + ")";
  }
  std::vector<std::pair<std::string, std::string>> details() const override {
    std::vector<std::pair<std::string, std::string>> d = {
        {"scale", triple(scale_)}, {"offset", triple(offset_)}, {"exact", exactness(rounded_, points_read_)}};
    if (!filters_.empty()) {
      d.emplace_back(
          "filter", filters_ + ": " + std::to_string(points_read_) + " of " + std::to_string(record_) + " points kept");
    }
    return d;
  }

 private:
  bool keep(const LasFields& f) const {
    if (!any_class_ && !classes_[f.classification]) return false;
    switch (returns_) {
      case PointReadOptions::LasReturns::kAll:
        return true;
      case PointReadOptions::LasReturns::kFirst:
        return f.return_number == 1;
      case PointReadOptions::LasReturns::kLast:
        return f.return_number == f.number_of_returns;
    }
    return true;
  }
  std::string record_location(std::uint64_t record) const {
    return "byte " + std::to_string(data_start_ + record * stride_);
  }

  std::unique_ptr<ByteSource> src_;
  std::uint64_t records_, data_start_;
  std::size_t stride_;
  int format_;
  double scale_[3], offset_[3];
  bool classes_[256] = {};
  bool any_class_ = true;
  PointReadOptions::LasReturns returns_;
  std::string filters_;
  std::function<void(ByteSource&)> after_;
  LasFieldSink sink_;
  std::uint64_t record_ = 0, rounded_ = 0;
  std::vector<std::uint64_t> kept_;  // record index of each point of the last read()
  bool tail_checked_ = false;
};

[[noreturn]] void laz(const std::string& file, const std::string& where) {
  throw InputError(file + ": " + where +
                   "LAZ (compressed LAS) needs LASzip, which Debian does not ship: decompress it first "
                   "(e.g. 'laszip -i in.laz -o out.las' or 'pdal translate in.laz out.las' on another machine)");
}

}  // namespace

std::unique_ptr<PointReader> open_las(std::unique_ptr<ByteSource> src, const PointReadOptions& options,
                                      LasFieldSink sink) {
  const std::string file = src->name();
  const auto dot = file.find_last_of('.');
  if (dot != std::string::npos && (file.substr(dot) == ".laz" || file.substr(dot) == ".LAZ")) laz(file, "");
  if (src->ensure(375) == 0) throw InputError::at_byte(file, 0, "empty file: no points");
  if (src->available() < 4 || std::memcmp(src->data(), "LASF", 4) != 0)
    throw InputError::at_byte(file, 0, "not a LAS file: it does not start with 'LASF'");
  if (src->available() < 227)
    throw InputError::at_byte(file, src->available(),
                              "truncated LAS header (" + std::to_string(src->available()) + " of 227 bytes)");
  const char* h = src->data();
  const int major = std::uint8_t(h[24]), minor = std::uint8_t(h[25]);
  if (major != 1 || minor > 4)
    throw InputError::at_byte(
        file, 24, "unsupported LAS version " + std::to_string(major) + "." + std::to_string(minor) + " (1.0-1.4)");
  const std::uint16_t header_size = le_at<std::uint16_t>(h + 94);
  const std::uint32_t data_offset = le_at<std::uint32_t>(h + 96);
  const std::uint8_t format_id = std::uint8_t(h[104]);
  const std::uint16_t record_length = le_at<std::uint16_t>(h + 105);
  const std::uint16_t need = minor >= 4 ? 375 : minor == 3 ? 235 : 227;
  if (header_size < need) {
    throw InputError::at_byte(file, 94,
                              "header size " + std::to_string(header_size) + " is less than the " +
                                  std::to_string(need) + " bytes of a LAS 1." + std::to_string(minor) + " header");
  }
  if (src->available() < need)
    throw InputError::at_byte(
        file, src->available(),
        "truncated LAS header (" + std::to_string(src->available()) + " of " + std::to_string(need) + " bytes)");
  if (data_offset < header_size)
    throw InputError::at_byte(file, 96,
                              "offset to point data " + std::to_string(data_offset) + " lies inside the " +
                                  std::to_string(header_size) + "-byte header");
  if (format_id & 0xC0) laz(file, "byte 104: ");
  if (format_id > 10)
    throw InputError::at_byte(file, 104, "unknown point data format " + std::to_string(format_id) + " (0-10)");
  if (record_length < kMinRecord[format_id]) {
    throw InputError::at_byte(file, 105,
                              "record length " + std::to_string(record_length) + " is shorter than the " +
                                  std::to_string(kMinRecord[format_id]) + " bytes of point format " +
                                  std::to_string(format_id));
  }
  // The point count: 1.4 has a 64-bit field; the legacy 32-bit one must then be 0 or agree.
  std::uint64_t count = le_at<std::uint32_t>(h + 107);
  if (minor >= 4) {
    const std::uint64_t count64 = le_at<std::uint64_t>(h + 247);
    if (count64 != 0 && count != 0 && count != count64) {
      throw InputError::at_byte(file, 107,
                                "the header's point counts disagree: legacy " + std::to_string(count) + ", 64-bit " +
                                    std::to_string(count64));
    }
    if (count64 != 0) count = count64;
  }
  double scale[3], offset[3];
  for (int c = 0; c < 3; ++c) {
    scale[c] = le_at<double>(h + 131 + 8 * c);
    offset[c] = le_at<double>(h + 155 + 8 * c);
    if (!std::isfinite(scale[c]) || scale[c] == 0)
      throw InputError::at_byte(
          file, 131 + 8 * c,
          std::string(1, "xyz"[c]) + " scale " + shortest(scale[c]) + " is not a finite non-zero number");
    if (!std::isfinite(offset[c]))
      throw InputError::at_byte(file, 155 + 8 * c, std::string(1, "xyz"[c]) + " offset is not finite");
  }
  // What may follow the points: waveform packets (1.3+) and extended VLRs (1.4).
  std::uint64_t accounted = 0;
  if (minor >= 3) accounted = le_at<std::uint64_t>(h + 227);
  if (minor >= 4) {
    const std::uint64_t evlr = le_at<std::uint64_t>(h + 235);
    if (evlr != 0 && (accounted == 0 || evlr < accounted)) accounted = evlr;
  }
  if (src->skip(data_offset) < data_offset)
    throw InputError::at_byte(file, src->offset(),
                              "truncated: the file ends before the point data at byte " + std::to_string(data_offset));

  BinaryLayout layout;
  layout.data_start = data_offset;
  layout.stride = record_length;
  for (int c = 0; c < 3; ++c) {
    layout.offset[c] = 4 * std::uint64_t(c);
    layout.type[c] = Scalar::kI32;
  }
  layout.big_endian = false;
  layout.record = "point record";
  layout.records = "point records";
  layout.tail = BinaryLayout::Tail::kChecked;
  // Bytes after the points that no header field accounts for: the format has room for
  // extra data, so a warning, not an error.
  layout.after = [accounted, file](ByteSource& s) {
    const std::uint64_t end = s.offset();
    if (accounted >= end || s.at_end()) return;
    const std::string amount = s.size() ? std::to_string(*s.size() - end) + " bytes" : "data";
    spdlog::warn("{}: byte {}: {} after the point records that the header does not account for (ignored)", file, end,
                 amount);
  };
  const std::string name =
      "las " + std::to_string(major) + "." + std::to_string(minor) + " point format " + std::to_string(format_id);
  if (options.las_filtered() || sink) {
    // The checks make_binary_reader does for the unfiltered reader, before any work.
    std::uint64_t bytes = 0;
    if (!checked_mul(count, record_length, bytes) || !checked_add(bytes, data_offset, bytes))
      throw InputError::at_byte(
          file, 107, "the header declares " + std::to_string(count) + " point records: more than any file can hold");
    if (count == 0) throw InputError::at_byte(file, data_offset, "the header declares 0 point records: no points");
    if (src->size() && *src->size() < bytes) {
      throw InputError::at_byte(file, *src->size(),
                                "truncated: the header promises " + std::to_string(count) + " point records of " +
                                    std::to_string(record_length) + " bytes from byte " + std::to_string(data_offset));
    }
    return std::make_unique<LasFilteredReader>(std::move(src), count, data_offset, record_length, format_id, scale,
                                               offset, name, options, std::move(layout.after), std::move(sink));
  }
  auto records = make_binary_reader(std::move(src), layout, count, /*promised=*/true, name);
  return std::make_unique<LasPointReader>(std::move(records), scale, offset, name);
}

}  // namespace tetstream::io::detail
