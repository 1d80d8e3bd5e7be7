// Reader options for inputs as users have them: text and npy with more than three
// columns (--columns), PLY with other property names (--properties, and X/Y/Z found
// without asking), several files read as one input (indices across the files, errors
// naming the right file), and the expansion of globs in natural order.
#include "io/point_reader.hpp"
#include "point_files.hpp"

#include <gtest/gtest.h>

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
