#include "pipeline/periodic/pad.hpp"

#include "core/error.hpp"
#include "io/tet_container.hpp"
#include "pipeline/files/checkpoint.hpp"
#include "pipeline/files/temp_files.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sstream>

namespace tetstream::pipeline::periodic {

bool exact_difference(double x, double l, double& out) {
  // TwoSum (Knuth): s + err = x - l exactly; the difference is a double iff err == 0.
  const double s = x - l;
  const double bv = s - x, av = s - bv;
  const double err = (x - av) + (-l - bv);
  out = s;
  return err == 0.0 && std::isfinite(s);
}

namespace {
constexpr std::size_t kChunk = std::size_t(1) << 16;

// A file written through PATH.tmp: fsynced when `durable` (a checkpointed job's, which
// a later start may find after a crash), then PATH replaced unless it already holds
// exactly these bytes (then it is left untouched, its modification time too).
class ReplacedFile {
 public:
  ReplacedFile(std::string path, bool durable)
      : path_(std::move(path)), file_(path_ + ".tmp", "wb"), durable_(durable) {}
  void write(const double* data, std::size_t n) {
    file_.write(data, sizeof(double), n);
    crc_ = io::crc32c(data, n * sizeof(double), crc_);
    bytes_ += n * sizeof(double);
  }
  // True when PATH was replaced (its bytes were not these).
  bool close() {
    file_.close(durable_);
    if (file_matches(path_, bytes_, crc_)) {
      remove_file(path_ + ".tmp");
      return false;
    }
    if (std::rename((path_ + ".tmp").c_str(), path_.c_str()) != 0)
      throw IoError(path_ + ": cannot rename into place: " + std::strerror(errno));
    return true;
  }

