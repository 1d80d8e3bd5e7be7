#pragma once
// The periodic job's first margin (docs/periodic.md, "The first margin"): a number of
// mean spacings, raised where the points near the box's faces are sparser than the
// mean. A void at a face holds Delaunay balls several mean spacings wide, which the
// first margin must cover (the keep needs the balls about centres near the box's faces
// to have radii below half of it): without the density's word the first attempt fails there and the
// job runs again at twice the margin. An estimate, not a proof: the certificate still
// decides, and the margin still doubles where it fails.
#include "pipeline/periodic/periodic.hpp"

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::pipeline::periodic {

// `spacings` mean spacings of the box's n points on each axis, at most half a period
// (where every image is exact by Sterbenz's lemma).
std::array<double, 3> mean_spacing_margin(const PeriodicOptions& p, std::uint64_t n);

struct DensityMargin {
  std::array<double, 3> margin{};
  std::array<double, 3> sparsest{1, 1, 1};  // per axis: the mean density over the sparsest near its faces
  std::uint64_t cells = 0;                  // the count grid's cells
};

// Counts the wrapped points (in [0, L), `count` of them) on a periodic grid of about 8
// points a cell, sums each cell's neighbourhood (at least ~1000 points of the mean
// density), and over the cells near each axis' faces (within the band the balls that
// could fail the keep's condition reach, docs/periodic.md) takes the sparsest: its
// spacing over the mean's, when above kSlack, multiplies `margin` on that axis. The
// grid takes at most `memory_bytes` / 4 (8 bytes a cell). Fed as the points are read
// (the pass that wraps them: pad.hpp), or from the wrapped file (margin_for_density).
class DensityGrid {
 public:
  DensityGrid(std::uint64_t count, const std::array<double, 3>& period, std::uint64_t memory_bytes);
  void add(const double* xyz, std::size_t n);  // n points, 3 doubles each
  // The margin from the counts (which it sums in place: once).
  DensityMargin margin(std::array<double, 3> margin) &&;

 private:
  std::uint64_t count_;
  std::array<double, 3> period_;
  std::array<std::int64_t, 3> n_{};
  std::vector<std::uint32_t> grid_;
};

// The same from the wrapped points' file (raw float64).
DensityMargin margin_for_density(const std::string& points_path, std::uint64_t count,
                                 const std::array<double, 3>& period, std::array<double, 3> margin,
                                 std::uint64_t memory_bytes);

// The mean-spacing margin already holds the balls of a density a little below the
// mean: its 4 spacings hold balls up to 2 spacings in radius (the keep's condition is a
// radius below M/2), and the largest empty
// ball among 10^7 uniform points is about 1.65 spacings (Poisson: n (4/3) pi r^3 ~
// ln n + ln ln n). A sparsest neighbourhood's spacing up to this factor of the mean
// leaves the margin as it is, which keeps uniform points' margin where it was.
inline constexpr double kSlack = 1.2;

}  // namespace tetstream::pipeline::periodic
