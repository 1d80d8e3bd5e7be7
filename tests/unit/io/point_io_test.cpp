// Point readers and writers: bit-exact round trips through every writer, the layouts
// the readers must accept (stride/offset, PLY extras, npy versions, text variants), and
// one test per class of bad input, checking the one-line message names file and place.
#include "io/point_reader.hpp"
#include "io/point_writer.hpp"
#include "io/point_generators.hpp"
#include "point_files.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace tetstream;
using namespace tetstream::io;

namespace {

bool same_bits(double a, double b) { return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b); }

// Awkward doubles: zeros of both signs, subnormals, extremes, values with 17 digits.
std::vector<double> tricky_points() {
  std::vector<double> v = {0.0,
                           -0.0,
                           0.1,
                           1.0 / 3.0,
                           -2.5,
                           5e-324,
                           -2.2250738585072014e-308,
                           1.7976931348623157e308,
                           -1e-300,
                           123456789.123456789,
                           3.141592653589793,
                           1e22};
  std::mt19937_64 rng(42);
  while (v.size() < 3 * 1000) {
    const double x = std::bit_cast<double>(rng());
    if (std::isfinite(x)) v.push_back(x);
  }
  return v;
}

struct WriterCase {
  const char* name;
  const char* file;
  PointWriteOptions opt;
  bool f32;
};

std::vector<WriterCase> writer_cases() {
  std::vector<WriterCase> c;
  auto add = [&](const char* name, const char* file, PointFormat f, ScalarType t, ByteOrder o, bool ascii) {
    PointWriteOptions w;
    w.format = f, w.type = t, w.byte_order = o, w.ascii = ascii;
    c.push_back({name, file, w, t == ScalarType::kFloat32});
  };
  add("raw f64", "p.f64", PointFormat::kAuto, ScalarType::kAuto, ByteOrder::kLittle, false);
  add("raw f32", "p.f32", PointFormat::kAuto, ScalarType::kFloat32, ByteOrder::kLittle, false);
  add("raw f64 big", "p.bin", PointFormat::kRaw, ScalarType::kFloat64, ByteOrder::kBig, false);
  add("raw f32 big", "p.raw", PointFormat::kRaw, ScalarType::kFloat32, ByteOrder::kBig, false);
  add("ply le", "p.ply", PointFormat::kAuto, ScalarType::kAuto, ByteOrder::kLittle, false);
  add("ply be", "p.ply", PointFormat::kPly, ScalarType::kAuto, ByteOrder::kBig, false);
  add("ply f32", "p.ply", PointFormat::kPly, ScalarType::kFloat32, ByteOrder::kLittle, false);
  add("ply ascii", "p.ply", PointFormat::kPly, ScalarType::kAuto, ByteOrder::kLittle, true);
  add("npy f8", "p.npy", PointFormat::kAuto, ScalarType::kAuto, ByteOrder::kLittle, false);
  add("npy >f8", "p.npy", PointFormat::kNpy, ScalarType::kAuto, ByteOrder::kBig, false);
  add("npy f4", "p.npy", PointFormat::kNpy, ScalarType::kFloat32, ByteOrder::kLittle, false);
  add("text", "p.txt", PointFormat::kAuto, ScalarType::kAuto, ByteOrder::kLittle, false);
  add("csv", "p.csv", PointFormat::kAuto, ScalarType::kAuto, ByteOrder::kLittle, false);
  add("xyz", "p.xyz", PointFormat::kAuto, ScalarType::kAuto, ByteOrder::kLittle, false);
  return c;
}

}  // namespace

