#include "io/point_format.hpp"

#include "core/error.hpp"

#include <algorithm>
#include <cctype>
#include <cstring>

namespace tetstream::io {

const char* to_string(PointFormat f) {
  switch (f) {
    case PointFormat::kAuto:
      return "auto";
    case PointFormat::kRaw:
      return "raw";
    case PointFormat::kPly:
      return "ply";
    case PointFormat::kNpy:
      return "npy";
    case PointFormat::kText:
      return "text";
    case PointFormat::kLas:
      return "las";
    case PointFormat::kHdf5:
      return "hdf5";
  }
  return "?";
}

const char* to_string(ScalarType t) {
  switch (t) {
    case ScalarType::kAuto:
      return "auto";
    case ScalarType::kFloat32:
      return "f32";
    case ScalarType::kFloat64:
      return "f64";
  }
  return "?";
}

const char* to_string(ByteOrder o) { return o == ByteOrder::kLittle ? "little" : "big"; }

void parse_format_name(std::string_view name, PointFormat& format, ScalarType& type) {
  if (name == "raw") {
    format = PointFormat::kRaw;
    return;
  }
  if (name == "f32") {
    format = PointFormat::kRaw;
    type = ScalarType::kFloat32;
    return;
  }
  if (name == "f64") {
    format = PointFormat::kRaw;
    type = ScalarType::kFloat64;
    return;
  }
  if (name == "ply") {
    format = PointFormat::kPly;
    return;
  }
  if (name == "npy") {
    format = PointFormat::kNpy;
    return;
  }
  if (name == "text" || name == "txt" || name == "csv" || name == "xyz") {
    format = PointFormat::kText;
    return;
  }
  if (name == "las") {
    format = PointFormat::kLas;
    return;
  }
  if (name == "hdf5" || name == "h5") {
    format = PointFormat::kHdf5;
    return;
  }
  if (name == "auto") {
    format = PointFormat::kAuto;
    return;
  }
  throw UsageError("unknown point format '" + std::string(name) +
                   "' (expected raw, f32, f64, ply, npy, text, las or hdf5)");
}

ByteOrder parse_byte_order(std::string_view name) {
  if (name == "little" || name == "le") return ByteOrder::kLittle;
  if (name == "big" || name == "be") return ByteOrder::kBig;
  throw UsageError("unknown byte order '" + std::string(name) + "' (expected little or big)");
}

FormatGuess format_from_extension(std::string_view path) {
  const auto slash = path.find_last_of('/');
  const auto dot = path.find_last_of('.');
  if (dot == std::string_view::npos || (slash != std::string_view::npos && dot < slash)) return {};
  std::string ext(path.substr(dot + 1));
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == "f64" || ext == "raw" || ext == "bin") return {PointFormat::kRaw, ScalarType::kAuto};
  if (ext == "f32") return {PointFormat::kRaw, ScalarType::kFloat32};
  if (ext == "ply") return {PointFormat::kPly, ScalarType::kAuto};
  if (ext == "npy") return {PointFormat::kNpy, ScalarType::kAuto};
  if (ext == "txt" || ext == "csv" || ext == "xyz" || ext == "pts" || ext == "asc")
    return {PointFormat::kText, ScalarType::kAuto};
  if (ext == "las" || ext == "laz") return {PointFormat::kLas, ScalarType::kAuto};
  if (ext == "hdf5" || ext == "h5" || ext == "hdf") return {PointFormat::kHdf5, ScalarType::kAuto};
  return {};
}

PointFormat sniff_format(const char* data, std::size_t size) {
  if (size >= 4 && std::memcmp(data, "ply", 3) == 0 && (data[3] == '\n' || data[3] == '\r')) return PointFormat::kPly;
  if (size >= 6 && std::memcmp(data, "\x93NUMPY", 6) == 0) return PointFormat::kNpy;
  if (size >= 4 && std::memcmp(data, "LASF", 4) == 0) return PointFormat::kLas;
  if (size >= 8 && std::memcmp(data, "\x89HDF\r\n\x1a\n", 8) == 0) return PointFormat::kHdf5;
  if (size == 0) return PointFormat::kAuto;
  // Text: printable ASCII and whitespace only in the prefix we have, after a UTF-8
  // byte order mark (editors on Windows write one).
  const std::size_t n = std::min<std::size_t>(size, 4096);
  const std::size_t bom = size >= 3 && std::memcmp(data, "\xEF\xBB\xBF", 3) == 0 ? 3 : 0;
  if (bom && size == 3) return PointFormat::kText;
  for (std::size_t i = bom; i < n; ++i) {
    const unsigned char c = static_cast<unsigned char>(data[i]);
    if (!(c == '\n' || c == '\r' || c == '\t' || (c >= 0x20 && c < 0x7f))) return PointFormat::kAuto;
  }
  return PointFormat::kText;
}

}  // namespace tetstream::io
