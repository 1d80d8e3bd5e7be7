#include "io/point_reader.hpp"

#include "io/point_detail.hpp"

#include <algorithm>
#include <cctype>
#include <glob.h>
#include <sys/stat.h>

namespace tetstream::io {

namespace {

bool is_regular_file(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

// Natural order: runs of digits compare as numbers (snap.2 < snap.10), the rest bytewise.
bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (std::isdigit(static_cast<unsigned char>(a[i])) && std::isdigit(static_cast<unsigned char>(b[j]))) {
      std::size_t i0 = i, j0 = j;
      while (i0 < a.size() && a[i0] == '0') ++i0;  // leading zeros do not change the number
      while (j0 < b.size() && b[j0] == '0') ++j0;
      std::size_t i1 = i0, j1 = j0;
      while (i1 < a.size() && std::isdigit(static_cast<unsigned char>(a[i1]))) ++i1;
      while (j1 < b.size() && std::isdigit(static_cast<unsigned char>(b[j1]))) ++j1;
      if (i1 - i0 != j1 - j0) return i1 - i0 < j1 - j0;
      const int c = a.compare(i0, i1 - i0, b, j0, j1 - j0);
      if (c != 0) return c < 0;
      i = i1, j = j1;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      ++i, ++j;
    }
  }
  if (a.size() - i != b.size() - j) return a.size() - i < b.size() - j;
  return a < b;  // equal as numbers (0 vs 00): any fixed order
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : ",") + x;
  return s;
}

// Which options apply to which formats: one that does not apply is a usage error, never
// silently ignored.
void check_applies(PointFormat format, const PointReadOptions& o, const std::string& name) {
  auto refuse = [&](const char* option, const char* formats) {
    throw UsageError(std::string(option) + " applies to " + formats + " input only, not " + to_string(format) + " (" +
                     name + ")");
  };
  if (format != PointFormat::kRaw && (o.stride != 0 || o.offset != 0)) refuse("--stride and --offset", "raw");
  if (format != PointFormat::kText && format != PointFormat::kNpy && !o.columns.empty())
    refuse("--columns", "text and npy");
  if (format != PointFormat::kPly && !o.properties.empty()) refuse("--properties", "PLY");
  if (format != PointFormat::kHdf5 && !o.datasets.empty()) refuse("--dataset", "HDF5");
  if (format != PointFormat::kLas && o.las_filtered()) refuse("--las-classes and --las-returns", "LAS");
}

std::unique_ptr<PointReader> open_one(const std::string& path, const PointReadOptions& options, bool one_of_many) {
  PointFormat format = options.format;
  ScalarType type = options.type;
  if (!is_std_stream(path)) {
    const FormatGuess guess = format_from_extension(path);
    if (format == PointFormat::kAuto) format = guess.format;
    if (type == ScalarType::kAuto && format == guess.format) type = guess.type;
  }
  if (format == PointFormat::kHdf5) {
    check_applies(format, options, path);
    return detail::open_hdf5(path, options, one_of_many);
  }
  auto src = std::make_unique<ByteSource>(path, options.block_bytes);
  if (format == PointFormat::kAuto) {
    src->ensure(4096);
    if (src->available() == 0) throw InputError::at_byte(src->name(), 0, "empty input: no points");
    format = sniff_format(src->data(), src->available());
    // Not text, PLY, npy, LAS or HDF5, and the user named a scalar type (`--type f64`):
    // raw records of that type, as they said.
    if (format == PointFormat::kAuto && options.type != ScalarType::kAuto) format = PointFormat::kRaw;
    if (format == PointFormat::kAuto) {
      throw UsageError("cannot tell the format of " + src->name() +
                       ": name it with --format (raw, f32, f64, ply, npy, text, las, hdf5)");
    }
    if (format == PointFormat::kHdf5) {
      if (is_std_stream(path)) throw UsageError("HDF5 cannot be read from stdin: name the file");
      check_applies(format, options, path);
      src.reset();
      return detail::open_hdf5(path, options, one_of_many);
    }
  }
  check_applies(format, options, src->name());
  if (type == ScalarType::kAuto) type = ScalarType::kFloat64;

  switch (format) {
    case PointFormat::kRaw:
      return detail::open_raw(std::move(src), type, options);
    case PointFormat::kPly:
      return detail::open_ply(std::move(src), options);
    case PointFormat::kNpy:
      return detail::open_npy(std::move(src), options);
    case PointFormat::kText:
      return detail::open_text(std::move(src), options);
    case PointFormat::kLas:
      return detail::open_las(std::move(src), options);
    case PointFormat::kHdf5:
    case PointFormat::kAuto:
      break;
  }
  throw UsageError("no reader for " + path);
}

}  // namespace

std::uint64_t PointReader::skip(std::uint64_t n) {
  constexpr std::size_t kChunk = 1 << 14;
  std::vector<double> scratch(3 * kChunk);
  std::uint64_t done = 0;
  while (done < n) {
    const std::size_t got = read(scratch.data(), std::size_t(std::min<std::uint64_t>(kChunk, n - done)));
    if (got == 0) break;
    done += got;
  }
  return done;
}

