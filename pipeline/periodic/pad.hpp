#pragma once
// The padded input of a periodic job (docs/periodic.md, "The padded set"): two raw
// float64 files in the job's directory that the ordinary job reads as one input.
//
//   periodic-points.f64   the N input points, wrapped into [0, L), in input order:
//                         the ordinary job's original index of a point is its own
//                         (not written when the input is a raw float64 file already
//                         inside the box, with no -0.0: the job reads that file);
//   periodic-images.f64   the images p + o L, o in {-1, 0}^3 \ {0}, of each point with
//                         p_k >= L_k - M_k on every axis k where o_k = -1: the periodic
//                         set inside [-M, L)^3 minus the box itself;
//   images (in memory)    for image j (original index N + j), point * 8 + bits, bit k
//                         set when o_k = -1.
//
// Every image coordinate is exact: p_k - L_k with p_k in [L_k/2, L_k) is a double
// (Sterbenz); for a margin above L/2 each one is checked, and an inexact one refused.
//
// Both files are deterministic (the input and the margin decide every byte), so a
// resumed job writes them again: each is written to NAME.tmp, fsynced, and replaces
// NAME only when its bytes differ (CRC32C and size). A file left in place keeps its
// modification time, so the checkpointed padded job (which fingerprints its input)
// resumes; `rewritten` says the bytes changed and the padded job's work is stale.
#include "io/point_reader.hpp"
#include "pipeline/periodic/margin.hpp"

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace tetstream::pipeline::periodic {

struct WrappedInput {
  std::string path;  // periodic-points.f64, or the input itself (as_is)
  std::uint64_t count = 0, wrapped = 0;
  bool as_is = false;      // the input is its own wrapped copy (raw float64, inside the box)
  bool rewritten = false;  // the file was not there with these bytes (never when as_is)
  // The wrapped points counted for the first margin as they were read (margin.hpp),
  // when asked and the input's count was known before it was read.
  std::optional<DensityGrid> density;
};

// Reads the input once and writes it wrapped (wrap) or refuses a point outside the
// box with its file and offset (InputError). A wrap is exact or refused. A raw float64
// input inside the box is not copied (as_is), a file the job only reads. `durable`:
// synced before it replaces an earlier one (a checkpointed job's; the same for images).
// `density_memory`: count the points for the first margin in the same pass, the grid
// within that many bytes (when the input tells its count before it is read).
WrappedInput write_wrapped(const std::string& input, const io::PointReadOptions& read,
                           const std::array<double, 3>& period, bool wrap, const std::string& dir, bool durable,
                           std::optional<std::uint64_t> density_memory = std::nullopt);

struct Images {
  std::string path;                 // periodic-images.f64
  std::vector<std::uint64_t> code;  // point * 8 + offset bits, in file order
  // Whether each of the padded box's 8 corner cubes of side M/2 holds a padded point:
  // then the box of centres is strictly inside the padded set's hull (keep.hpp).
  bool corners_full = false;
  bool rewritten = false;  // the file was not there with these bytes
};

// The images of the wrapped points within `margin` of the upper faces.
Images write_images(const WrappedInput& points, const std::array<double, 3>& period,
                    const std::array<double, 3>& margin, const std::string& dir, bool durable);

// The threshold t_k = L_k - M_k/2 (rounded once, here): the box of centres is
// [t - L, t) on each axis (keep_parts.hpp, centre_box).
inline double canonical_threshold(double period, double margin) { return period - 0.5 * margin; }

// x - l when it is a double, else nullopt-like false (error-free transformation).
bool exact_difference(double x, double l, double& out);

}  // namespace tetstream::pipeline::periodic