TEST(PointIo, EveryWriterRoundTripsBitExact) {
  const std::vector<double> all = tricky_points();
  // float32 outputs get the values float can hold (the rest would overflow to inf).
  std::vector<double> small = all;
  for (double& v : small) {
    if (!std::isfinite(static_cast<float>(v))) v = std::fmod(v, 1e30);
  }
  const std::size_t n = all.size() / 3;
  for (const auto& wc : writer_cases()) {
    const std::vector<double>& pts = wc.f32 ? small : all;
    for (bool known_count : {true, false}) {
      SCOPED_TRACE(std::string(wc.name) + (known_count ? "" : " (count patched at commit)"));
      TempDir dir;
      const std::string path = dir.file(wc.file);
      {
        auto w = create_points(path, wc.opt, known_count ? n : PointWriter::kUnknownCount);
        // Uneven chunks.
        for (std::size_t i = 0; i < n;) {
          const std::size_t k = std::min<std::size_t>(n - i, 1 + i % 97);
          w->write(pts.data() + 3 * i, k);
          i += k;
        }
        w->commit();
        EXPECT_FALSE(fs::exists(path + ".partial"));
      }
      PointReadOptions ro;
      if (wc.opt.format == PointFormat::kRaw) ro.format = PointFormat::kRaw, ro.type = wc.opt.type;
      if (wc.opt.format == PointFormat::kRaw) ro.byte_order = wc.opt.byte_order;
      const std::vector<double> back = read_all(path, ro, 13);
      ASSERT_EQ(back.size(), pts.size());
      for (std::size_t i = 0; i < pts.size(); ++i) {
        const double want = wc.f32 ? double(static_cast<float>(pts[i])) : pts[i];
        ASSERT_TRUE(same_bits(back[i], want)) << "coordinate " << i << ": " << back[i] << " vs " << want;
      }
    }
  }
}

TEST(PointIo, CountAndFormatName) {
  TempDir dir;
  const std::vector<double> pts = {1, 2, 3, 4, 5, 6};
  for (const char* f : {"a.f64", "a.ply", "a.npy", "a.txt"}) {
    auto w = create_points(dir.file(f), {}, 2);
    w->write(pts.data(), 2);
    w->commit();
  }
  EXPECT_EQ(open_points(dir.file("a.f64"))->count(), 2u);
  EXPECT_EQ(open_points(dir.file("a.ply"))->count(), 2u);
  EXPECT_EQ(open_points(dir.file("a.npy"))->count(), 2u);
  EXPECT_FALSE(open_points(dir.file("a.txt"))->count().has_value());
  EXPECT_EQ(open_points(dir.file("a.f64"))->format_name(), "raw f64 little-endian");
  EXPECT_EQ(open_points(dir.file("a.ply"))->format_name(), "ply binary_little_endian");
  EXPECT_EQ(open_points(dir.file("a.npy"))->format_name(), "npy <f8");
  EXPECT_EQ(open_points(dir.file("a.txt"))->format_name(), "text");
  EXPECT_EQ(open_points(dir.file("a.txt"))->source_name(), dir.file("a.txt"));
  // Unknown extension: PLY and npy are recognised by their magic, text by its bytes.
  fs::copy_file(dir.file("a.ply"), dir.file("a.dat"));
  EXPECT_EQ(open_points(dir.file("a.dat"))->format_name(), "ply binary_little_endian");
  fs::copy_file(dir.file("a.txt"), dir.file("b.dat"));
  EXPECT_EQ(open_points(dir.file("b.dat"))->format_name(), "text");
  // Raw cannot be recognised: a usage error asking for --format.
  fs::copy_file(dir.file("a.f64"), dir.file("c.dat"));
  EXPECT_THROW(open_points(dir.file("c.dat")), UsageError);
  PointReadOptions f64;
  parse_format_name("f64", f64.format, f64.type);
  EXPECT_EQ(read_all(dir.file("c.dat"), f64), pts);
}

TEST(PointIo, RawStrideOffsetAndByteOrder) {
  TempDir dir;
  // 40-byte records: int64 id, x y z as big-endian doubles at offset 8, 8 bytes of colour.
  std::string bytes;
  std::vector<double> want;
  for (int i = 0; i < 500; ++i) {
    bytes += le_bytes<std::int64_t>(i);
    for (int c = 0; c < 3; ++c) {
      const double v = i * 10.0 + c + 0.25;
      want.push_back(v);
      bytes += be_bytes(v);
    }
    bytes += "RGBA1234";
  }
  write_bytes(dir.file("dump.bin"), bytes);
  PointReadOptions o;
  o.stride = 40, o.offset = 8, o.byte_order = ByteOrder::kBig;
  EXPECT_EQ(read_all(dir.file("dump.bin"), o), want);
  auto r = open_points(dir.file("dump.bin"), o);
  EXPECT_EQ(r->count(), 500u);
  EXPECT_EQ(r->location(3), "byte 128");  // x of record 3 = 3 * 40 + 8
  // Offset + 24 > stride is a usage error.
  o.offset = 20;
  EXPECT_THROW(open_points(dir.file("dump.bin"), o), UsageError);
}

