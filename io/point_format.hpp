#pragma once
// Point file formats: the names a user types (--format), the extensions we map, and
// the sniffing of magic numbers for stdin and unknown extensions. docs/inputs.md is
// the user-facing description of the same table.
//
//   extension                    format  scalar
//   .f64 .raw .bin               raw     float64 (unless --type f32)
//   .f32                         raw     float32
//   .ply                         ply     from the header
//   .npy                         npy     from the header
//   .txt .csv .xyz .pts .asc     text    (parsed as float64)
//   .las .laz                    las     int32 with scale and offset (.laz: refused, compressed)
//   .hdf5 .h5 .hdf               hdf5    the --dataset arrays, float32 or float64
//
// `.xyz` is text: that is what point-cloud tools (CloudCompare, PDAL, MeshLab) mean by it.
#include <cstdint>
#include <string>
#include <string_view>

namespace tetstream::io {

enum class PointFormat { kAuto, kRaw, kPly, kNpy, kText, kLas, kHdf5 };
// The scalar type of raw input and of binary output. kAuto: from the extension, else float64.
enum class ScalarType { kAuto, kFloat32, kFloat64 };
enum class ByteOrder { kLittle, kBig };

const char* to_string(PointFormat f);
const char* to_string(ScalarType t);
const char* to_string(ByteOrder o);

// Parses a --format value: "raw", "f32", "f64", "ply", "npy", "text" (aliases "txt", "csv",
// "xyz"), "las", "hdf5" (alias "h5"). "f32"/"f64" set both the format (raw) and the scalar type. Throws UsageError.
void parse_format_name(std::string_view name, PointFormat& format, ScalarType& type);
ByteOrder parse_byte_order(std::string_view name);  // "little" | "big"; throws UsageError

// The format and scalar type a path's extension implies; kAuto when it implies none.
struct FormatGuess {
  PointFormat format = PointFormat::kAuto;
  ScalarType type = ScalarType::kAuto;
};
FormatGuess format_from_extension(std::string_view path);

// Recognises a PLY, .npy, LAS or HDF5 (at byte 0) magic number, or text (printable bytes, digits first); kAuto
// when the prefix says nothing (raw binary cannot be recognised).
PointFormat sniff_format(const char* data, std::size_t size);

// True when `path` names stdin/stdout ("-").
inline bool is_std_stream(std::string_view path) { return path == "-"; }

}  // namespace tetstream::io
