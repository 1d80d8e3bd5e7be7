// Reader options for inputs as users have them: text and npy with more than three
// columns (--columns), PLY with other property names (--properties, and X/Y/Z found
// without asking), several files read as one input (indices across the files, errors
// naming the right file), and the expansion of globs in natural order.
#include "io/point_reader.hpp"
#include "point_files.hpp"

#include <gtest/gtest.h>

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

PointReadOptions with_columns(std::uint64_t a, std::uint64_t b, std::uint64_t c) {
  PointReadOptions o;
  o.columns = {a, b, c};
  return o;
}

}  // namespace

TEST(PointInput, TextColumns) {
  TempDir dir;
  write_bytes(dir.file("t.csv"), "id,class,x,y,z,intensity\n7,ground,1,2,3,0.5\n8,roof,4,5,6,0.25\n");
  EXPECT_EQ(read_all(dir.file("t.csv"), with_columns(3, 4, 5)), (std::vector<double>{1, 2, 3, 4, 5, 6}));
  // Any order, and a column may come first.
  EXPECT_EQ(read_all(dir.file("t.csv"), with_columns(5, 1, 6)), (std::vector<double>{3, 7, 0.5, 6, 8, 0.25}));
  // A chosen column that is not a number is an error naming the line and the field.
  EXPECT_INPUT_ERROR(dir.file("t.csv"), with_columns(2, 3, 4), "line 2", "not a number: 'ground'");
  // Too few fields for the columns, and ragged lines.
  EXPECT_INPUT_ERROR(dir.file("t.csv"), with_columns(3, 4, 9), "line 2", "only 6 fields");
  write_bytes(dir.file("ragged.txt"), "0 1 2 3\n0 4 5 6\n0 7 8 9 10\n");
  EXPECT_INPUT_ERROR(dir.file("ragged.txt"), with_columns(2, 3, 4), "line 3", "expected 4 fields");
  // Without --columns, a wider file is an error that names the option.
  EXPECT_INPUT_ERROR(dir.file("ragged.txt"), PointReadOptions{}, "line 1", "--columns");
}

TEST(PointInput, ColumnsAreValidated) {
  PointReadOptions o = with_columns(0, 1, 2);
  EXPECT_THROW(o.validate(), UsageError);  // 1-based
  o = with_columns(1, 1, 2);
  EXPECT_THROW(o.validate(), UsageError);  // twice
  o.columns = {1, 2};
  EXPECT_THROW(o.validate(), UsageError);  // three
  o.columns = {1, 2, 3};
  o.validate();
  TempDir dir;
  write_bytes(dir.file("p.f64"), le_doubles({1, 2, 3}));
  EXPECT_THROW(open_points(dir.file("p.f64"), o), UsageError);  // not for raw
  o.columns.clear();
  o.properties = {"x", "y", "z"};
  EXPECT_THROW(open_points(dir.file("p.f64"), o), UsageError);  // not for raw
}

TEST(PointInput, NpyColumns) {
  TempDir dir;
  write_bytes(dir.file("w.npy"), npy_bytes(1, "<f8", "(2, 5)", le_doubles({0, 1, 2, 3, 4, 10, 11, 12, 13, 14})));
  EXPECT_EQ(read_all(dir.file("w.npy"), with_columns(2, 3, 4)), (std::vector<double>{1, 2, 3, 11, 12, 13}));
  EXPECT_EQ(read_all(dir.file("w.npy"), with_columns(5, 1, 3)), (std::vector<double>{4, 0, 2, 14, 10, 12}));
  EXPECT_INPUT_ERROR(dir.file("w.npy"), PointReadOptions{}, "byte 10", "--columns");
  EXPECT_THROW(read_all(dir.file("w.npy"), with_columns(2, 3, 6)), UsageError);
  // float32, big-endian, with columns: the stride is the row, not three scalars.
  std::string be;
  for (float v : {0.f, 1.f, 2.f, 3.f, 4.f, 5.f, 6.f, 7.f}) be += be_bytes(v);
  write_bytes(dir.file("be.npy"), npy_bytes(1, ">f4", "(2, 4)", be));
  EXPECT_EQ(read_all(dir.file("be.npy"), with_columns(4, 3, 2)), (std::vector<double>{3, 2, 1, 7, 6, 5}));
}

