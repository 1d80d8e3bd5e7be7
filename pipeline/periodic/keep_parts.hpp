#pragma once
// What both keeps of a periodic job share (docs/periodic.md, "Keep", "Certify",
// "Write"): the keep in the padded job itself (keep_stage.hpp, one process) and the
// keep step after it (keep.hpp, under mpirun, from the padded container). A padded
// point's code word, the ball and edge tests, and the kept tets cut into frames.
#include "core/error.hpp"
#include "core/predicates.hpp"
#include "io/tet_periodic.hpp"
#include "pipeline/periodic/pad.hpp"
#include "pipeline/periodic/tet_records.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace tetstream::pipeline::periodic {

// A padded point's code word: its point's periodic label << 4 and its offset (bit k: -1
// on axis k): one word a vertex.
inline std::uint64_t code_plabel(std::uint64_t code) { return code >> 4; }
inline unsigned code_bits(std::uint64_t code) { return unsigned(code & 7); }

// The padded box's lower corner, -M rounded up (conservatively inside).
inline std::array<double, 3> padded_lower(const std::array<double, 3>& period, const std::array<double, 3>& margin) {
  std::array<double, 3> lower{};
  for (std::size_t k = 0; k < 3; ++k) {
    const double lo = (period[k] - margin[k]) - period[k];
    lower[k] = std::nextafter(std::nextafter(lo, 0.0), 0.0);
  }
  return lower;
}

// The box of circumcentres C = [t - L, t) on each axis, t = L - M/2 (canonical_threshold):
// a fundamental domain of the periods, so each periodic tet has one copy whose
// circumcentre lies in it, the copy kept (docs/periodic.md, "Keep"). With the padded
// box [-M, L) around it, `half_margin` is the least room between C and the padded box's
// faces (about M/2), rounded down.
struct CentreBox {
  std::array<double, 3> lo{}, hi{}, lower{}, period{};
  double half_margin = 0;
};
inline CentreBox centre_box(const std::array<double, 3>& period, const std::array<double, 3>& margin) {
  CentreBox b;
  b.period = period;
  b.lower = padded_lower(period, margin);
  b.half_margin = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < 3; ++k) {
    b.hi[k] = canonical_threshold(period[k], margin[k]);
    b.lo[k] = b.hi[k] - period[k];  // exact (Sterbenz: t >= L/2 for M <= L)
    const double room = std::min(b.lo[k] - b.lower[k], period[k] - b.hi[k]);
    b.half_margin = std::min(b.half_margin, std::nextafter(std::nextafter(room, 0.0), 0.0));
  }
  return b;
}

// A padded point's side of C on each axis: bit k below it (x_k < t_k - L_k), bit 3 + k
// at or past it (x_k >= t_k).
inline constexpr unsigned kBelowC = 1, kAboveC = 8, kOutsideC = 63;
inline unsigned centre_box_sides(const double* x, const CentreBox& b) {
  unsigned f = 0;
  for (int k = 0; k < 3; ++k)
    f |= (x[k] < b.lo[std::size_t(k)] ? kBelowC << k : 0u) | (x[k] >= b.hi[std::size_t(k)] ? kAboveC << k : 0u);
  return f;
}
// Whether a tet with vertices on these sides may meet C: its bounding box does unless
// all four lie below C, or all past it, on one axis.
inline bool may_meet_centre_box(const unsigned side[4]) {
  return (side[0] & side[1] & side[2] & side[3] & kOutsideC) == 0;
}

// The completeness condition of a padded tet that may meet C (docs/periodic.md,
// "Completeness"): at every point y of the tet the nearest padded point is nearer than
// the padded box's faces, so that no periodic point nearer lies outside the padded set.
// At y in the tet that distance is at most sqrt(r^2 - |y - c|^2) (the tet's vertices
// are on its sphere): within `half_margin` when r^2 - dist(c, C)^2 is below its square
// (for y in C), or inside the box whenever the ball of radius sqrt(2) r about c is. With
// the circumsphere's proved error bounds and a relative slack for these roundings.
inline bool covers_centre_box(const core::Circumsphere& s, const CentreBox& b) {
  if (!s.valid) return false;
  const double e = s.center_error * (1 + 0x1p-40);
  const double r = (s.radius + s.radius_error) * (1 + 0x1p-40);
  double d2 = 0;  // dist(c, C)^2, a lower bound
  for (std::size_t k = 0; k < 3; ++k) {
    const double c = s.center[k];
    const double gap = std::max({0.0, b.lo[k] - (c + e), (c - e) - b.hi[k]}) * (1 - 0x1p-40);
    d2 += gap * gap;
  }
  const double h = b.half_margin * (1 - 0x1p-40);
  if (r * r * (1 + 0x1p-40) - d2 * (1 - 0x1p-40) < h * h) return true;
  const double reach = (std::sqrt(2.0) * r + e) * (1 + 0x1p-40);
  for (std::size_t k = 0; k < 3; ++k) {
    const double c = s.center[k], slack = std::fabs(c) * 0x1p-50 + 0x1p-1000;
    if (!(c - reach - slack > b.lower[k]) || !(c + reach + slack < b.period[k])) return false;
  }
  return std::isfinite(reach);
}

// Whether the padded tet `p`'s circumcentre lies in C: from its sphere where the centre
// is clear of C's faces by the error bound, exactly (core::circumcentre_side) where it
// is not. Two copies of a tet differ by whole periods, exact translations, so exactly
// one of them answers true.
inline bool centre_in_box(const core::Circumsphere& s, const double* p[4], const CentreBox& b) {
  const auto side = [&](int k, double plane) {  // the sign of c_k - plane
    if (s.valid) {
      const double c = s.center[k];
      const double e = s.center_error * (1 + 0x1p-40) + (std::fabs(c) + std::fabs(plane)) * 0x1p-50 + 0x1p-1060;
      if (c - e > plane) return 1;
      if (c + e < plane) return -1;
    }
    return core::circumcentre_side(p[0], p[1], p[2], p[3], k, plane);
  };
  for (int k = 0; k < 3; ++k)
    if (side(k, b.lo[std::size_t(k)]) < 0 || side(k, b.hi[std::size_t(k)]) >= 0) return false;
  return true;
}

