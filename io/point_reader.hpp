#pragma once
// Streaming point readers: raw float32/float64 records, PLY (binary either endianness,
// ASCII), NumPy .npy and text. The pipeline pulls chunks:
//
//   auto reader = io::open_points("cloud.ply", options);
//   std::vector<double> xyz(3 * kChunk);
//   while (std::size_t n = reader->read(xyz.data(), kChunk)) { ... }
//
// Memory is bounded (one block of ByteSource, 8 MiB, plus the caller's chunk) whatever
// the file size. Every coordinate returned is finite; a NaN or Inf, a truncated file,
// a lying header, a malformed text line, or an input with no points throws InputError
// with one line "FILE: byte OFFSET: PROBLEM" (or "line N" for text and PLY ASCII).
#include "core/error.hpp"
#include "io/point_format.hpp"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace tetstream::io {

struct PointReadOptions {
  PointFormat format = PointFormat::kAuto;  // kAuto: from the extension, else sniffed
  ScalarType type = ScalarType::kAuto;      // raw only; kAuto: from the extension, else float64
  std::uint64_t stride = 0;                 // raw only: bytes per record; 0: 3 * scalar size
  std::uint64_t offset = 0;                 // raw only: byte offset of x within a record
  ByteOrder byte_order = ByteOrder::kLittle;  // raw only (PLY and npy say it in the header)
  std::size_t block_bytes = std::size_t(8) << 20;  // read(2) block size

  // Throws UsageError for options that contradict each other (offset + 3 scalars > stride).
  void validate() const;
};

class PointReader {
 public:
  virtual ~PointReader() = default;

  // Fills xyz[0 .. 3n) with the next n <= max_points points (x, y, z per point) and
  // returns n; returns 0 at the end of the input. Throws InputError on bad data.
  virtual std::size_t read(double* xyz, std::size_t max_points) = 0;

  // The number of points when the format says so up front (raw files from their size,
  // PLY and npy from the header); nullopt for text and raw stdin.
  std::optional<std::uint64_t> count() const { return count_; }
  // "raw f64 little-endian, stride 24", "ply binary_little_endian", "npy <f8", "text".
  const std::string& format_name() const { return format_name_; }
  // The path, or "<stdin>".
  const std::string& source_name() const { return source_name_; }
  // Points returned so far.
  std::uint64_t points_read() const { return points_read_; }
  // Bytes of input consumed so far, and the input size when known (for progress).
  virtual std::uint64_t bytes_read() const = 0;
  virtual std::optional<std::uint64_t> source_size() const = 0;

  // Where point `index` (0-based, in input order) came from, as "byte N" or "line N".
  // Binary formats answer for any index; text formats for the points of the last
  // read() (older ones give "point N"). For errors the pipeline finds later (a
  // duplicate, a degenerate input), as one line in the same style as the reader's own.
  virtual std::string location(std::uint64_t index) const = 0;
  InputError error_at(std::uint64_t index, const std::string& problem) const {
    return InputError(source_name_ + ": " + location(index) + ": " + problem);
  }

 protected:
  std::optional<std::uint64_t> count_;
  std::string format_name_, source_name_;
  std::uint64_t points_read_ = 0;
};

// Opens `path` ("-" for stdin) with the format from options.format, else from the
// extension, else from the first bytes (PLY and npy magic, text); raw input needs
// the extension or --format. Reads and checks the header. Throws IoError when the file
// cannot be opened, UsageError when the format cannot be told, InputError on a bad header.
std::unique_ptr<PointReader> open_points(const std::string& path, const PointReadOptions& options = {});

}  // namespace tetstream::io
