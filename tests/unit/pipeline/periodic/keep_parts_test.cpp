// The periodic keep's choice of copies and its cover (pipeline/periodic/keep_parts.hpp,
// zone_keep.hpp): of a tet and its translates by whole periods exactly one has its
// circumcentre in the box of centres C, centres on C's faces included; the cover holds
// for small balls, for balls whose centres lie far from C, and fails for a ball about a
// centre in C that reaches past the padded box; a safe vertex's place says inner or
// outer only where every ball through it (below the grid's radius) agrees.
#include "pipeline/periodic/keep_parts.hpp"
#include "pipeline/periodic/zone_keep.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <span>
#include <utility>
#include <vector>

namespace tetstream::pipeline::periodic {
namespace {

using P3 = std::array<double, 3>;
const std::array<double, 3> kPeriod{1, 1, 1}, kMargin{0.25, 0.25, 0.25};

bool kept(const CentreBox& b, const std::array<P3, 4>& t) {
  const double* p[4] = {t[0].data(), t[1].data(), t[2].data(), t[3].data()};
  return centre_in_box(core::circumsphere(p[0], p[1], p[2], p[3]), p, b);
}

TEST(KeepParts, TheBoxOfCentresLiesHalfAMarginInsideThePaddedBox) {
  const CentreBox b = centre_box(kPeriod, kMargin);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(b.lo[k], -0.125);
    EXPECT_EQ(b.hi[k], 0.875);
    EXPECT_GE(b.lower[k], -0.25);
    EXPECT_LT(b.lower[k], -0.25 + 1e-12);
  }
  EXPECT_LE(b.half_margin, 0.125);
  EXPECT_GT(b.half_margin, 0.125 - 1e-12);
}

// Every tet, moved by whole periods to each of its 27 places, is kept at exactly one
// (coordinates on a grid of 2^-16, so that the moves are exact).
TEST(KeepParts, ExactlyOneCopyOfATetHasItsCentreInTheBox) {
  const CentreBox b = centre_box(kPeriod, kMargin);
  std::mt19937_64 rng(5);
  const auto grid = [&](double lo, double hi) {
    return lo + std::ldexp(double(rng() % (std::uint64_t(1) << 16)), -16) * (hi - lo);
  };
  int on_a_face = 0, checked = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::array<P3, 4> t;
    if (trial % 3 == 0) {
      // A box corner's tet: its centre the middle of the box, put exactly on a face of C.
      const double h = std::ldexp(double(1 + rng() % 64), -10);
      P3 c = {grid(-0.2, 0.95), grid(-0.2, 0.95), grid(-0.2, 0.95)};
      const int face = int(rng() % 3);
      c[std::size_t(face)] = rng() % 2 ? b.lo[std::size_t(face)] : b.hi[std::size_t(face)];
      const P3 x = {c[0] - h / 2, c[1] - h / 2, c[2] - h / 2};
      t = {P3{x[0], x[1], x[2]}, P3{x[0] + h, x[1], x[2]}, P3{x[0], x[1] + h, x[2]}, P3{x[0], x[1], x[2] + h}};
      ++on_a_face;
    } else {
      const P3 x = {grid(-0.2, 0.9), grid(-0.2, 0.9), grid(-0.2, 0.9)};
      for (auto& p : t)
        for (int k = 0; k < 3; ++k) p[std::size_t(k)] = x[std::size_t(k)] + grid(0, 0.05);
    }
    // A sliver's centre can lie periods away: only those one move can bring into C.
    const core::Circumsphere s = core::circumsphere(t[0].data(), t[1].data(), t[2].data(), t[3].data());
    bool near = s.valid;
    for (int k = 0; k < 3; ++k)
      near = near && s.center[k] > b.lo[std::size_t(k)] - 0.9 && s.center[k] < b.hi[std::size_t(k)] + 0.9;
    if (!near) continue;
    int copies = 0;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          std::array<P3, 4> moved = t;
          for (auto& p : moved) p[0] += dx, p[1] += dy, p[2] += dz;
          copies += kept(b, moved);
        }
    ASSERT_EQ(copies, 1) << "trial " << trial;
    ++checked;
  }
  EXPECT_GT(on_a_face, 900);
  EXPECT_GT(checked, 2500);
}

