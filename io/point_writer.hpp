#pragma once
// Streaming point writers (for `gen`, and later `convert`): raw float32/float64, PLY
// (binary, double or float x,y,z; or ASCII), .npy (float64 or float32) and text.
//
//   auto w = io::create_points("out.ply", {}, n);
//   while (...) w->write(xyz, k);
//   w->commit();   // flush, close, rename OUT.partial -> OUT
//
// Nothing is left looking complete on failure: the data goes to "OUT.partial" in the
// same directory and is renamed to OUT by commit(); a writer destroyed without commit()
// (an exception, a failed check) removes its partial file. "-" writes to stdout.
//
// Round trips: binary formats store the doubles (or their float32 rounding) bit for bit;
// text and PLY ASCII print the shortest representation that reads back to the same
// double (std::to_chars), so they round-trip exactly too.
#include "io/point_format.hpp"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace tetstream::io {

class OutputClaim;

struct PointWriteOptions {
  PointFormat format = PointFormat::kAuto;    // kAuto: from the extension
  ScalarType type = ScalarType::kAuto;        // raw, PLY binary, npy; kAuto: extension, else float64
  ByteOrder byte_order = ByteOrder::kLittle;  // raw, PLY binary, npy
  bool ascii = false;                         // PLY: ASCII instead of binary
  std::size_t buffer_bytes = std::size_t(8) << 20;
};

class PointWriter {
 public:
  static constexpr std::uint64_t kUnknownCount = ~std::uint64_t(0);
  virtual ~PointWriter();

  // Appends n points (xyz[0..3n)).
  void write(const double* xyz, std::size_t n);
  // Checks the count against the header's, flushes, closes and renames into place.
  // Throws IoError (disk full, rename failed) or std::logic_error (count mismatch).
  void commit();

  const std::string& format_name() const { return format_name_; }
  const std::string& path() const { return path_; }
  std::uint64_t points_written() const { return points_; }
  std::uint64_t bytes_written() const { return bytes_; }

 protected:
  PointWriter();
  virtual void encode(const double* xyz, std::size_t n) = 0;
  // Called by commit() before the final flush; headers with a count placeholder patch it.
  virtual void finish() {}

  void put(const void* data, std::size_t n);  // buffered
  void flush();
  void pwrite_at(std::uint64_t offset, const void* data, std::size_t n);  // header patches

  std::string path_, tmp_path_, format_name_;
  std::uint64_t count_ = kUnknownCount;  // what the header says, if it says
  std::uint64_t points_ = 0, bytes_ = 0;
  bool to_stdout_ = false;

 private:
  friend std::unique_ptr<PointWriter> create_points(const std::string&, const PointWriteOptions&, std::uint64_t);
  void open(const std::string& path, std::size_t buffer_bytes);

  std::unique_ptr<OutputClaim> claim_;  // PATH.partial, locked until the writer goes
  int fd_ = -1;
  bool committed_ = false;
  std::unique_ptr<char[]> buf_;
  std::size_t cap_ = 0, used_ = 0;
};

// Creates a writer for `count` points (kUnknownCount allowed: PLY and npy then reserve
// room in the header and patch it at commit(), which needs a seekable file, not stdout).
// The format comes from options.format, else from the extension. Throws UsageError for
// an unknown format, IoError when the file cannot be created.
std::unique_ptr<PointWriter> create_points(const std::string& path, const PointWriteOptions& options,
                                           std::uint64_t count);

}  // namespace tetstream::io
