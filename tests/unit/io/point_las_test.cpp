// The LAS reader against files written here byte by byte (a small LAS writer that follows
// the ASPRS layout): every point data record format 0-10 with its own record length (and
// extra bytes), versions 1.2, 1.3 and 1.4 headers (legacy and 64-bit counts), VLRs before
// the points, scale and offset, and bad, lying or truncated headers; LAZ is refused.
#include "io/point_reader.hpp"
#include "point_files.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <string>
#include <vector>

using namespace tetstream;
using namespace tetstream::io;

namespace {

constexpr std::uint16_t kMinRecord[11] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};

struct LasFile {
  int minor = 2;
  int format = 0;
  int record_length = 0;  // 0: the format's minimum
  double scale[3] = {0.01, 0.01, 0.01};
  double offset[3] = {0, 0, 0};
  std::vector<std::array<std::int32_t, 3>> points;
  int vlr_payload = 0;  // bytes of one VLR's payload between header and points (0: no VLR)
  // Header fields overridden when set (for lying headers).
  std::optional<std::uint32_t> legacy_count;
  std::optional<std::uint64_t> count64;
  std::optional<std::uint16_t> header_size;
  std::string trailing;  // bytes after the points
  // Per point (when given): return number, number of returns, classification, intensity.
  struct Fields {
    int return_number, returns, classification, intensity;
  };
  std::vector<Fields> fields;
};

template <class T>
void put(std::string& s, std::size_t at, T v) {
  const std::string b = le_bytes(v);
  s.replace(at, b.size(), b);
}

std::string las_bytes(const LasFile& f) {
  const std::uint16_t header = f.minor >= 4 ? 375 : f.minor == 3 ? 235 : 227;
  const std::uint16_t length = std::uint16_t(f.record_length ? f.record_length : kMinRecord[f.format]);
  const std::uint32_t vlr = f.vlr_payload ? 54 + f.vlr_payload : 0;
  const std::uint32_t data_offset = header + vlr;
  std::string s(header, '\0');
  s.replace(0, 4, "LASF");
  s[24] = 1;
  s[25] = char(f.minor);
  s.replace(26, 8, "tetstrm!");
  put<std::uint16_t>(s, 94, f.header_size.value_or(header));
  put<std::uint32_t>(s, 96, data_offset);
  put<std::uint32_t>(s, 100, f.vlr_payload ? 1 : 0);
  s[104] = char(f.format);
  put<std::uint16_t>(s, 105, length);
  const std::uint64_t n = f.points.size();
  const bool legacy_ok = f.format < 6 && n <= 0xffffffffu;
  put<std::uint32_t>(s, 107, f.legacy_count.value_or(f.minor < 4 || legacy_ok ? std::uint32_t(n) : 0));
  for (int c = 0; c < 3; ++c) {
    put<double>(s, 131 + 8 * c, f.scale[c]);
    put<double>(s, 155 + 8 * c, f.offset[c]);
  }
  if (f.minor >= 4) put<std::uint64_t>(s, 247, f.count64.value_or(n));
  if (f.vlr_payload) {
    std::string v(54, '\0');
    v.replace(2, 9, "LASF_Spec");
    put<std::uint16_t>(v, 20, std::uint16_t(f.vlr_payload));
    s += v + std::string(std::size_t(f.vlr_payload), '\x5a');
  }
  for (const auto& p : f.points) {
    std::string r(length, '\xab');  // every other field: noise the reader must skip
    for (int c = 0; c < 3; ++c) put<std::int32_t>(r, 4 * std::size_t(c), p[c]);
    if (!f.fields.empty()) {
      // ASPRS layout: formats 0-5 pack the returns in 3 + 3 bits of byte 14 and the class
      // in bits 0-4 of byte 15 (bits 5-7: flags, set here as noise); 6-10 use 4 + 4 bits
      // and a whole class byte at 16.
      const auto& q = f.fields[std::size_t(&p - f.points.data())];
      put<std::uint16_t>(r, 12, std::uint16_t(q.intensity));
      if (f.format < 6) {
        r[14] = char(q.return_number | q.returns << 3);
        r[15] = char(q.classification | 0xE0);
      } else {
        r[14] = char(q.return_number | q.returns << 4);
        r[16] = char(q.classification);
      }
    }
    s += r;
  }
  return s + f.trailing;
}

