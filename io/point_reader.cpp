#include "io/point_reader.hpp"

#include "io/point_detail.hpp"

namespace tetstream::io {

void PointReadOptions::validate() const {
  const std::uint64_t w = type == ScalarType::kFloat32 ? 4 : 8;
  if (stride != 0 && offset + 3 * w > stride) {
    throw UsageError("--offset " + std::to_string(offset) + " + 3 coordinates of " + std::to_string(w) +
                     " bytes do not fit in a record of --stride " + std::to_string(stride) + " bytes");
  }
  if (block_bytes < 4096) throw UsageError("read block must be at least 4096 bytes");
}

std::unique_ptr<PointReader> open_points(const std::string& path, const PointReadOptions& options) {
  options.validate();
  auto src = std::make_unique<ByteSource>(path, options.block_bytes);

  PointFormat format = options.format;
  ScalarType type = options.type;
  if (!is_std_stream(path)) {
    const FormatGuess guess = format_from_extension(path);
    if (format == PointFormat::kAuto) format = guess.format;
    if (type == ScalarType::kAuto && format == guess.format) type = guess.type;
  }
  if (format == PointFormat::kAuto) {
    src->ensure(4096);
    if (src->available() == 0) throw InputError::at_byte(src->name(), 0, "empty input: no points");
    format = sniff_format(src->data(), src->available());
    if (format == PointFormat::kAuto) {
      throw UsageError("cannot tell the format of " + src->name() +
                       ": name it with --format (raw, f32, f64, ply, npy, text)");
    }
  }
  if (format != PointFormat::kRaw && (options.stride != 0 || options.offset != 0)) {
    throw UsageError(std::string("--stride and --offset apply to raw input only, not ") + to_string(format));
  }
  if (type == ScalarType::kAuto) type = ScalarType::kFloat64;

  switch (format) {
    case PointFormat::kRaw: return detail::open_raw(std::move(src), type, options);
    case PointFormat::kPly: return detail::open_ply(std::move(src));
    case PointFormat::kNpy: return detail::open_npy(std::move(src));
    case PointFormat::kText: return detail::open_text(std::move(src));
    case PointFormat::kAuto: break;
  }
  throw UsageError("no reader for " + path);
}

}  // namespace tetstream::io
