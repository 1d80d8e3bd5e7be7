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
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace tetstream::pipeline::periodic {

// A padded point's code word: its point's periodic label << 4, its offset (bit k: -1 on
// axis k) and kCanonical when it is its point's canonical image: one word a vertex.
inline constexpr std::uint64_t kCanonical = 8;
inline std::uint64_t code_plabel(std::uint64_t code) { return code >> 4; }
inline unsigned code_bits(std::uint64_t code) { return unsigned(code & 7); }

// Whether a padded point at `xyz` with offset `bits` is its point's canonical image:
// on each axis at offset -1 exactly when its point lies at or past the threshold
// L - M/2 (`threshold`, canonical_threshold).
inline bool is_canonical(const double* xyz, unsigned bits, const std::array<double, 3>& period,
                         const double threshold[3]) {
  bool canonical = true;
  for (int a = 0; a < 3; ++a) {
    const bool minus = bits >> a & 1;
    const double p = minus ? xyz[a] + period[std::size_t(a)] : xyz[a];  // exact: the image was
    canonical = canonical && (minus == (p >= threshold[a]));
  }
  return canonical;
}

// The padded box's lower corner, -M rounded up (conservatively inside).
inline std::array<double, 3> padded_lower(const std::array<double, 3>& period, const std::array<double, 3>& margin) {
  std::array<double, 3> lower{};
  for (std::size_t k = 0; k < 3; ++k) {
    const double lo = (period[k] - margin[k]) - period[k];
    lower[k] = std::nextafter(std::nextafter(lo, 0.0), 0.0);
  }
  return lower;
}

// The circumball of a padded tet lies inside the padded box (-M, L)^3, with the
// circumsphere's proved error bounds and a relative slack for this test's own
// roundings: every periodic point it could hold is then in the padded set.
inline bool ball_inside(const double* p[4], const std::array<double, 3>& period, const std::array<double, 3>& lower) {
  const core::Circumsphere s = core::circumsphere(p[0], p[1], p[2], p[3]);
  if (!s.valid) return false;
  const double reach = (s.radius + s.radius_error + s.center_error) * (1 + 0x1p-40);
  for (std::size_t k = 0; k < 3; ++k) {
    const double slack = std::fabs(s.center[k]) * 0x1p-50 + 0x1p-1000;
    if (!(s.center[k] - reach - slack > lower[k]) || !(s.center[k] + reach + slack < period[k])) return false;
  }
  return std::isfinite(reach);
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

// A padded tet given by its vertices' code words: whether to certify it (a vertex at
// its canonical image) and whether it is kept (its smallest periodic label's vertex
// canonical: each orbit's one copy); its stored form when kept (false: not a tet of
// one period, a failure of the certificate).
struct Verdict {
  bool certify = false, kept = false;
};
inline Verdict judge(const std::uint64_t code[4]) {
  int mi = 0;
  bool any = false;
  for (int j = 0; j < 4; ++j) {
    any = any || (code[j] & kCanonical);
    mi = code_plabel(code[j]) < code_plabel(code[mi]) ? j : mi;
  }
  return {any, any && (code[mi] & kCanonical) != 0};
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

// The kept tets, in stored order, cut into frames at group boundaries (a frame at the
// first new smallest label past `frame_tets` tets): each frame's labels and offset
// codes go to `emit` as it is cut, which takes them (leaving empty vectors, recycled
// ones best: a frame's fresh pages cost their zeroing). The frame being filled is
// what a checkpoint keeps.
class FrameFeeder {
 public:
  using Emit = std::function<void(std::vector<std::uint64_t>& labels, std::vector<std::uint16_t>& codes)>;
  FrameFeeder(Emit emit, std::size_t frame_tets) : emit_(std::move(emit)), frame_tets_(frame_tets) {}

  void add(std::span<const KeptTet> batch) {
    for (const KeptTet& t : batch) {
      if (codes_.size() >= frame_tets_ && t.v[0] != labels_[labels_.size() - 4]) flush();
      labels_.insert(labels_.end(), t.v, t.v + 4);
      codes_.push_back(t.code);
      ++count_;
    }
  }
  void flush() {
    if (codes_.empty()) return;
    emit_(labels_, codes_);
    labels_.clear();
    codes_.clear();
  }
  std::uint64_t count() const { return count_; }

  // The frame being filled, as tets; a resumed feeder's, with the count so far.
  std::vector<KeptTet> pending() const {
    std::vector<KeptTet> out(codes_.size());
    for (std::size_t i = 0; i < out.size(); ++i) {
      std::copy(&labels_[4 * i], &labels_[4 * i] + 4, out[i].v);
      out[i].code = codes_[i];
      std::fill(std::begin(out[i].pad), std::end(out[i].pad), 0);
    }
    return out;
  }
  void restore(std::span<const KeptTet> pending, std::uint64_t count) {
    labels_.clear();
    codes_.clear();
    count_ = count - pending.size();
    add(pending);
  }

 private:
  Emit emit_;
  std::size_t frame_tets_;
  std::vector<std::uint64_t> labels_;
  std::vector<std::uint16_t> codes_;
  std::uint64_t count_ = 0;
};

}  // namespace tetstream::pipeline::periodic
