#pragma once
// A zone's tets kept (keep_stage.hpp), on the thread that triangulated it: the
// cover of each tet that may meet the box of centres C, the copies whose circumcentres
// lie in C left in the zone's output, each turned to its stored rotation (m, a, b, c) and the
// output put in the order of m, so that a segment's zones only need merging. The
// zone's output comes grouped by smallest padded label, and for almost every kept tet
// that vertex is m (docs/periodic.md, "Why the padded order almost is the periodic
// one"): those groups are already in the order of m. The others (m is not the smallest
// padded vertex: an image across the sort axis' lower face, or a tie on the sort axis)
// are sorted apart, and those whose m has images across the sort axis' lower face (m at
// or past `deferred_from`, written last) put at the end:
//
//   tets = [ in order | sorted apart | deferred ]      (local ids, 4 a tet)
#include "core/compiler.hpp"
#include "pipeline/periodic/keep_parts.hpp"
#include "pipeline/periodic/tet_records.hpp"
#include "pipeline/window/zone_triangulator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

namespace tetstream::pipeline::periodic {

struct ZoneKept {
  std::vector<std::uint64_t> code;  // by local id: the code word of the window's point
  std::size_t in_order_end = 0, sorted_end = 0;
  std::uint64_t long_edges = 0;
  std::uint64_t certified = 0, balls = 0;  // tets that may meet C (covered); circumspheres computed
};

// The even rotation of a tet (its vertices v, code words c) that puts m (the smallest
// periodic label) first and the smallest of the others second (tet_records.hpp,
// stored_form). False when two of its periodic labels are equal (a tet across a whole
// period: the certificate fails).
namespace detail {
// For the first two places (s0, s1), the other two vertices in the order that makes
// (s0, s1, x, y) an even permutation of (0, 1, 2, 3).
struct EvenRest {
  std::int8_t rest[4][4][2];
  constexpr EvenRest() : rest{} {
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        if (a == b) continue;
        int x = -1, y = -1;
        for (int j = 0; j < 4; ++j)
          if (j != a && j != b) (x < 0 ? x : y) = j;
        const int p[4] = {a, b, x, y};
        int inversions = 0;
        for (int i = 0; i < 4; ++i)
          for (int j = i + 1; j < 4; ++j) inversions += p[i] > p[j];
        rest[a][b][0] = std::int8_t(inversions % 2 ? y : x);
        rest[a][b][1] = std::int8_t(inversions % 2 ? x : y);
      }
  }
};
inline constexpr EvenRest kEvenRest{};
}  // namespace detail

inline bool rotate_stored(int v[4], const std::uint64_t c[4]) {
  // The smallest and second smallest labels by selects (no branches to mispredict: the
  // labels come in any order), then the rest from the table.
  const std::uint64_t l[4] = {code_plabel(c[0]), code_plabel(c[1]), code_plabel(c[2]), code_plabel(c[3])};
  if ((l[0] == l[1]) | (l[0] == l[2]) | (l[0] == l[3]) | (l[1] == l[2]) | (l[1] == l[3]) | (l[2] == l[3])) return false;
  int s0 = 0;
  for (int j = 1; j < 4; ++j) s0 = l[j] < l[s0] ? j : s0;
  int s1 = s0 == 0 ? 1 : 0;
  for (int j = 1; j < 4; ++j) s1 = j != s0 && l[j] < l[s1] ? j : s1;
  const std::int8_t* rest = detail::kEvenRest.rest[s0][s1];
  const int w[4] = {v[s0], v[s1], v[rest[0]], v[rest[1]]};
  std::copy(w, w + 4, v);
  return true;
}

// A window point as the zone's keep reads it for every tet: its code word with its
// place (vertex_place, below) in the top bits, and its coordinate on the sort axis, 16
// bytes (the rest of its coordinates only for the tets whose balls are computed, from
// the worker's window). The periodic labels stay below 2^48 (keep_stage.cpp).
struct ZoneVertex {
  static constexpr int kPlaceShift = 52;
  static constexpr std::uint64_t kCodeMask = (std::uint64_t(1) << kPlaceShift) - 1;
  std::uint64_t word;
  double axis;

  std::uint64_t code() const { return word & kCodeMask; }
  unsigned place() const { return unsigned(word >> kPlaceShift); }
};

// The offsets' code of a tet whose four vertices are at offset 0.
inline constexpr std::uint16_t kNoOffsets = std::uint16_t(729 * 13 + 27 * 13 + 13);