TEST(PointIo, PlyExtrasAreSkipped) {
  TempDir dir;
  // A face element (with a list) before vertex, mixed-type vertex properties, comments,
  // obj_info, and an element after vertex.
  auto header = [](const char* enc) {
    return std::string("ply\nformat ") + enc +
           " 1.0\ncomment made by hand\nobj_info test\n"
           "element face 2\nproperty list uchar int vertex_indices\nproperty uchar flag\n"
           "element vertex 3\nproperty uchar red\nproperty float x\nproperty int y\n"
           "property double nx\nproperty double z\nproperty short s\n"
           "element edge 1\nproperty int a\nproperty int b\nend_header\n";
  };
  const std::vector<double> want = {1.5, -2, 3.25, 4.5, 5, -6.75, 0.125, 8, 9.5};
  for (bool big : {false, true}) {
    auto put = [&](auto v) { return big ? be_bytes(v) : le_bytes(v); };
    std::string s = header(big ? "binary_big_endian" : "binary_little_endian");
    s += put((std::uint8_t)3) + put((std::int32_t)0) + put((std::int32_t)1) + put((std::int32_t)2) +
         put((std::uint8_t)7);
    s += put((std::uint8_t)4) + put((std::int32_t)0) + put((std::int32_t)1) + put((std::int32_t)2) +
         put((std::int32_t)3) + put((std::uint8_t)9);
    for (int i = 0; i < 3; ++i) {
      s += put((std::uint8_t)200) + put((float)float(want[3 * i])) + put((std::int32_t)std::int32_t(want[3 * i + 1])) +
           put((double)42.0) + put((double)want[3 * i + 2]) + put((std::int16_t)-1);
    }
    s += put((std::int32_t)0) + put((std::int32_t)1);
    const std::string path = dir.file(big ? "be.ply" : "le.ply");
    write_bytes(path, s);
    EXPECT_EQ(read_all(path), want) << path;
  }
  std::string a = header("ascii");
  a += "3 0 1 2 7\n4 0 1 2 3 9\n";
  a += "200 1.5 -2 42 3.25 -1\n200 4.5 5 42 -6.75 -1\n\n200 0.125 8 42 9.5 -1\n0 1\n";
  write_bytes(dir.file("a.ply"), a);
  EXPECT_EQ(read_all(dir.file("a.ply")), want);
}