TEST(PointInput, PlyPropertyNames) {
  TempDir dir;
  const std::string upper =
      "ply\nformat ascii 1.0\nelement vertex 2\nproperty double X\nproperty double Y\nproperty double Z\n"
      "property uchar intensity\nend_header\n1 2 3 9\n4 5 6 9\n";
  write_bytes(dir.file("upper.ply"), upper);
  EXPECT_EQ(read_all(dir.file("upper.ply")), (std::vector<double>{1, 2, 3, 4, 5, 6}));
  PointReadOptions o;
  o.properties = {"Z", "intensity", "X"};
  EXPECT_EQ(read_all(dir.file("upper.ply"), o), (std::vector<double>{3, 9, 1, 6, 9, 4}));
  o.properties = {"px", "py", "pz"};
  EXPECT_INPUT_ERROR(dir.file("upper.ply"), o, "line 3", "no 'px' property (it has: X, Y, Z, intensity");
  // Binary, other names.
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float a\nproperty double px\n"
      "property double py\nproperty double pz\nend_header\n";
  write_bytes(dir.file("named.ply"), header + le_bytes(1.5f) + le_doubles({7, 8, 9}));
  o.properties = {"px", "py", "pz"};
  EXPECT_EQ(read_all(dir.file("named.ply"), o), (std::vector<double>{7, 8, 9}));
  EXPECT_INPUT_ERROR(dir.file("named.ply"), PointReadOptions{}, "line 3", "no 'x' property");
}

TEST(PointInput, SeveralFilesAreOneInput) {
  TempDir dir;
  write_bytes(dir.file("a.f64"), le_doubles({1, 2, 3, 4, 5, 6}));
  write_bytes(dir.file("b.txt"), "7 8 9\n");
  write_bytes(dir.file("c.npy"), npy_bytes(1, "<f8", "(1, 3)", le_doubles({10, 11, 12})));
  PointReadOptions o;
  o.more_inputs = {dir.file("b.txt"), dir.file("c.npy")};
  EXPECT_EQ(read_all(dir.file("a.f64"), o, 2), (std::vector<double>{1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12}));
  // The count is known only when every file states it (text does not).
  EXPECT_FALSE(open_points(dir.file("a.f64"), o)->count());
  o.more_inputs = {dir.file("a.f64")};
  auto r = open_points(dir.file("c.npy"), o);
  ASSERT_TRUE(r->count());
  EXPECT_EQ(*r->count(), 3u);
  std::vector<double> buf(3 * 8);
  EXPECT_EQ(r->read(buf.data(), 8), 1u);  // one file per read at most
  EXPECT_EQ(r->read(buf.data(), 8), 2u);
  // Point 2 is a.f64's second record: the error names that file and its byte.
  EXPECT_EQ(std::string(r->error_at(2, "duplicate").what()), dir.file("a.f64") + ": byte 24: duplicate");
  EXPECT_EQ(r->read(buf.data(), 8), 0u);

  // A bad file among several: its own message, found before reading (headers first).
  write_bytes(dir.file("bad.npy"), npy_bytes(1, "<f8", "(5, 3)", le_doubles({1, 2, 3})));
  o.more_inputs = {dir.file("bad.npy")};
  EXPECT_THROW(open_points(dir.file("a.f64"), o), InputError);
  o.more_inputs = {"-"};
  EXPECT_THROW(open_points(dir.file("a.f64"), o), UsageError);
}