// A kept tet's stored form from its rotated code words (no reads).
inline void kept_tet_into(const std::uint64_t c[4], KeptTet& t) {
  int o[3], codes[3];
  for (int j = 0; j < 4; ++j) t.v[j] = code_plabel(c[j]);
  std::fill(std::begin(t.pad), std::end(t.pad), 0);
  if (((c[0] | c[1] | c[2] | c[3]) & 7) == 0) {  // the box's interior: most tets
    t.code = kNoOffsets;
    return;
  }
  for (int j = 1; j < 4; ++j) {
    for (int k = 0; k < 3; ++k) o[k] = int(code_bits(c[0]) >> k & 1) - int(code_bits(c[j]) >> k & 1);
    codes[j - 1] = io::offset_code(o);
  }
  t.code = io::tet_offset_code(codes[0], codes[1], codes[2]);
}
inline KeptTet kept_tet_of(const std::uint64_t c[4]) {
  KeptTet t;
  kept_tet_into(c, t);
  return t;
}

// A kept tet's stored form from its rotated local ids and the zone's code words.
inline KeptTet kept_tet(const std::uint32_t* q, const std::vector<std::uint64_t>& code) {
  const std::uint64_t c[4] = {code[q[0]], code[q[1]], code[q[2]], code[q[3]]};
  return kept_tet_of(c);
}

// A window point's place, as the keep reads it for each of its tets (a bit field): its
// sides of C (keep_parts.hpp, centre_box_sides), whether it is safe in the ball grid
// (ball_grid.hpp: every Delaunay ball through it has a radius below the grid's bound
// R), and, when safe, whether it is roomy (those balls pass the cover:
// covers_centre_box's ball of radius sqrt(2) r about the centre, which lies within
// (1 + sqrt(2)) R of the point, inside the padded box), and whether every such ball has
// its centre in C (kInner: inside C by more than R on every axis) or outside it
// (kOuter: outside by R or more on one axis).
inline constexpr std::uint16_t kSafe = 64, kRoomy = 128, kInner = 256, kOuter = 512;
inline std::uint16_t vertex_place(const double* x, bool safe, double radius, const CentreBox& b) {
  std::uint16_t f = std::uint16_t(centre_box_sides(x, b));
  if (!safe) return f;
  f |= kSafe;
  const double r = radius * (1 + 0x1p-30);  // the roundings of the sums below, and more
  const double reach = (1 + std::sqrt(2.0)) * r;
  bool inner = true, outer = false, roomy = true;
  for (std::size_t k = 0; k < 3; ++k) {
    const double slack = std::fabs(x[k]) * 0x1p-50;  // the sums' roundings, wherever the box lies
    inner = inner && x[k] - r - slack > b.lo[k] && x[k] + r + slack < b.hi[k];
    outer = outer || x[k] + r + slack < b.lo[k] || x[k] - r - slack > b.hi[k];
    roomy = roomy && x[k] - reach - slack > b.lower[k] && x[k] + reach + slack < b.period[k];
  }
  return std::uint16_t(f | (inner ? kInner : 0) | (outer ? kOuter : 0) | (roomy ? kRoomy : 0));
}