TEST(PointIo, NpyVersionsAndDtypes) {
  TempDir dir;
  const std::vector<double> want = {1, 2, 3, -4, 5.5, 6};
  std::string le8, be8, le4;
  for (double v : want) le8 += le_bytes(v), be8 += be_bytes(v), le4 += le_bytes(float(v));
  write_bytes(dir.file("v1.npy"), npy_bytes(1, "<f8", "(2, 3)", le8));
  write_bytes(dir.file("v2.npy"), npy_bytes(2, ">f8", "(2,3)", be8));
  write_bytes(dir.file("v3.npy"), npy_bytes(3, "<f4", "(2, 3)", le4));
  for (const char* f : {"v1.npy", "v2.npy", "v3.npy"}) EXPECT_EQ(read_all(dir.file(f)), want) << f;

  // Bad headers: shape, order, dtype.
  write_bytes(dir.file("shape4.npy"), npy_bytes(1, "<f8", "(1, 4)", le8.substr(0, 32)));
  EXPECT_INPUT_ERROR(dir.file("shape4.npy"), PointReadOptions{}, "byte 10", "not (N, 3)");
  write_bytes(dir.file("shape1.npy"), npy_bytes(1, "<f8", "(6,)", le8));
  EXPECT_INPUT_ERROR(dir.file("shape1.npy"), PointReadOptions{}, "byte 10", "not (N, 3)");
  write_bytes(dir.file("fortran.npy"), npy_bytes(1, "<f8", "(2, 3)", le8, "True"));
  EXPECT_INPUT_ERROR(dir.file("fortran.npy"), PointReadOptions{}, "byte 10", "fortran_order");
  write_bytes(dir.file("int.npy"), npy_bytes(1, "<i4", "(2, 3)", le8));
  EXPECT_INPUT_ERROR(dir.file("int.npy"), PointReadOptions{}, "byte 10", "unsupported dtype");
  write_bytes(dir.file("zero.npy"), npy_bytes(1, "<f8", "(0, 3)", ""));
  EXPECT_INPUT_ERROR(dir.file("zero.npy"), PointReadOptions{}, "byte 128", "no points");
  write_bytes(dir.file("short.npy"), npy_bytes(1, "<f8", "(3, 3)", le8));  // header promises 3 rows, 2 present
  EXPECT_INPUT_ERROR(dir.file("short.npy"), PointReadOptions{}, "byte 176", "truncated");
  write_bytes(dir.file("magic.npy"), "\x93NUMPX" + std::string(100, ' '));
  EXPECT_INPUT_ERROR(dir.file("magic.npy"), PointReadOptions{}, "byte 0", "not a .npy file");
}

TEST(PointIo, TextVariants) {
  TempDir dir;
  write_bytes(dir.file("a.txt"),
              "x,y,z\r\n"
              "# a comment\n"
              "\n"
              "1,2,3\r\n"
              "  4.5\t-5e-1  +6   # trailing comment\n"
              "7 ; 8 ; 9\n"
              "1e2 .5 -0\n"
              "10 11 12");  // no final newline
  EXPECT_EQ(read_all(dir.file("a.txt")),
            (std::vector<double>{1, 2, 3, 4.5, -0.5, 6, 7, 8, 9, 100, 0.5, -0.0, 10, 11, 12}));
  // Location of points: the line they came from.
  auto r = open_points(dir.file("a.txt"));
  double buf[15];
  ASSERT_EQ(r->read(buf, 5), 5u);
  EXPECT_EQ(r->location(0), "line 4");
  EXPECT_EQ(r->location(4), "line 8");
  EXPECT_EQ(r->error_at(1, "duplicate").what(), dir.file("a.txt") + ": line 5: duplicate");

  // Many lines through a 4 KiB read block: every line boundary case.
  std::string big;
  std::vector<double> want;
  for (int i = 0; i < 20000; ++i) {
    big += std::to_string(i) + " " + std::to_string(i * 0.5) + " " + std::to_string(-i) + "\n";
    want.insert(want.end(), {double(i), std::stod(std::to_string(i * 0.5)), double(-i)});
  }
  write_bytes(dir.file("big.txt"), big);
  EXPECT_EQ(read_all(dir.file("big.txt"), {}, 1000), want);
}

TEST(PointIo, TextWriterIsShortest) {
  TempDir dir;
  const double p[] = {0.1, 1.0, -2.5e-10};
  auto w = create_points(dir.file("s.txt"), {}, 1);
  w->write(p, 1);
  w->commit();
  std::ifstream in(dir.file("s.txt"));
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "0.1 1 -2.5e-10");
}

TEST(PointIo, WriterLeavesNothingOnFailure) {
  TempDir dir;
  const std::string path = dir.file("out.ply");
  {
    auto w = create_points(path, {}, 10);
    const double p[3] = {1, 2, 3};
    w->write(p, 1);
    EXPECT_TRUE(fs::exists(path + ".partial"));
    EXPECT_FALSE(fs::exists(path));
    EXPECT_THROW(w->commit(), std::logic_error);  // 1 of 10 points
  }
  EXPECT_FALSE(fs::exists(path + ".partial"));
  EXPECT_FALSE(fs::exists(path));
  EXPECT_THROW(create_points(dir.file("no/such/dir/x.f64"), {}, 1), IoError);
  EXPECT_THROW(create_points(dir.file("x.unknown"), {}, 1), UsageError);
}