TEST(KeepParts, TheCoverHoldsForSmallBallsAndBallsFarFromTheBox) {
  const CentreBox b = centre_box(kPeriod, kMargin);
  const auto sphere = [](const std::array<P3, 4>& t) {
    return core::circumsphere(t[0].data(), t[1].data(), t[2].data(), t[3].data());
  };
  // A small tet in C: its ball well below half the margin.
  EXPECT_TRUE(
      covers_centre_box(sphere({P3{0.5, 0.5, 0.5}, P3{0.52, 0.5, 0.5}, P3{0.5, 0.52, 0.5}, P3{0.5, 0.5, 0.52}}), b));
  // A ball of radius 0.2 about a centre in C near its lower face: r > M/2 and the ball
  // of sqrt(2) r reaches past -M: the cover fails.
  const double r = 0.2;
  const P3 c = {-0.1, 0.5, 0.5};
  const std::array<P3, 4> big = {P3{c[0] + r, c[1], c[2]}, P3{c[0], c[1] + r, c[2]}, P3{c[0], c[1], c[2] + r},
                                 P3{c[0] - r, c[1], c[2]}};
  EXPECT_FALSE(covers_centre_box(sphere(big), b));
  // The same ball about a centre deep inside C: the ball of sqrt(2) r is inside.
  std::array<P3, 4> deep = big;
  for (auto& p : deep) p[0] += 0.6;
  EXPECT_TRUE(covers_centre_box(sphere(deep), b));
  // A huge flat tet at the padded box's lower face, its middle vertex nearer the face:
  // its centre far below, so its ball does not reach into C (r^2 - dist(c, C)^2 < 0);
  // with the middle vertex raised instead, the centre lies far above, the ball holds
  // most of C, and the cover fails.
  const double z = -0.24;
  const std::array<P3, 4> flat = {P3{z, 0.1, 0.1}, P3{z, 0.9, 0.1}, P3{z, 0.1, 0.9}, P3{z + 1e-3, 0.5, 0.5}};
  const core::Circumsphere s = sphere(flat);
  ASSERT_TRUE(s.valid);
  EXPECT_GT(s.radius, 100);
  EXPECT_LT(s.center[0], -100);
  EXPECT_TRUE(covers_centre_box(s, b));
  std::array<P3, 4> raised = flat;
  raised[3][0] = z - 1e-3;
  EXPECT_FALSE(covers_centre_box(sphere(raised), b));
}

TEST(KeepParts, ASafeVertexIsInnerOrOuterOnlyWhereEveryBallAgrees) {
  const CentreBox b = centre_box(kPeriod, kMargin);  // C = [-0.125, 0.875)^3, padded (-0.25, 1)^3
  const double radius = 0.05;
  const auto place = [&](P3 x, bool safe) { return vertex_place(x.data(), safe, radius, b); };
  EXPECT_TRUE(place({0.5, 0.5, 0.5}, true) & kInner);
  EXPECT_FALSE(place({0.5, 0.5, 0.5}, false) & (kInner | kSafe | kRoomy));  // not safe: no bound on its balls
  EXPECT_FALSE(place({-0.1, 0.5, 0.5}, true) & (kInner | kOuter));          // within the radius of a face
  EXPECT_FALSE(place({0.84, 0.5, 0.5}, true) & (kInner | kOuter));
  EXPECT_TRUE(place({-0.2, 0.5, 0.5}, true) & kOuter);
  EXPECT_TRUE(place({0.93, 0.5, 0.5}, true) & kOuter);
  // Roomy: (1 + sqrt(2)) x 0.05 = 0.1207 inside the padded box on every axis.
  EXPECT_TRUE(place({0.5, 0.5, 0.5}, true) & kRoomy);
  EXPECT_TRUE(place({-0.129, 0.878, 0.5}, true) & kRoomy);
  EXPECT_FALSE(place({-0.13, 0.5, 0.5}, true) & kRoomy);
  EXPECT_FALSE(place({0.5, 0.88, 0.5}, true) & kRoomy);
  // And a roomy vertex's balls pass the cover: spheres through it of radius up to the
  // bound, their centres in every direction.
  std::mt19937_64 rng(8);
  std::normal_distribution<double> g;
  for (const P3 x : {P3{-0.129, 0.5, 0.5}, P3{0.5, 0.878, 0.878}, P3{0.3, 0.6, -0.129}}) {
    ASSERT_TRUE(place(x, true) & kRoomy);
    for (int i = 0; i < 2000; ++i) {
      P3 d{g(rng), g(rng), g(rng)};
      const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      const double r = radius * (0.999 - 0.2 * (i % 5) / 5.0);
      core::Circumsphere s{};
      s.valid = true;
      for (int k = 0; k < 3; ++k) s.center[std::size_t(k)] = x[std::size_t(k)] + r * d[std::size_t(k)] / len;
      s.radius = r;
      s.center_error = s.radius_error = 1e-17;
      EXPECT_TRUE(covers_centre_box(s, b)) << i;
    }
  }
  EXPECT_EQ(place({-0.2, 0.5, 0.9}, false) & kOutsideC, kBelowC | (kAboveC << 2));
  const unsigned below_x[4] = {kBelowC, kBelowC, kBelowC | (kAboveC << 1), kBelowC};
  EXPECT_FALSE(may_meet_centre_box(below_x));
  const unsigned across[4] = {kBelowC, 0, kBelowC, kAboveC};
  EXPECT_TRUE(may_meet_centre_box(across));
}

}  // namespace
}  // namespace tetstream::pipeline::periodic

