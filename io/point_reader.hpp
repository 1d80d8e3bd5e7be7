#pragma once
// Streaming point readers: raw float32/float64 records, PLY (binary either endianness,
// ASCII), NumPy .npy, text, LAS 1.0-1.4 and (when built with it) HDF5 datasets; several
// files read one after another as one input. The pipeline pulls chunks:
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

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tetstream::io {

struct PointReadOptions {
  PointFormat format = PointFormat::kAuto;         // kAuto: from the extension, else sniffed
  ScalarType type = ScalarType::kAuto;             // raw only; kAuto: from the extension, else float64
  std::uint64_t stride = 0;                        // raw only: bytes per record; 0: 3 * scalar size
  std::uint64_t offset = 0;                        // raw only: byte offset of x within a record
  ByteOrder byte_order = ByteOrder::kLittle;       // raw only (PLY and npy say it in the header)
  std::size_t block_bytes = std::size_t(8) << 20;  // read(2) block size
  // Further files of the same input, read after the first one in this order: the
  // points of all of them are one point set, indexed across the files (file-major).
  std::vector<std::string> more_inputs;
  std::vector<std::string> datasets;    // HDF5: the (N, 3) datasets to read, in order
  std::vector<std::uint64_t> columns;   // text, npy: 1-based columns of x, y, z; empty: the only three
  std::vector<std::string> properties;  // PLY: vertex properties of x, y, z; empty: x,y,z, else X,Y,Z
  // LAS only: keep the points of these ASPRS classification codes (0-255; empty: all),
  // and of these returns. Applied as the records are decoded, so the points are
  // numbered (original ids) among those kept.
  std::vector<std::uint8_t> las_classes;
  enum class LasReturns : std::uint8_t { kAll, kFirst, kLast } las_returns = LasReturns::kAll;
  bool las_filtered() const { return !las_classes.empty() || las_returns != LasReturns::kAll; }

  // The largest --stride (and any binary record) we accept: one record must fit the
  // read buffer, so a larger one could only be an error.
  static constexpr std::uint64_t kMaxRecordBytes = std::uint64_t(1) << 20;

  // Throws UsageError for options that contradict each other or are out of range
  // (offset + 3 scalars > stride, computed without wrapping; columns not three distinct
  // positive numbers; ...).
  void validate() const;
  // The options that change which points are read, as one canonical line (for a job's
  // identity): format, type, stride, offset, byte order, files, datasets, columns, properties,
  // and the LAS filters when set (absent when not: the identity of older jobs is unchanged).
  std::string identity() const;
  // The LAS filters alone (" las_classes=2,6 las_returns=last"; empty when none is set).
  std::string las_identity() const;
};

class PointReader {
 public:
  virtual ~PointReader() = default;

  // Fills xyz[0 .. 3n) with the next n <= max_points points (x, y, z per point) and
  // returns n; returns 0 at the end of the input. Throws InputError on bad data.
  virtual std::size_t read(double* xyz, std::size_t max_points) = 0;
  // Skips the next n points (fewer at the end of the input) and returns how many it
  // skipped: binary records with a known count seek past them; other formats read them
  // (and check them) and drop them. How a rank of a distributed job reaches its own
  // range of the input (pipeline/point_sort_distributed.hpp).
  virtual std::uint64_t skip(std::uint64_t n);

  // The number of points when the format says so up front (raw files from their size,
  // PLY and npy from the header); nullopt for text and raw stdin.
  std::optional<std::uint64_t> count() const { return count_; }
  // "raw f64 little-endian, stride 24", "ply binary_little_endian", "npy <f8", "text".
  const std::string& format_name() const { return format_name_; }
  // Whether every coordinate comes from a float32 in the file (raw f32, PLY float,
  // npy <f4; several files: all of them): the sorted points and the container keep
  // them as float32, which hold them exactly.
  bool float32_input() const { return float32_; }
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
  // The file point `index` came from (several files: the one that holds it).
  virtual std::string source_of(std::uint64_t /*index*/) const { return source_name_; }
  InputError error_at(std::uint64_t index, const std::string& problem) const {
    return InputError(source_of(index) + ": " + location(index) + ": " + problem);
  }
  // Facts about the input worth showing beside the count ("scale" -> "0.01 0.01 0.01" for
  // LAS), as label and value; complete once the input has been read to its end.
  virtual std::vector<std::pair<std::string, std::string>> details() const { return {}; }

 protected:
  std::optional<std::uint64_t> count_;
  std::string format_name_, source_name_;
  std::uint64_t points_read_ = 0;
  bool float32_ = false;
};

// Opens `path` ("-" for stdin), then options.more_inputs after it, with the format from
// options.format, else from each file's extension, else from its first bytes (PLY, npy,
// LAS and HDF5 magic, text); raw input needs the extension or --format. Reads and checks
// the headers. Throws IoError when a file cannot be opened, UsageError when the format
// cannot be told or an option does not apply to it, InputError on a bad header.
std::unique_ptr<PointReader> open_points(const std::string& path, const PointReadOptions& options = {});

// The files named by command-line input arguments: each argument that is not an
// existing file and holds a glob character (* ? [) is expanded, its matches in natural
// order (runs of digits compared as numbers: snap.2 before snap.10); other arguments
// are kept as given. Throws IoError when a pattern matches nothing, UsageError when "-"
// (stdin) is one of several inputs.
std::vector<std::string> expand_inputs(const std::vector<std::string>& args);

// An HDF5 dataset that holds an (N, 3) array of floats: a candidate for --dataset.
struct Hdf5PointDataset {
  std::string path;  // "/PartType1/Coordinates"
  std::uint64_t rows = 0;
  std::string type;  // "float32", "float64"
};
// The (N, 3) float datasets of an HDF5 file, in name order. Throws UsageError when this
// build has no HDF5, InputError when the file is not HDF5.
std::vector<Hdf5PointDataset> list_hdf5_point_datasets(const std::string& path);
// The box of a simulation snapshot: the attribute BoxSize of the group Header (Gadget,
// AREPO, SWIFT), one number or three. Throws UsageError when the file has none.
std::array<double, 3> hdf5_box_size(const std::string& path);
bool hdf5_available();  // whether this build reads HDF5

}  // namespace tetstream::io