// ---- bad input: one test per class; each message names the file and the place ----

TEST(PointIoBadInput, NonFiniteCoordinates) {
  TempDir dir;
  std::vector<double> pts(3 * 10, 1.0);
  pts[3 * 4 + 1] = std::numeric_limits<double>::quiet_NaN();
  for (const char* f : {"n.f64", "n.ply", "n.npy"}) {
    auto w = create_points(dir.file(f), {}, 10);
    w->write(pts.data(), 10);
    w->commit();
  }
  EXPECT_INPUT_ERROR(dir.file("n.f64"), PointReadOptions{}, "byte 104", "non-finite coordinate (y = nan)");
  EXPECT_INPUT_ERROR(dir.file("n.npy"), PointReadOptions{}, "byte 232", "non-finite");  // 128 + 104
  PointWriteOptions ascii;
  ascii.ascii = true;
  pts[3 * 4 + 1] = -std::numeric_limits<double>::infinity();
  auto w = create_points(dir.file("n2.ply"), ascii, 10);
  w->write(pts.data(), 10);
  w->commit();
  EXPECT_INPUT_ERROR(dir.file("n2.ply"), PointReadOptions{}, "line 13", "y = -inf");
  write_bytes(dir.file("n.txt"), "1 2 3\n4 inf 6\n");
  EXPECT_INPUT_ERROR(dir.file("n.txt"), PointReadOptions{}, "line 2", "non-finite");
  write_bytes(dir.file("n2.txt"), "1 2 3\n4 5 nan\n");
  EXPECT_INPUT_ERROR(dir.file("n2.txt"), PointReadOptions{}, "line 2", "z = nan");
  write_bytes(dir.file("n3.txt"), "1 2 3\n4 5 1e999\n");
  EXPECT_INPUT_ERROR(dir.file("n3.txt"), PointReadOptions{}, "line 2", "non-finite");
  // The binary PLY NaN: vertex 4's y, 4 * 24 + 8 bytes into the data.
  const std::string ply_err = read_error(dir.file("n.ply"));
  EXPECT_NE(ply_err.find("non-finite"), std::string::npos) << ply_err;
  EXPECT_NE(ply_err.find("byte "), std::string::npos) << ply_err;
}

TEST(PointIoBadInput, TruncatedFiles) {
  TempDir dir;
  write_bytes(dir.file("t.f64"), std::string(24 * 3 + 5, '\0'));
  EXPECT_INPUT_ERROR(dir.file("t.f64"), PointReadOptions{}, "byte 72", "not a multiple of the 24-byte record");
  write_bytes(dir.file("t.f32"), std::string(12 * 3 + 11, '\0'));
  EXPECT_INPUT_ERROR(dir.file("t.f32"), PointReadOptions{}, "byte 36", "12-byte record");

  // PLY binary: the header promises 5 vertices, the file holds 2 and a half.
  const std::string head =
      "ply\nformat binary_little_endian 1.0\nelement vertex 5\n"
      "property double x\nproperty double y\nproperty double z\nend_header\n";
  write_bytes(dir.file("t.ply"), head + std::string(24 * 2 + 12, '\0'));
  EXPECT_INPUT_ERROR(dir.file("t.ply"), PointReadOptions{}, "byte " + std::to_string(head.size() + 60),
                     "header promises 5 vertices");
  // PLY ASCII: 3 promised, 2 present.
  write_bytes(dir.file("ta.ply"),
              "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
              "property float z\nend_header\n1 2 3\n4 5 6\n");
  EXPECT_INPUT_ERROR(dir.file("ta.ply"), PointReadOptions{}, "line 10", "header promises 3");
}

