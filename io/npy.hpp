#pragma once
// NumPy .npy output in one place: the header (format version 1.0, the dict padded with
// blanks so the data starts on a 64-byte boundary) and a writer for n-dimensional
// arrays of a fixed dtype, used by `gen` (points) and `field` (per-point fields, grids).
//
//   io::NpyArrayWriter w("rho.npy", "<f8", {n});
//   w.write(values, n * 8);  ...
//   w.commit();              // checks the byte count, renames rho.npy.partial -> rho.npy
//
// Nothing incomplete looks complete: the bytes go to PATH.partial (io/output_file.hpp),
// renamed by commit(); a writer destroyed without commit() removes it.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace tetstream::io {

class OutputFile;

// The preamble and header of a .npy v1.0 file for `descr` (e.g. "<f8") and `shape`,
// the text inside the shape tuple (e.g. "1000, 3"). With total > 0 the header is
// padded to exactly `total` bytes (to patch a placeholder in place), else to the next
// multiple of 64.
std::string npy_header(const std::string& descr, const std::string& shape, std::size_t total = 0);

class NpyArrayWriter {
 public:
  // descr: "<f4", "<f8", "<i4", "<i8", "<u8"...; shape: the dimensions (C order).
  NpyArrayWriter(std::string path, std::string descr, std::vector<std::uint64_t> shape);
  ~NpyArrayWriter();
  NpyArrayWriter(const NpyArrayWriter&) = delete;
  NpyArrayWriter& operator=(const NpyArrayWriter&) = delete;

  void write(const void* data, std::size_t bytes);
  // Throws std::logic_error if the bytes written are not the shape's, IoError on I/O.
  void commit();
  const std::string& path() const { return path_; }
  std::uint64_t data_bytes() const { return expected_; }

 private:
  std::string path_;
  std::unique_ptr<OutputFile> file_;
  std::uint64_t expected_ = 0, written_ = 0;
};

std::size_t npy_item_bytes(const std::string& descr);  // 4 for "<f4", 8 for "<i8"...

}  // namespace tetstream::io

namespace tetstream::io {

// Per-point scalars (masses) of a field job, read forward by index: a .npy 1-D array
// of little-endian float64 or float32 ("<f8", "<f4"), or raw little-endian float64.
// It must hold exactly `count` values, each finite and > 0; InputError names the file
// and the byte offset otherwise.
class ScalarFileReader {
 public:
  ScalarFileReader(std::string path, std::uint64_t count);
  ~ScalarFileReader();
  ScalarFileReader(const ScalarFileReader&) = delete;
  ScalarFileReader& operator=(const ScalarFileReader&) = delete;
  // The value at `index`; indices must not decrease from call to call.
  double at(std::uint64_t index);

 private:
  void fill(std::uint64_t index);
  std::string path_;
  int fd_ = -1;
  std::uint64_t count_ = 0, data_offset_ = 0;
  std::size_t item_ = 8;
  std::vector<unsigned char> buf_;
  std::uint64_t buf_first_ = 0, buf_count_ = 0;  // items buffered
};

}  // namespace tetstream::io

namespace tetstream::io {

// A whole 1-D .npy array (little-endian or single-byte float64, float32, or signed or
// unsigned integers of 1-8 bytes; version 1-3 header) as doubles, for per-point data
// (`convert --point-data`). It must hold exactly `count` values; integers must be
// exact in a double (|v| <= 2^53). Throws InputError naming the file and the problem.
std::vector<double> read_npy_values(const std::string& path, std::uint64_t count);

}  // namespace tetstream::io
