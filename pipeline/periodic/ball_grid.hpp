#pragma once
// Which padded points need no circumsphere for the keep's tests (docs/periodic.md,
// "Completeness", the grid): a grid of cubes of side c over the padded box, each
// marked when a padded point lies in it. A point v is *safe* when every cell within
// kReach cells of v's cell (Chebyshev distance) is marked and inside the padded box.
// Then every Delaunay ball of the padded set with v on its sphere has a radius below
// sqrt(3) c: a ball B through v of radius R >= sqrt(3) c would hold the ball B' of
// radius sqrt(3) c tangent to it at v, which lies within 2 sqrt(3) c < kReach c of v
// (inside the marked cells) and holds the cube of half-width c about its centre (its
// corners on B''s sphere), so a whole cell there: a padded point strictly inside B,
// which a Delaunay ball never has. So the ball lies within 2 sqrt(3) c of v: inside the
// padded box. (Which of the safe points are *roomy*, their balls' covers inside the
// padded box too, their coordinates say: zone_keep.hpp, vertex_place.)
//
// Rounding: a point marks a cell, and a vertex is placed in one, only when it lies in
// the cell's interior by a relative 2^-30 of the grid's extent (far beyond the
// rounding of (x - lower) / c); otherwise it marks nothing and is not safe.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline::periodic {

class BallGrid {
 public:
  static constexpr int kReach = 4;

  // The padded box from `lower` (inside -M) to the period; cells of side `cell`, fewer
  // when the grid would pass `max_cells`.
  BallGrid(const std::array<double, 3>& lower, const std::array<double, 3>& period, double cell,
           std::uint64_t max_cells = std::uint64_t(1) << 24) {
    for (;;) {
      std::uint64_t total = 1;
      for (std::size_t k = 0; k < 3; ++k) {
        // Whole cells inside [lower, L], one left out for the rounding of the extent.
        const double extent = period[k] - lower[k];
        n_[k] = std::max<std::int64_t>(0, std::int64_t(std::floor(extent / cell)) - 1);
        total *= std::uint64_t(std::max<std::int64_t>(n_[k], 1));
      }
      if (total <= max_cells) break;
      cell *= 1.25;
    }
    lower_ = lower;
    cell_ = cell;
    marked_.assign(std::size_t(n_[0] * n_[1] * n_[2]), 0);
  }

  // A padded point: its cell marked (by any number of threads at once).
  void mark(const double* p) {
    std::int64_t c[3];
    if (cell_of(p, c)) std::atomic_ref<std::uint8_t>(marked_[index(c)]).store(1, std::memory_order_relaxed);
  }

  // After every point is marked: the safe cells (all within kReach marked and inside).
  void finish() {
    safe_ = marked_;
    for (int axis = 0; axis < 3; ++axis) erode(axis);
  }

  bool safe(const double* p) const {
    std::int64_t c[3];
    return !safe_.empty() && cell_of(p, c) && safe_[index(c)];
  }

  std::uint64_t bytes() const { return marked_.size() + safe_.size(); }
  // The radius of every Delaunay ball through a safe point is below this (sqrt(3) c,
  // rounded up by far more than its rounding).
  double radius_bound() const { return std::sqrt(3.0) * cell_ * (1 + 0x1p-40); }
  // A ball through a safe point has a diameter below this: its tet's edges are shorter.
  double diameter_bound() const { return 2 * radius_bound(); }

 private:
  bool cell_of(const double* p, std::int64_t c[3]) const {
    for (std::size_t k = 0; k < 3; ++k) {
      const double t = (p[k] - lower_[k]) / cell_;
      const double f = std::floor(t);
      const double slack = 0x1p-30 * double(n_[k] + 1);
      if (!(f >= 0 && f < double(n_[k]) && t - f > slack && t - f < 1 - slack)) return false;
      c[k] = std::int64_t(f);
    }
    return true;
  }
  std::size_t index(const std::int64_t c[3]) const { return std::size_t((c[2] * n_[1] + c[1]) * n_[0] + c[0]); }

  // A cell stays safe only when the 2 kReach + 1 cells around it along `axis` are all
  // safe and inside: three such passes erode by the cube of half-width kReach.
  void erode(int axis) {
    const std::int64_t n = n_[std::size_t(axis)];
    const std::int64_t stride = axis == 0 ? 1 : axis == 1 ? n_[0] : n_[0] * n_[1];
    std::vector<std::uint8_t> line(std::size_t(std::max<std::int64_t>(n, 0)));
    std::vector<std::int64_t> bad_before(std::size_t(n + 1));
    for (std::int64_t start = 0; start < std::int64_t(safe_.size()); ++start) {
      // The first cell of each line along `axis`.
      if ((start / stride) % n != 0) continue;
      for (std::int64_t i = 0; i < n; ++i) line[std::size_t(i)] = safe_[std::size_t(start + i * stride)];
      bad_before[0] = 0;
      for (std::int64_t i = 0; i < n; ++i)
        bad_before[std::size_t(i + 1)] = bad_before[std::size_t(i)] + !line[std::size_t(i)];
      for (std::int64_t i = 0; i < n; ++i) {
        const bool inside = i - kReach >= 0 && i + kReach < n;
        safe_[std::size_t(start + i * stride)] =
            inside && bad_before[std::size_t(i + kReach + 1)] == bad_before[std::size_t(i - kReach)];
      }
    }
  }

  std::array<double, 3> lower_{};
  double cell_ = 1;
  std::int64_t n_[3] = {0, 0, 0};
  std::vector<std::uint8_t> marked_, safe_;
};

}  // namespace tetstream::pipeline::periodic