// Certifies and keeps a zone's tets in place (above). `vx` by local id, and
// `xyz` the window's coordinates (3 a point); the sort axis decides which tets are in
// order: m strictly first on it is the tet's smallest padded vertex (the padded labels
// are the lexicographic order). A tet that may meet C passes the completeness condition
// (covers_centre_box: at once when it has a roomy vertex, else by its circumsphere); the
// tets whose circumcentre lies in C are kept (at once from a safe vertex that is inner or
// outer, else from the circumsphere, exactly near C's faces). False at the first tet
// that fails the condition: the margin must double. `safe_edges`: a tet with a safe
// vertex (its ball smaller than the grid's reach) has no edge as long as CGAL's limit.
// The last two are scratch.
//
// The run in order is in order by m only: the order within a group does not matter to
// the frames' labels (the codec puts each group in the stored order itself), and where
// it matters to their offsets, a group of tets with different offsets, the frame feeder
// sorts it (keep_parts.hpp, FrameFeeder).
inline bool keep_zone(ZoneTets& z, ZoneKept& k, const std::vector<ZoneVertex>& vx, const double* xyz,
                      const CentreBox& box, std::uint64_t deferred_from, bool safe_edges,
                      std::vector<std::pair<KeptTet, std::array<std::uint32_t, 4>>>& apart,
                      std::vector<std::uint32_t>& deferred) {
  apart.clear();
  deferred.clear();
  std::uint32_t* t = z.tets.data();
  const std::size_t tets = z.size();
  std::size_t kept = 0;
  const KeptTetLess less;
  const auto by_form = [&less](const auto& x, const auto& y) { return less(x.first, y.first); };
  bool in_order = true;
  std::uint64_t previous_m = 0;
  // A tet's vertices are read at random within a slab of the window (past the caches
  // at 10^6 points and more): each tet asks for those of the tet kAhead places on, and,
  // once they are in, for the coordinates of the tet kAhead / 2 places on when its
  // places say that its sphere will be computed (no roomy vertex, or no inner or outer one).
  constexpr std::size_t kAhead = 16, kHalf = kAhead / 2;
  const auto needs_sphere = [](unsigned any) { return !(any & kRoomy) || !(any & (kInner | kOuter)); };
  for (std::size_t i = 0; i < tets; ++i) {
    if (i + kAhead < tets)
      for (int j = 0; j < 4; ++j) TS_PREFETCH(&vx[t[4 * (i + kAhead) + std::size_t(j)]]);
    if (i + kHalf < tets) {
      const std::uint32_t* a = t + 4 * (i + kHalf);
      if (needs_sphere(vx[a[0]].place() | vx[a[1]].place() | vx[a[2]].place() | vx[a[3]].place()))
        for (int j = 0; j < 4; ++j) TS_PREFETCH(xyz + 3 * std::size_t(a[j]));
    }
    std::uint32_t v[4] = {t[4 * i], t[4 * i + 1], t[4 * i + 2], t[4 * i + 3]};
    const ZoneVertex* w[4] = {&vx[v[0]], &vx[v[1]], &vx[v[2]], &vx[v[3]]};
    const unsigned f[4] = {w[0]->place(), w[1]->place(), w[2]->place(), w[3]->place()};
    const unsigned any = f[0] | f[1] | f[2] | f[3];
    const double* p[4] = {xyz + 3 * std::size_t(v[0]), xyz + 3 * std::size_t(v[1]), xyz + 3 * std::size_t(v[2]),
                          xyz + 3 * std::size_t(v[3])};
    std::optional<core::Circumsphere> sphere;
    const auto ball = [&]() -> const core::Circumsphere& {
      if (!sphere) sphere = core::circumsphere(p[0], p[1], p[2], p[3]);
      return *sphere;
    };
    if (may_meet_centre_box(f)) {
      ++k.certified;
      if (!(any & kRoomy) && !covers_centre_box(ball(), box)) return false;
    }
    const bool in_c = (any & kInner) ? true : (any & kOuter) ? false : centre_in_box(ball(), p, box);
    k.balls += sphere.has_value();
    if (!in_c) continue;
    const std::uint64_t c[4] = {w[0]->code(), w[1]->code(), w[2]->code(), w[3]->code()};
    const bool small = (any & kSafe) != 0;
    int order[4] = {0, 1, 2, 3};
    if (!rotate_stored(order, c)) return false;
    if (!(small && safe_edges)) k.long_edges += long_edge(p, box.period);
    const std::uint64_t rc[4] = {c[order[0]], c[order[1]], c[order[2]], c[order[3]]};
    const std::array<std::uint32_t, 4> q = {v[order[0]], v[order[1]], v[order[2]], v[order[3]]};
    const double xm = vx[q[0]].axis;
    const bool first_on_axis = xm < vx[q[1]].axis && xm < vx[q[2]].axis && xm < vx[q[3]].axis;
    const std::uint64_t m = code_plabel(rc[0]);
    if (m >= deferred_from) {
      deferred.insert(deferred.end(), q.begin(), q.end());
    } else if (!first_on_axis) {
      apart.push_back({kept_tet_of(rc), q});
    } else {
      // Written back where the kept tets go: a kept tet's place is never past its own.
      in_order = in_order && m >= previous_m;
      previous_m = m;
      std::copy(q.begin(), q.end(), t + 4 * kept++);
    }
  }
  if (!in_order) {
    // A tie on the sort axis broke the groups' order: all of them sorted apart.
    for (std::size_t i = 0; i < kept; ++i) {
      std::array<std::uint32_t, 4> q;
      std::copy(t + 4 * i, t + 4 * i + 4, q.begin());
      std::uint64_t c[4];
      for (int j = 0; j < 4; ++j) c[j] = vx[q[std::size_t(j)]].code();
      apart.push_back({kept_tet_of(c), q});
    }
    kept = 0;
  }
  std::sort(apart.begin(), apart.end(), by_form);
  k.in_order_end = kept;
  k.sorted_end = kept + apart.size();
  z.tets.resize(4 * kept);
  for (const auto& [form, q] : apart) z.tets.insert(z.tets.end(), q.begin(), q.end());
  z.tets.insert(z.tets.end(), deferred.begin(), deferred.end());
  return true;
}

}  // namespace tetstream::pipeline::periodic
