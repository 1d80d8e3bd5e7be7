// Readers never drop data silently and never read outside a record (issue #16, defects
// 8 and 9): a header that declares fewer points than the file holds, a malformed first
// text line taken for a header, and reader options whose sums wrap around.
#include "io/point_reader.hpp"
#include "point_files.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

using namespace tetstream;
using namespace tetstream::io;

namespace {

std::string le_doubles(const std::vector<double>& v) {
  std::string s;
  for (double x : v) s += le_bytes(x);
  return s;
}

const std::string kPlyBinaryHeader2 =
    "ply\nformat binary_little_endian 1.0\nelement vertex 2\n"
    "property double x\nproperty double y\nproperty double z\nend_header\n";

}  // namespace

TEST(PointSafety, PlyBinaryDataAfterTheDeclaredVerticesIsAnError) {
  TempDir dir;
  const std::string path = dir.file("more.ply");
  write_bytes(path, kPlyBinaryHeader2 + le_doubles({1, 2, 3, 4, 5, 6, 7, 8, 9}));
  const std::uint64_t end_of_two = kPlyBinaryHeader2.size() + 48;
  EXPECT_INPUT_ERROR(path, PointReadOptions{}, "byte " + std::to_string(end_of_two), "24 bytes");
}

TEST(PointSafety, PlyElementsAfterVertexAreNotTrailingData) {
  TempDir dir;
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 2\n"
      "property double x\nproperty double y\nproperty double z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  std::string face =
      std::string(1, '\3') + le_bytes<std::int32_t>(0) + le_bytes<std::int32_t>(1) + le_bytes<std::int32_t>(0);
  write_bytes(dir.file("face.ply"), header + le_doubles({1, 2, 3, 4, 5, 6}) + face);
  EXPECT_EQ(read_all(dir.file("face.ply")), (std::vector<double>{1, 2, 3, 4, 5, 6}));
  // ... but bytes after the last element are.
  write_bytes(dir.file("face_more.ply"), header + le_doubles({1, 2, 3, 4, 5, 6}) + face + "junk");
  EXPECT_INPUT_ERROR(dir.file("face_more.ply"), PointReadOptions{},
                     "byte " + std::to_string(header.size() + 48 + face.size()), "4 bytes");
}

TEST(PointSafety, PlyAsciiLinesAfterTheDeclaredVerticesAreAnError) {
  TempDir dir;
  const std::string path = dir.file("more_ascii.ply");
  write_bytes(path,
              "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
              "property float z\nend_header\n1 2 3\n4 5 6\n7 8 9\n\n");
  EXPECT_INPUT_ERROR(path, PointReadOptions{}, "line 10", "after the last element");
  // A final blank line is not data.
  write_bytes(dir.file("ok.ply"),
              "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
              "property float z\nend_header\n1 2 3\n4 5 6\n\n");
  EXPECT_EQ(read_all(dir.file("ok.ply")).size(), 6u);
}

TEST(PointSafety, NpyRowsAfterTheDeclaredShapeAreAnError) {
  TempDir dir;
  const std::string path = dir.file("more.npy");
  write_bytes(path, npy_bytes(1, "<f8", "(2, 3)", le_doubles({1, 2, 3, 4, 5, 6, 7, 8, 9})));
  EXPECT_INPUT_ERROR(path, PointReadOptions{}, "byte 176", "24 bytes");
}

TEST(PointSafety, MalformedFirstTextLineIsAnErrorNotAHeader) {
  TempDir dir;
  for (const char* bad : {"1e5x", "1.2.3", "12abc", "--1", "1e", "0x1p0"}) {
    const std::string path = dir.file("bad.txt");
    write_bytes(path, std::string(bad) + " 2 3\n4 5 6\n7 8 9\n");
    EXPECT_INPUT_ERROR(path, PointReadOptions{}, "line 1", std::string("not a number: '") + bad + "'");
    // The same token on a later line: the same error there.
    write_bytes(path, std::string("4 5 6\n") + bad + " 2 3\n");
    EXPECT_INPUT_ERROR(path, PointReadOptions{}, "line 2", std::string("not a number: '") + bad + "'");
  }
  // A header is a line of names only.
  write_bytes(dir.file("names.csv"), "# made by hand\nx,y,z\n1,2,3\n");
  EXPECT_EQ(read_all(dir.file("names.csv")), (std::vector<double>{1, 2, 3}));
  write_bytes(dir.file("quoted.csv"), "\"X\",\"Y\",\"Z\"\n1,2,3\n");
  EXPECT_EQ(read_all(dir.file("quoted.csv")), (std::vector<double>{1, 2, 3}));
  write_bytes(dir.file("mixed.txt"), "x 2 z\n1 2 3\n");
  EXPECT_INPUT_ERROR(dir.file("mixed.txt"), PointReadOptions{}, "line 1", "not a number: 'x'");
}

TEST(PointSafety, RawOffsetThatWrapsAroundIsRefused) {
  TempDir dir;
  const std::string path = dir.file("p.f64");
  write_bytes(path, le_doubles({1, 2, 3, 4, 5, 6}));
  PointReadOptions o;
  o.stride = 24;
  o.offset = 18446744073709551608ull;  // 2^64 - 8: offset + 24 wraps to 16
  EXPECT_THROW(o.validate(), UsageError);
  EXPECT_THROW(open_points(path, o), UsageError);
  o.offset = 0;
  o.stride = std::numeric_limits<std::uint64_t>::max();
  EXPECT_THROW(open_points(path, o), UsageError);  // a record larger than any buffer we would allocate
}

TEST(PointSafety, HeaderSizesThatWrapAroundAreRefused) {
  TempDir dir;
  // npy: 2^62 columns of 8 bytes wrap the row size to 0.
  write_bytes(dir.file("wide.npy"), npy_bytes(1, "<f8", "(2, 4611686018427387904)", le_doubles({1, 2, 3, 4, 5, 6})));
  EXPECT_NE(read_error(dir.file("wide.npy")), "");
  // PLY: an element before vertex whose count times record size wraps.
  write_bytes(dir.file("wrap.ply"),
              "ply\nformat binary_little_endian 1.0\nelement pad 2305843009213693952\nproperty double a\n"
              "element vertex 1\nproperty double x\nproperty double y\nproperty double z\nend_header\n" +
                  le_doubles({1, 2, 3}));
  EXPECT_INPUT_ERROR(dir.file("wrap.ply"), PointReadOptions{}, "wrap.ply", "pad");
}
