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

WrappedInput write_wrapped(const std::string& input, const io::PointReadOptions& read,
                           const std::array<double, 3>& period, bool wrap, const std::string& dir, bool durable) {
  WrappedInput out;
  out.path = dir + "/periodic-points.f64";
  auto reader = io::open_points(input, read);
  ReplacedFile file(out.path, durable);
  std::vector<double> xyz(3 * kChunk);
  static const char* kAxis[3] = {"x", "y", "z"};
  while (const std::size_t n = reader->read(xyz.data(), kChunk)) {
    for (std::size_t i = 0; i < n; ++i) {
      bool moved = false;
      for (int k = 0; k < 3; ++k) {
        double& x = xyz[3 * i + k];
        if (x >= 0 && x < period[k]) {
          x += 0.0;
          continue;
        }
        const std::uint64_t index = out.count + i;
        const std::string what = std::string(kAxis[k]) + " = " + coordinate_text(x) + " lies outside [0, " +
                                 coordinate_text(period[k]) + ")";
        if (!wrap) throw reader->error_at(index, what + " (--periodic-outside wrap wraps it)");
        if (!wrap_coordinate(x, period[k]))
          throw reader->error_at(index, what + " and cannot be wrapped exactly (x + L is not a double)");
        moved = true;
      }
      out.wrapped += moved;
    }
    file.write(xyz.data(), 3 * n);
    out.count += n;
  }
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