namespace tetstream::pipeline::periodic {
namespace {

// The feeder cuts its frames between groups of one smallest label, past the frame's
// size, whether it is handed spans (the keep after an MPI job) or one tet at a time
// (the keep's merge).
TEST(KeepParts, TheFeederMakesTheSameFramesFromOneTetAtATime) {
  std::mt19937_64 rng(5);
  std::vector<KeptTet> tets;
  std::uint64_t m = 0;
  for (int i = 0; i < 5000; ++i) {
    m += rng() % 3 == 0;  // groups of about three tets
    KeptTet t{};
    t.v[0] = m;
    for (int j = 1; j < 4; ++j) t.v[j] = m + 1 + rng() % 100;
    t.code = std::uint16_t(rng() % 19683);
    tets.push_back(t);
  }
  using Frames = std::vector<std::pair<std::vector<std::uint64_t>, std::vector<std::uint16_t>>>;
  for (const std::size_t frame : {std::size_t(1), std::size_t(7), std::size_t(64), std::size_t(10000)}) {
    Frames by_span, by_one;
    FrameFeeder spans([&](auto& l, auto& c) { by_span.push_back({l, c}); }, frame);
    FrameFeeder ones([&](auto& l, auto& c) { by_one.push_back({l, c}); }, frame);
    for (std::size_t i = 0; i < tets.size();) {
      const std::size_t n = std::min<std::size_t>(tets.size() - i, 1 + rng() % 50);
      spans.add(std::span<const KeptTet>(&tets[i], n));
      i += n;
    }
    for (const KeptTet& t : tets) ones.add_one(t);
    spans.flush();
    ones.flush();
    EXPECT_EQ(by_one, by_span) << "frames of " << frame;
    EXPECT_EQ(ones.count(), tets.size());
    // The frames hold every tet in order; every frame but the last at least the
    // frame's size, and no group across a cut.
    std::vector<std::uint64_t> all;
    for (const auto& [labels, codes] : by_one) all.insert(all.end(), labels.begin(), labels.end());
    ASSERT_EQ(all.size(), 4 * tets.size());
    for (std::size_t i = 0; i < tets.size(); ++i) EXPECT_EQ(all[4 * i], tets[i].v[0]);
    for (std::size_t f = 0; f + 1 < by_one.size(); ++f) {
      EXPECT_GE(by_one[f].second.size(), frame);
      const std::vector<std::uint64_t>& l = by_one[f].first;
      EXPECT_NE(l[l.size() - 4], by_one[f + 1].first[0]);
    }
  }
}

}  // namespace
}  // namespace tetstream::pipeline::periodic