const std::vector<std::array<std::int32_t, 3>> kPoints = {
    {0, 0, 0}, {100, -200, 300}, {2147483647, -2147483647 - 1, 12345}, {-1, 1, -1}};

std::vector<double> expected(const LasFile& f) {
  std::vector<double> v;
  for (const auto& p : f.points)
    for (int c = 0; c < 3; ++c) v.push_back(double(p[c]) * f.scale[c] + f.offset[c]);
  return v;
}

std::string detail(const PointReader& r, const std::string& label) {
  for (const auto& [k, v] : r.details())
    if (k == label) return v;
  return "";
}

}  // namespace

TEST(PointLas, EveryPointFormatAndVersion) {
  TempDir dir;
  for (int format = 0; format <= 10; ++format) {
    for (int minor : {2, 3, 4}) {
      for (int extra : {0, 7}) {
        LasFile f;
        f.minor = minor, f.format = format;
        f.points.insert(f.points.end(), kPoints.begin(), kPoints.end());
        f.record_length = kMinRecord[format] + extra;
        f.scale[0] = 0.01, f.scale[1] = 0.5, f.scale[2] = 1e-7;
        f.offset[0] = 1000, f.offset[1] = -2.5, f.offset[2] = 6e5;
        f.vlr_payload = extra ? 13 : 0;
        std::string name = "f";  // (built by appending: GCC 12 warns on "f" + std::string)
        name += std::to_string(format) + "_" + std::to_string(minor) + ".las";
        const std::string path = dir.file(name);
        write_bytes(path, las_bytes(f));
        EXPECT_EQ(read_all(path), expected(f)) << "format " << format << " version 1." << minor << " extra " << extra;
        expect_skip_is_read_and_drop(path);  // seeking past whole records
      }
    }
  }
}

TEST(PointLas, HeaderNamesAndCounts) {
  TempDir dir;
  LasFile f;
  f.minor = 4, f.format = 6, f.points = kPoints;
  write_bytes(dir.file("a.las"), las_bytes(f));
  auto r = open_points(dir.file("a.las"));
  EXPECT_EQ(r->format_name(), "las 1.4 point format 6");
  ASSERT_TRUE(r->count());
  EXPECT_EQ(*r->count(), kPoints.size());
  EXPECT_EQ(r->location(1), "byte " + std::to_string(375 + 30));
  // 1.4 with only the legacy count (formats 0-5 may carry it): read.
  f.format = 1, f.count64 = 0;
  write_bytes(dir.file("legacy.las"), las_bytes(f));
  EXPECT_EQ(read_all(dir.file("legacy.las")), expected(f));
  // Sniffed without the extension.
  write_bytes(dir.file("noext"), las_bytes(f));
  EXPECT_EQ(read_all(dir.file("noext")), expected(f));
}

TEST(PointLas, ExactnessOfTheConversionIsReported) {
  TempDir dir;
  LasFile f;
  f.points = kPoints;
  f.scale[0] = f.scale[1] = f.scale[2] = 0.25;  // a power of two: X * s is exact
  f.offset[0] = 1024, f.offset[1] = -3, f.offset[2] = 0.5;
  write_bytes(dir.file("exact.las"), las_bytes(f));
  {
    auto r = open_points(dir.file("exact.las"));
    std::vector<double> buf(3 * 16);
    while (r->read(buf.data(), 16)) {
    }
    EXPECT_EQ(detail(*r, "exact").substr(0, 3), "yes");
    EXPECT_EQ(detail(*r, "scale"), "0.25 0.25 0.25");
    EXPECT_EQ(detail(*r, "offset"), "1024 -3 0.5");
  }
  f.scale[0] = f.scale[1] = f.scale[2] = 0.01;  // 100 * 0.01 rounds
  write_bytes(dir.file("inexact.las"), las_bytes(f));
  auto r = open_points(dir.file("inexact.las"));
  std::vector<double> buf(3 * 16);
  while (r->read(buf.data(), 16)) {
  }
  EXPECT_EQ(detail(*r, "exact").substr(0, 2), "no");
}