 private:
  std::string path_;
  BinaryFile file_;
  bool durable_;
  std::uint32_t crc_ = 0;
  std::uint64_t bytes_ = 0;
};

std::string coordinate_text(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

// Wraps one coordinate into [0, l) exactly; false when that is impossible (the
// result of fmod plus l rounds).
bool wrap_coordinate(double& x, double l) {
  double r = std::fmod(x, l);  // exact, with the sign of x
  if (r < 0) {
    double s;
    if (!exact_difference(r, -l, s) || s >= l) return false;
    r = s;
  }
  x = r + 0.0;  // -0.0 becomes 0.0
  return true;
}
}  // namespace

namespace {
// Reads the input a chunk at a time, each point checked and wrapped in place (or
// refused with its file and offset), -0.0 made 0.0; `chunk(xyz, n, changed)` gets each
// chunk and whether a coordinate of it changed, and stops the pass by returning false.
template <class Chunk>
void each_wrapped_chunk(io::PointReader& reader, const std::array<double, 3>& period, bool wrap, std::uint64_t& wrapped,
                        Chunk&& chunk) {
  std::vector<double> xyz(3 * kChunk);
  static const char* kAxis[3] = {"x", "y", "z"};
  std::uint64_t first = 0;
  while (const std::size_t n = reader.read(xyz.data(), kChunk)) {
    bool changed = false;
    for (std::size_t i = 0; i < n; ++i) {
      bool moved = false;
      for (int k = 0; k < 3; ++k) {
        double& x = xyz[3 * i + k];
        if (x >= 0 && x < period[k]) {
          changed = changed || std::signbit(x);
          x += 0.0;
          continue;
        }
        const std::string what = std::string(kAxis[k]) + " = " + coordinate_text(x) + " lies outside [0, " +
                                 coordinate_text(period[k]) + ")";
        if (!wrap) throw reader.error_at(first + i, what + " (--periodic-outside wrap wraps it)");
        if (!wrap_coordinate(x, period[k]))
          throw reader.error_at(first + i, what + " and cannot be wrapped exactly (x + L is not a double)");
        moved = true;
      }
      wrapped += moved;
      changed = changed || moved;
    }
    if (!chunk(xyz.data(), n, changed)) return;
    first += n;
  }
}

// Whether the padded job, which reads its points as raw float64 (24-byte records), reads
// this input's points as the user's options do: then an input inside the box, with no
// -0.0, is its own wrapped copy.
bool reads_as_raw_float64(const std::string& input, const io::PointReadOptions& read, const io::PointReader& reader) {
  // (A file of known size: a pipe could not be read twice.)
  return input != "-" && read.more_inputs.empty() && reader.count().has_value() &&
         reader.format_name() == "raw f64 little-endian";
}
}  // namespace

WrappedInput write_wrapped(const std::string& input, const io::PointReadOptions& read,
                           const std::array<double, 3>& period, bool wrap, const std::string& dir, bool durable,
                           std::optional<std::uint64_t> density_memory) {
  WrappedInput out;
  auto reader = io::open_points(input, read);
  // A fresh count for each pass (the copy after an in-place pass that found a point to wrap).
  const auto start_density = [&] {
    out.density.reset();
    if (density_memory && reader->count()) out.density.emplace(*reader->count(), period, *density_memory);
  };
  const auto count_density = [&](const double* xyz, std::size_t n) {
    if (out.density) out.density->add(xyz, n);
  };
  if (reads_as_raw_float64(input, read, *reader)) {
    // One pass that writes nothing: a point outside the box (or a -0.0) ends it, and
    // the copy below reads the input again.
    bool as_is = true;
    std::uint64_t wrapped = 0;
    start_density();
    each_wrapped_chunk(*reader, period, wrap, wrapped, [&](const double* xyz, std::size_t n, bool changed) {
      out.count += n;
      as_is = !changed;
      if (as_is) count_density(xyz, n);
      return as_is;
    });
    if (as_is) {
      out.path = input;
      out.as_is = true;
      return out;
    }
    out.count = 0;
    reader = io::open_points(input, read);
  }
  out.path = dir + "/periodic-points.f64";
  ReplacedFile file(out.path, durable);
  start_density();
  each_wrapped_chunk(*reader, period, wrap, out.wrapped, [&](const double* xyz, std::size_t n, bool) {
    file.write(xyz, 3 * n);
    count_density(xyz, n);
    out.count += n;
    return true;
  });
  out.rewritten = file.close();
  return out;
}

Images write_images(const WrappedInput& points, const std::array<double, 3>& period,
                    const std::array<double, 3>& margin, const std::string& dir, bool durable) {
  Images out;
  out.path = dir + "/periodic-images.f64";
  BinaryFile in(points.path, "rb");
  ReplacedFile file(out.path, durable);
  std::vector<double> xyz(3 * kChunk), img;
  std::uint64_t first = 0;
  double threshold[3];
  for (int k = 0; k < 3; ++k) threshold[k] = canonical_threshold(period[k], margin[k]);
  bool corner[8] = {};
  while (const std::size_t n = in.read(xyz.data(), 3 * sizeof(double), kChunk)) {
    img.clear();
    for (std::size_t i = 0; i < n; ++i) {
      const double* p = &xyz[3 * i];
      double shifted[3];
      unsigned near = 0;  // the axes on which p lies within the margin of the upper face
      for (int k = 0; k < 3; ++k) {
        if (p[k] < period[k] - margin[k]) continue;
        if (!exact_difference(p[k], period[k], shifted[k])) {
          throw InputError(points.path + ": point " + std::to_string(first + i) + ": its image " +
                           coordinate_text(p[k]) + " - " + coordinate_text(period[k]) +
                           " is not a double (the margin the certificate needs exceeds half the period: too few "
                           "points for the 1-sheeted covering, docs/periodic.md)");
        }
        near |= 1u << k;
      }
      // The corner cube it (or an image) lies in: on axis k above the threshold at
      // offset 0 (bit set), or between L - M and the threshold at offset -1.
      unsigned pattern = 0;
      for (int k = 0; k < 3; ++k) pattern |= (p[k] >= threshold[k] ? 1u : 0u) << k;
      if ((near | pattern) == 7) corner[pattern] = true;
      // Every non-empty subset of those axes: the images across faces, edges, corners.
      for (unsigned bits = 1; bits < 8; ++bits) {
        if ((bits & near) != bits) continue;
        for (int k = 0; k < 3; ++k) img.push_back((bits >> k & 1) ? shifted[k] : p[k]);
        out.code.push_back((first + i) * 8 + bits);
      }
    }
    file.write(img.data(), img.size());
    first += n;
  }
  out.rewritten = file.close();
  out.corners_full = std::all_of(corner, corner + 8, [](bool c) { return c; });
  return out;
}

}  // namespace tetstream::pipeline::periodic