TEST(PointIoBadInput, MalformedOrLyingHeaders) {
  TempDir dir;
  write_bytes(dir.file("m.ply"), "plx\nformat ascii 1.0\n");
  EXPECT_INPUT_ERROR(dir.file("m.ply"), PointReadOptions{}, "byte 0", "not a PLY file");
  write_bytes(dir.file("f.ply"), "ply\nformat binary_middle_endian 1.0\nend_header\n");
  EXPECT_INPUT_ERROR(dir.file("f.ply"), PointReadOptions{}, "line 2", "unknown PLY format");
  write_bytes(dir.file("nz.ply"),
              "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n");
  EXPECT_INPUT_ERROR(dir.file("nz.ply"), PointReadOptions{}, "line 3", "no 'z' property");
  write_bytes(dir.file("ne.ply"), "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
  EXPECT_INPUT_ERROR(dir.file("ne.ply"), PointReadOptions{}, "line 5", "no end_header");
  write_bytes(dir.file("nv.ply"), "ply\nformat ascii 1.0\nelement face 1\nproperty int a\nend_header\n1\n");
  EXPECT_INPUT_ERROR(dir.file("nv.ply"), PointReadOptions{}, "line 5", "no 'vertex' element");
  write_bytes(dir.file("bc.ply"), "ply\nformat ascii 1.0\nelement vertex -3\nend_header\n");
  EXPECT_INPUT_ERROR(dir.file("bc.ply"), PointReadOptions{}, "line 3", "not a non-negative integer");
  // A lying count: the vertex count is far larger than the data.
  write_bytes(dir.file("lie.ply"),
              "ply\nformat binary_big_endian 1.0\nelement vertex 18446744073709551615\nproperty double x\n"
              "property double y\nproperty double z\nend_header\n" +
                  std::string(48, '\0'));
  EXPECT_INPUT_ERROR(dir.file("lie.ply"), PointReadOptions{}, "byte ", "truncated");
}

TEST(PointIoBadInput, TextColumnsAndNonNumeric) {
  TempDir dir;
  write_bytes(dir.file("c2.txt"), "1 2 3\n4 5\n");
  EXPECT_INPUT_ERROR(dir.file("c2.txt"), PointReadOptions{}, "line 2", "expected 3 coordinates (x y z), found 2");
  write_bytes(dir.file("c4.csv"), "x,y,z\n1,2,3\n\n4,5,6,7\n");
  EXPECT_INPUT_ERROR(dir.file("c4.csv"), PointReadOptions{}, "line 4", "found 4");
  write_bytes(dir.file("nn.txt"), "1 2 3\n# ok\n1 2 abc\n");
  EXPECT_INPUT_ERROR(dir.file("nn.txt"), PointReadOptions{}, "line 3", "not a number: 'abc'");
  write_bytes(dir.file("nn2.txt"), "1 2 3\n1.5x 2 3\n");
  EXPECT_INPUT_ERROR(dir.file("nn2.txt"), PointReadOptions{}, "line 2", "not a number: '1.5x'");
  // Only the first data line may be a header.
  write_bytes(dir.file("h2.txt"), "x y z\nu v w\n1 2 3\n");
  EXPECT_INPUT_ERROR(dir.file("h2.txt"), PointReadOptions{}, "line 2", "not a number: 'u'");
}

TEST(PointIoBadInput, EmptyInputOrNoPoints) {
  TempDir dir;
  for (const char* f : {"e.f64", "e.ply", "e.npy", "e.txt"}) {
    write_bytes(dir.file(f), "");
    EXPECT_INPUT_ERROR(dir.file(f), PointReadOptions{}, "empty", "no points");
  }
  write_bytes(dir.file("c.txt"), "# only a comment\nx y z\n\n");
  EXPECT_INPUT_ERROR(dir.file("c.txt"), PointReadOptions{}, "line 4", "no points");
  write_bytes(dir.file("z.ply"),
              "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty double x\n"
              "property double y\nproperty double z\nend_header\n");
  EXPECT_INPUT_ERROR(dir.file("z.ply"), PointReadOptions{}, "line 3", "0 vertices");
}

TEST(PointIoBadInput, MissingFileIsAnIoError) { EXPECT_THROW(open_points("/nonexistent/points.f64"), IoError); }