TEST(PointLas, BadHeaders) {
  TempDir dir;
  LasFile good;
  good.minor = 4, good.format = 7, good.points = kPoints;
  const std::string bytes = las_bytes(good);
  auto with = [&](const std::string& name, std::string b) {
    write_bytes(dir.file(name), b);
    return dir.file(name);
  };
  EXPECT_INPUT_ERROR(with("trunc_header.las", bytes.substr(0, 200)), PointReadOptions{}, "byte 200",
                     "truncated LAS header");
  EXPECT_INPUT_ERROR(with("trunc14.las", bytes.substr(0, 300)), PointReadOptions{}, "byte 300", "of 375 bytes");
  EXPECT_INPUT_ERROR(with("trunc_points.las", bytes.substr(0, bytes.size() - 5)), PointReadOptions{}, "byte",
                     "truncated");
  std::string b = bytes;
  b[0] = 'X';
  EXPECT_INPUT_ERROR(with("magic.las", b), PointReadOptions{}, "byte 0", "not a LAS file");
  b = bytes;
  b[25] = 5;
  EXPECT_INPUT_ERROR(with("version.las", b), PointReadOptions{}, "byte 24", "unsupported LAS version 1.5");
  b = bytes;
  b[104] = 11;
  EXPECT_INPUT_ERROR(with("format.las", b), PointReadOptions{}, "byte 104", "unknown point data format 11");
  b = bytes;
  put<std::uint16_t>(b, 105, 20);
  EXPECT_INPUT_ERROR(with("short_record.las", b), PointReadOptions{}, "byte 105", "shorter than the 36 bytes");
  b = bytes;
  put<std::uint16_t>(b, 94, 227);
  EXPECT_INPUT_ERROR(with("header_size.las", b), PointReadOptions{}, "byte 94", "less than the 375 bytes");
  b = bytes;
  put<std::uint32_t>(b, 96, 100);
  EXPECT_INPUT_ERROR(with("data_offset.las", b), PointReadOptions{}, "byte 96", "inside the 375-byte header");
  b = bytes;
  put<double>(b, 139, 0.0);
  EXPECT_INPUT_ERROR(with("scale.las", b), PointReadOptions{}, "byte 139", "y scale 0");
  LasFile lie = good;
  lie.format = 1, lie.legacy_count = 3;  // legacy 3, 64-bit 4
  EXPECT_INPUT_ERROR(with("counts.las", las_bytes(lie)), PointReadOptions{}, "byte 107", "point counts disagree");
  lie.legacy_count = 0;
  lie.count64 = 1000;  // more than the file holds
  EXPECT_INPUT_ERROR(with("many.las", las_bytes(lie)), PointReadOptions{}, "byte", "the header promises 1000");
  lie.count64 = 0;
  lie.legacy_count = 0;
  EXPECT_INPUT_ERROR(with("none.las", las_bytes(lie)), PointReadOptions{}, "byte", "no points");
}

TEST(PointLas, CompressedLazIsRefusedWithAdvice) {
  TempDir dir;
  LasFile f;
  f.points = kPoints;
  std::string b = las_bytes(f);
  b[104] = char(0x80 | 3);  // LASzip sets bit 7 of the point format
  write_bytes(dir.file("c.las"), b);
  EXPECT_INPUT_ERROR(dir.file("c.las"), PointReadOptions{}, "byte 104", "LASzip, which Debian does not ship");
  write_bytes(dir.file("c.laz"), las_bytes(f));
  EXPECT_INPUT_ERROR(dir.file("c.laz"), PointReadOptions{}, "c.laz", "decompress it first");
}