void PointReadOptions::validate() const {
  const std::uint64_t w = type == ScalarType::kFloat32 ? 4 : 8;
  if (stride > kMaxRecordBytes) {
    throw UsageError("--stride " + std::to_string(stride) + " is larger than the largest record we read (" +
                     std::to_string(kMaxRecordBytes) + " bytes)");
  }
  std::uint64_t end = 0;
  if (stride != 0 && (!detail::checked_add(offset, 3 * w, end) || end > stride)) {
    throw UsageError("--offset " + std::to_string(offset) + " + 3 coordinates of " + std::to_string(w) +
                     " bytes do not fit in a record of --stride " + std::to_string(stride) + " bytes");
  }
  if (block_bytes < 4096) throw UsageError("read block must be at least 4096 bytes");
  if (!columns.empty()) {
    if (columns.size() != 3)
      throw UsageError("--columns takes three column numbers (x,y,z), got " + std::to_string(columns.size()));
    for (std::size_t i = 0; i < 3; ++i) {
      if (columns[i] == 0 || columns[i] > kMaxRecordBytes) {
        throw UsageError("--columns: column " + std::to_string(columns[i]) +
                         " is out of range (columns count from 1, at most " + std::to_string(kMaxRecordBytes) + ")");
      }
      for (std::size_t j = 0; j < i; ++j)
        if (columns[j] == columns[i])
          throw UsageError("--columns names column " + std::to_string(columns[i]) + " twice");
    }
  }
  if (!properties.empty()) {
    if (properties.size() != 3)
      throw UsageError("--properties takes three names (x,y,z), got " + std::to_string(properties.size()));
    for (std::size_t i = 0; i < 3; ++i) {
      if (properties[i].empty()) throw UsageError("--properties: empty property name");
      for (std::size_t j = 0; j < i; ++j)
        if (properties[j] == properties[i]) throw UsageError("--properties names '" + properties[i] + "' twice");
    }
  }
  for (const auto& d : datasets)
    if (d.empty()) throw UsageError("--dataset: empty dataset path");
  for (const auto& f : more_inputs)
    if (is_std_stream(f)) throw UsageError("stdin (-) cannot be one of several inputs");
}

std::string PointReadOptions::identity() const {
  std::vector<std::string> cols;
  for (auto c : columns) cols.push_back(std::to_string(c));
  return std::string("format=") + to_string(format) + " type=" + to_string(type) + " stride=" + std::to_string(stride) +
         " offset=" + std::to_string(offset) + " byte_order=" + to_string(byte_order) +
         " more_inputs=" + join(more_inputs) + " datasets=" + join(datasets) + " columns=" + join(cols) +
         " properties=" + join(properties) + las_identity();
}

std::string PointReadOptions::las_identity() const {
  std::string s;
  if (!las_classes.empty()) {
    std::vector<std::string> codes;
    for (auto c : las_classes) codes.push_back(std::to_string(c));
    s += " las_classes=" + join(codes);
  }
  if (las_returns != LasReturns::kAll)
    s += std::string(" las_returns=") + (las_returns == LasReturns::kLast ? "last" : "first");
  return s;
}

std::unique_ptr<PointReader> open_points(const std::string& path, const PointReadOptions& options) {
  options.validate();
  if (options.more_inputs.empty()) return open_one(path, options, false);
  if (is_std_stream(path)) throw UsageError("stdin (-) cannot be one of several inputs");
  std::vector<std::string> paths{path};
  paths.insert(paths.end(), options.more_inputs.begin(), options.more_inputs.end());
  PointReadOptions each = options;
  each.more_inputs.clear();
  return detail::open_concat(std::move(paths), [each](const std::string& p) { return open_one(p, each, true); });
}

std::vector<std::string> expand_inputs(const std::vector<std::string>& args) {
  std::vector<std::string> files;
  for (const auto& a : args) {
    if (is_std_stream(a) || is_regular_file(a) || a.find_first_of("*?[") == std::string::npos) {
      files.push_back(a);
      continue;
    }
    glob_t g{};
    const int rc = ::glob(a.c_str(), GLOB_ERR, nullptr, &g);
    std::vector<std::string> matches;
    if (rc == 0)
      for (std::size_t i = 0; i < g.gl_pathc; ++i) matches.emplace_back(g.gl_pathv[i]);
    ::globfree(&g);
    if (matches.empty()) throw IoError("cannot open " + a + ": no file matches the pattern");
    std::sort(matches.begin(), matches.end(), natural_less);
    files.insert(files.end(), matches.begin(), matches.end());
  }
  if (files.size() > 1 &&
      std::find_if(files.begin(), files.end(), [](const std::string& f) { return is_std_stream(f); }) != files.end())
    throw UsageError("stdin (-) cannot be one of several inputs");
  return files;
}

}  // namespace tetstream::io