// skip() is how a rank of a distributed job reaches its range of the input: seeking in
// raw, npy, PLY binary and (point_las_test) LAS files and over whole files of several,
// reading and dropping text.
TEST(PointInput, SkipIsReadAndDrop) {
  TempDir dir;
  std::vector<double> v;
  for (int i = 0; i < 3 * 23; ++i) v.push_back(i * 0.25 - 3);
  const std::vector<double> head(v.begin(), v.begin() + 3 * 9), tail(v.begin() + 3 * 9, v.end());
  write_bytes(dir.file("a.f64"), le_doubles(v));
  expect_skip_is_read_and_drop(dir.file("a.f64"));
  // Records with a stride and an offset (4 bytes before each x, 4 after z).
  std::string strided;
  for (std::size_t i = 0; i < v.size(); i += 3) strided += "abcd" + le_doubles({v[i], v[i + 1], v[i + 2]}) + "wxyz";
  write_bytes(dir.file("s.bin"), strided);
  PointReadOptions o;
  o.format = PointFormat::kRaw, o.type = ScalarType::kFloat64, o.stride = 32, o.offset = 4;
  expect_skip_is_read_and_drop(dir.file("s.bin"), o);
  write_bytes(dir.file("a.npy"), npy_bytes(1, "<f8", "(23, 3)", le_doubles(v)));
  expect_skip_is_read_and_drop(dir.file("a.npy"));
  const std::string ply_head =
      "ply\nformat binary_little_endian 1.0\nelement vertex 23\n"
      "property double x\nproperty double y\nproperty double z\nend_header\n";
  write_bytes(dir.file("a.ply"), ply_head + le_doubles(v));
  expect_skip_is_read_and_drop(dir.file("a.ply"));
  std::string text;
  for (std::size_t i = 0; i < v.size(); i += 3)
    text += std::to_string(v[i]) + " " + std::to_string(v[i + 1]) + " " + std::to_string(v[i + 2]) + "\n";
  write_bytes(dir.file("a.txt"), text);
  expect_skip_is_read_and_drop(dir.file("a.txt"));

  // Several files, counts known: whole files passed, the rest skipped inside one.
  write_bytes(dir.file("h.f64"), le_doubles(head));
  write_bytes(dir.file("t.npy"), npy_bytes(1, "<f8", "(14, 3)", le_doubles(tail)));
  o = PointReadOptions{};
  o.more_inputs = {dir.file("t.npy"), dir.file("h.f64")};
  expect_skip_is_read_and_drop(dir.file("h.f64"), o);
  {
    auto r = open_points(dir.file("h.f64"), o);
    ASSERT_TRUE(r->count());
    EXPECT_EQ(r->skip(9 + 14 + 2), 25u);  // into the third file's records
    std::vector<double> buf(3 * 8);
    ASSERT_EQ(r->read(buf.data(), 8), 7u);
    EXPECT_EQ(buf[0], head[6]);
    // A point found bad now is named in its own file.
    EXPECT_EQ(std::string(r->error_at(25, "bad").what()), dir.file("h.f64") + ": byte 48: bad");
  }
  // And with a text file (no count: read and dropped).
  o.more_inputs = {dir.file("a.txt"), dir.file("t.npy")};
  expect_skip_is_read_and_drop(dir.file("h.f64"), o);

  // Seeking reads nothing: a NaN among the skipped records is not seen (the rank whose
  // range holds it reads it, and says so), in one file or as a whole file of several.
  std::vector<double> bad = head;
  bad[4] = std::numeric_limits<double>::quiet_NaN();
  write_bytes(dir.file("bad.f64"), le_doubles(bad));
  EXPECT_THROW(read_all(dir.file("bad.f64")), InputError);
  auto expect_rest_reads = [&](const std::string& path, PointReadOptions opt, std::uint64_t n, std::size_t left) {
    auto r = open_points(path, opt);
    EXPECT_EQ(r->skip(n), n);
    std::vector<double> buf(3 * 64);
    std::size_t got = 0;
    while (std::size_t k = r->read(buf.data(), 64)) got += k;
    EXPECT_EQ(got, left) << path;
  };
  expect_rest_reads(dir.file("bad.f64"), PointReadOptions{}, 2, 7);
  o.more_inputs = {dir.file("t.npy")};
  expect_rest_reads(dir.file("bad.f64"), o, 9, 14);
}

TEST(PointInput, GlobsExpandInNaturalOrder) {
  TempDir dir;
  for (const char* f : {"snap_000.10.hdf5", "snap_000.2.hdf5", "snap_000.0.hdf5", "snap_000.1.hdf5", "other.txt"})
    write_bytes(dir.file(f), "x");
  const auto files = expand_inputs({dir.file("snap_000.*.hdf5"), dir.file("other.txt")});
  ASSERT_EQ(files.size(), 5u);
  EXPECT_EQ(files[0], dir.file("snap_000.0.hdf5"));
  EXPECT_EQ(files[1], dir.file("snap_000.1.hdf5"));
  EXPECT_EQ(files[2], dir.file("snap_000.2.hdf5"));
  EXPECT_EQ(files[3], dir.file("snap_000.10.hdf5"));
  EXPECT_EQ(files[4], dir.file("other.txt"));
  // Files given one by one keep their order; a pattern that matches nothing is an error.
  EXPECT_EQ(expand_inputs({"b", "a"}), (std::vector<std::string>{"b", "a"}));
  EXPECT_THROW(expand_inputs({dir.file("nothing.*")}), IoError);
  EXPECT_THROW(expand_inputs({"-", "a"}), UsageError);
}