TEST(PointLas, DataAfterThePointsIsAllowed) {
  // Waveform packets and extended VLRs may follow the points: the format allows data
  // there, so the reader warns (when no header field accounts for it) and reads on.
  TempDir dir;
  LasFile f;
  f.minor = 4, f.format = 6, f.points = kPoints, f.trailing.assign(60, '\x01');
  write_bytes(dir.file("evlr.las"), las_bytes(f));
  EXPECT_EQ(read_all(dir.file("evlr.las")), expected(f));
}

// --las-classes and --las-returns: the points kept, in file order, for the old and the
// new record layouts; the count is known only at the end; a filter that keeps nothing,
// and one given for another format, are refused.
TEST(PointLas, ClassAndReturnFilters) {
  TempDir dir;
  // Six points: (return number, number of returns, class, intensity).
  const std::vector<LasFile::Fields> fields = {{1, 1, 2, 10}, {1, 3, 5, 11}, {3, 3, 2, 12},
                                               {2, 3, 6, 13}, {1, 2, 6, 14}, {2, 2, 1, 15}};
  std::vector<std::array<std::int32_t, 3>> points;
  for (int i = 0; i < 6; ++i) points.push_back({i, 10 * i, 100 * i});
  auto pick = [&](const LasFile& f, std::vector<int> which) {
    std::vector<double> v;
    for (int i : which)
      for (int c = 0; c < 3; ++c) v.push_back(double(f.points[std::size_t(i)][c]) * f.scale[c] + f.offset[c]);
    return v;
  };
  using R = PointReadOptions::LasReturns;
  for (int format : {0, 3, 6, 10}) {
    LasFile f;
    f.minor = format >= 6 ? 4 : 2, f.format = format, f.points = points, f.fields = fields;
    std::string name = "filter";  // (appended: GCC 12 warns on "f" + std::string)
    name += std::to_string(format) + ".las";
    const std::string path = dir.file(name);
    write_bytes(path, las_bytes(f));
    std::string what = "format ";
    what += std::to_string(format);
    EXPECT_EQ(read_all(path), expected(f)) << what;
    PointReadOptions o;
    o.las_classes = {2, 6};
    EXPECT_EQ(read_all(path, o), pick(f, {0, 2, 3, 4})) << what;
    expect_skip_is_read_and_drop(path, o);
    o.las_returns = R::kLast;
    EXPECT_EQ(read_all(path, o), pick(f, {0, 2})) << what;
    o.las_classes.clear();
    EXPECT_EQ(read_all(path, o), pick(f, {0, 2, 5})) << what;
    o.las_returns = R::kFirst;
    EXPECT_EQ(read_all(path, o), pick(f, {0, 1, 4})) << what;
    // The count is not known up front; the details say what the filter kept.
    auto r = open_points(path, o);
    EXPECT_FALSE(r->count()) << what;
    std::vector<double> buf(3 * 8);
    while (r->read(buf.data(), 2)) {
    }
    EXPECT_EQ(r->points_read(), 3u);
    EXPECT_EQ(detail(*r, "filter"), "las_returns=first: 3 of 6 points kept") << what;
    o.las_returns = R::kAll;
    o.las_classes = {9};
    EXPECT_INPUT_ERROR(path, o, ".las", "passes the filter (las_classes=9)");
  }
  // Part of the job's identity, and only when set (older jobs keep theirs).
  PointReadOptions o;
  const std::string plain = o.identity();
  EXPECT_EQ(plain.find("las"), std::string::npos);
  o.las_classes = {2, 6};
  o.las_returns = R::kLast;
  EXPECT_EQ(o.identity(), plain + " las_classes=2,6 las_returns=last");
  // A filter on another format is a usage error, not silently ignored.
  write_bytes(dir.file("p.f64"), std::string(48, '\0'));
  EXPECT_THROW(open_points(dir.file("p.f64"), o), UsageError);
  // Truncated records are still found with a filter.
  LasFile f;
  f.points = points, f.fields = fields;
  const std::string bytes = las_bytes(f);
  write_bytes(dir.file("t.las"), bytes.substr(0, bytes.size() - 3));
  EXPECT_INPUT_ERROR(dir.file("t.las"), o, "byte", "truncated");
}