// CGAL's criterion for the 1-sheeted covering (Periodic_3_Delaunay_triangulation_3:
// every edge shorter than sqrt(0.166) times the period): an edge at or past it,
// conservatively, means this is not the triangulation CGAL defines in one sheet.
inline bool long_edge(const double* p[4], const std::array<double, 3>& period) {
  const double l = std::min({period[0], period[1], period[2]});
  const double limit = 0.166 * l * l * (1 - 0x1p-40);
  for (int i = 0; i < 4; ++i) {
    for (int j = i + 1; j < 4; ++j) {
      double d2 = 0;
      for (int k = 0; k < 3; ++k) d2 += (p[i][k] - p[j][k]) * (p[i][k] - p[j][k]);
      if (!(d2 < limit)) return true;
    }
  }
  return false;
}

inline InputError long_edges_error(const std::string& input, std::uint64_t long_edges) {
  return InputError(input + ": " + std::to_string(long_edges) +
                    " Delaunay tets have an edge of sqrt(0.166) periods or longer: the 1-sheeted covering is not "
                    "a triangulation of the torus by CGAL's criterion (too few points for the box; "
                    "docs/periodic.md, \"When it refuses\")");
}

inline bool stored_form_of(const std::uint64_t code[4], KeptTet& out) {
  std::uint64_t label[4];
  int off[4][3];
  for (int j = 0; j < 4; ++j) {
    label[j] = code_plabel(code[j]);
    for (int k = 0; k < 3; ++k) off[j][k] = -int(code_bits(code[j]) >> k & 1);
  }
  return stored_form(label, off, out);
}

// The kept tets, in the order of their smallest label m, cut into frames at group
// boundaries (a frame at the first new smallest label past `frame_tets` tets): each
// frame's labels and offset codes go to `emit` as it is cut, which takes them (leaving
// empty vectors, recycled ones best: a frame's fresh pages cost their zeroing). The
// frame being filled is what a checkpoint keeps.
//
// Within a group the tets may come in any order: the codec stores each group in the
// stored order whatever its labels' order, so only the offsets must follow that order
// themselves. A group whose tets all have the same offsets (almost all: the box's
// interior) is therefore left as it came, and the others are sorted (KeptTetLess).
class FrameFeeder {
 public:
  using Emit = std::function<void(std::vector<std::uint64_t>& labels, std::vector<std::uint16_t>& codes)>;
  FrameFeeder(Emit emit, std::size_t frame_tets) : emit_(std::move(emit)), frame_tets_(frame_tets) {}

  void add(std::span<const KeptTet> batch) {
    for (const KeptTet& t : batch) add_one(t);
  }
  // One tet: a full frame goes out before the next smallest label (the group of the
  // last one goes on past the frame's size).
  void add_one(const KeptTet& t) {
    if (codes_.empty() || t.v[0] != labels_[labels_.size() - 4]) {
      close_group();
      if (codes_.size() >= frame_tets_) flush();
      group_ = codes_.size();
    } else {
      mixed_ = mixed_ || t.code != codes_[group_];
    }
    // (Not a range insert: for four labels its call costs more than the copy.)
    const std::size_t at = labels_.size();
    labels_.resize(at + 4);
    std::copy_n(t.v, 4, labels_.data() + at);
    codes_.push_back(t.code);
    ++count_;
  }
  void flush() {
    if (codes_.empty()) return;
    close_group();
    emit_(labels_, codes_);
    labels_.clear();
    codes_.clear();
  }
  std::uint64_t count() const { return count_; }

  // The frame being filled, as tets; a resumed feeder's, with the count so far.
  std::vector<KeptTet> pending() const {
    std::vector<KeptTet> out(codes_.size());
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = tet(i);
    return out;
  }
  void restore(std::span<const KeptTet> pending, std::uint64_t count) {
    labels_.clear();
    codes_.clear();
    mixed_ = false;
    count_ = count - pending.size();
    add(pending);
  }

 private:
  KeptTet tet(std::size_t i) const {
    KeptTet t;
    std::copy(&labels_[4 * i], &labels_[4 * i] + 4, t.v);
    t.code = codes_[i];
    std::fill(std::begin(t.pad), std::end(t.pad), 0);
    return t;
  }
  // The group from group_ to the end, in the stored order when its offsets differ.
  void close_group() {
    if (!mixed_) return;
    mixed_ = false;
    group_tets_.clear();
    for (std::size_t i = group_; i < codes_.size(); ++i) group_tets_.push_back(tet(i));
    std::sort(group_tets_.begin(), group_tets_.end(), KeptTetLess{});
    for (std::size_t i = 0; i < group_tets_.size(); ++i) {
      std::copy(std::begin(group_tets_[i].v), std::end(group_tets_[i].v), &labels_[4 * (group_ + i)]);
      codes_[group_ + i] = group_tets_[i].code;
    }
  }

  Emit emit_;
  std::size_t frame_tets_;
  std::vector<std::uint64_t> labels_;
  std::vector<std::uint16_t> codes_;
  std::size_t group_ = 0;  // where the last group starts
  bool mixed_ = false;     // its offsets differ
  std::vector<KeptTet> group_tets_;
  std::uint64_t count_ = 0;
};

}  // namespace tetstream::pipeline::periodic
