// The exact predicates (core/predicates.hpp) against independent exact references.
//
// References use boost::multiprecision (test code only): every double of one call is
// turned into an integer after scaling by a common power of two (the predicates are
// homogeneous, so the sign is unchanged), and
//   orient3d  = sign det[b-a, c-a, d-a];
//   insphere  = sign of the lifted polynomial I = sum_p O_p |p|^2 - O |e|^2 with O_p
//               the orientation with e in p's place (barycentric form on the raw
//               coordinates; the implementation uses the 4x4 determinant of the
//               differences to e), cross-checked against the circumcentre in rationals;
//   SoS       = the coefficient of the largest label in I + sum_p O_p eps_p - O eps_e.
// Every loop is seeded; the seed is in the SCOPED_TRACE and can be forced with
// TETSTREAM_TEST_SEED=<n> to replay a failure.
#include "core/predicates.hpp"
#include "tests/unit/test_points.hpp"

#include <gtest/gtest.h>

#include <boost/multiprecision/cpp_int.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

namespace tetstream::core {
namespace {

namespace tp = tetstream::test;
using boost::multiprecision::cpp_int;
using boost::multiprecision::cpp_rational;
using P3 = std::array<double, 3>;

std::uint64_t test_seed(std::uint64_t fallback) {
  if (const char* s = std::getenv("TETSTREAM_TEST_SEED")) return std::strtoull(s, nullptr, 10);
  return fallback;
}

#define SEEDED(var, value)                    \
  const std::uint64_t var = test_seed(value); \
  SCOPED_TRACE("seed " + std::to_string(var) + " (TETSTREAM_TEST_SEED)")

// ---- exact references ----------------------------------------------------------------

// x = mant * 2^exp with mant odd (or x == 0).
void decompose(double x, std::int64_t& mant, int& exp) {
  if (x == 0) {
    mant = 0;
    exp = 0;
    return;
  }
  int e;
  const double f = std::frexp(x, &e);
  mant = std::int64_t(std::ldexp(f, 53));
  exp = e - 53;
  while ((mant & 1) == 0) {
    mant /= 2;
    ++exp;
  }
}

using IP = std::array<cpp_int, 3>;

// The points as integers, all multiplied by the same power of two.
std::vector<IP> to_int(const std::vector<const double*>& pts) {
  int g = 1 << 20;
  for (const double* p : pts)
    for (int k = 0; k < 3; ++k) {
      std::int64_t m;
      int e;
      decompose(p[k], m, e);
      if (m != 0) g = std::min(g, e);
    }
  std::vector<IP> out(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      std::int64_t m;
      int e;
      decompose(pts[i][k], m, e);
      out[i][k] = m == 0 ? cpp_int(0) : cpp_int(m) << (e - g);
    }
  return out;
}

cpp_rational to_rational(double x) {
  std::int64_t m;
  int e;
  decompose(x, m, e);
  if (e >= 0) return cpp_rational(cpp_int(m) << e);
  return cpp_rational(cpp_int(m), cpp_int(1) << -e);
}

int sgn(const cpp_int& v) { return v.sign(); }

cpp_int det3(const IP& a, const IP& b, const IP& c, const IP& d) {
  const cpp_int ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const cpp_int vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const cpp_int wx = d[0] - a[0], wy = d[1] - a[1], wz = d[2] - a[2];
  return ux * (vy * wz - vz * wy) - uy * (vx * wz - vz * wx) + uz * (vx * wy - vy * wx);
}

int ref_orient3d(const double* a, const double* b, const double* c, const double* d) {
  const auto q = to_int({a, b, c, d});
  return sgn(det3(q[0], q[1], q[2], q[3]));
}

// I and the signs of its perturbation coefficients (a, b, c, d, e), barycentric form.
struct Lifted {
  int i_sign;
  int coef[5];
};

Lifted ref_lifted(const double* a, const double* b, const double* c, const double* d, const double* e) {
  const auto q = to_int({a, b, c, d, e});
  const cpp_int o = det3(q[0], q[1], q[2], q[3]);
  const cpp_int oa = det3(q[4], q[1], q[2], q[3]);
  const cpp_int ob = det3(q[0], q[4], q[2], q[3]);
  const cpp_int oc = det3(q[0], q[1], q[4], q[3]);
  const cpp_int od = det3(q[0], q[1], q[2], q[4]);
  const auto w = [&](int i) { return q[i][0] * q[i][0] + q[i][1] * q[i][1] + q[i][2] * q[i][2]; };
  const cpp_int lifted = oa * w(0) + ob * w(1) + oc * w(2) + od * w(3) - o * w(4);
  return {sgn(lifted), {sgn(oa), sgn(ob), sgn(oc), sgn(od), -sgn(o)}};
}

int ref_insphere(const double* a, const double* b, const double* c, const double* d, const double* e) {
  return ref_lifted(a, b, c, d, e).i_sign;
}

int ref_insphere_sos(const double* a, const double* b, const double* c, const double* d, const double* e,
                     const std::array<std::uint64_t, 5>& labels) {
  const Lifted l = ref_lifted(a, b, c, d, e);
  if (l.i_sign != 0) return l.i_sign;
  std::array<int, 5> order = {0, 1, 2, 3, 4};
  std::stable_sort(order.begin(), order.end(), [&](int i, int j) { return labels[i] > labels[j]; });
  for (int i : order)
    if (l.coef[i] != 0) return l.coef[i];
  return 0;
}

// a - (b-a) x (c-a): behind facet abc. Exact for the small integer-like inputs the
// tests feed it (checked).
P3 inner_point(const double* a, const double* b, const double* c) {
  const double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const P3 o = {a[0] - (uy * vz - uz * vy), a[1] - (uz * vx - ux * vz), a[2] - (ux * vy - uy * vx)};
  EXPECT_LT(ref_orient3d(a, b, c, o.data()), 0);
  return o;
}

// Reference of infinite_conflict_sos: the perturbed in-circle test through an exact
// inner point o = a - n (n the facet normal), built in integers, not as the
// implementation builds it.
int ref_infinite(const double* a, const double* b, const double* c, const double* e,
                 const std::array<std::uint64_t, 4>& labels) {
  const int s = ref_orient3d(a, b, c, e);
  if (s != 0) return s;
  const P3 o = inner_point(a, b, c);
  const std::uint64_t lowest = 0;
  return ref_insphere_sos(a, c, b, o.data(), e, {labels[0], labels[2], labels[1], lowest, labels[3]});
}

// ---- generators ------------------------------------------------------------------------

P3 random_point(tp::Rng& rng) { return {rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1)}; }

P3 grid_point(tp::Rng& rng, int k) { return {double(rng.below(k)), double(rng.below(k)), double(rng.below(k))}; }

// Moves x by `ulps` units in the last place (either direction).
double nudge(double x, int ulps) {
  for (int i = 0; i < std::abs(ulps); ++i) x = std::nextafter(x, ulps > 0 ? HUGE_VAL : -HUGE_VAL);
  return x;
}

const std::vector<P3>& sphere65() {  // x^2 + y^2 + z^2 = 65^2: hundreds of integer points
  static const std::vector<P3> pts = [] {
    const tp::Points p = tp::integer_sphere(65 * 65);
    std::vector<P3> out;
    for (std::size_t i = 0; i < tp::count(p); ++i) out.push_back({p[3 * i], p[3 * i + 1], p[3 * i + 2]});
    return out;
  }();
  return pts;
}

// Groups of >= 4 points of sphere65 on one plane (so on one circle).
const std::vector<std::vector<P3>>& cocircular_groups() {
  static const std::vector<std::vector<P3>> groups = [] {
    const int normals[][3] = {{0, 0, 1}, {1, 1, 0}, {1, -1, 0}, {1, 1, 1}, {1, -1, 1},
                              {1, 2, 0}, {1, 2, 3}, {2, -1, 1}, {3, 1, -2}};
    std::vector<std::vector<P3>> out;
    for (const auto& n : normals) {
      std::map<long, std::vector<P3>> by_key;
      for (const P3& p : sphere65()) by_key[long(n[0] * p[0] + n[1] * p[1] + n[2] * p[2])].push_back(p);
      for (auto& [key, g] : by_key)
        if (g.size() >= 4) out.push_back(g);
    }
    return out;
  }();
  return groups;
}

// An exact similarity that keeps integer cospherical points cospherical: a signed
// permutation of the axes, a power-of-two scale and an integer-valued offset.
struct Transform {
  int perm[3];
  double sign[3];
  int scale_exp;
  double offset[3];
  P3 operator()(const P3& p) const {
    P3 q;
    for (int k = 0; k < 3; ++k) q[k] = std::ldexp(sign[k] * p[perm[k]] + offset[k], scale_exp);
    return q;
  }
};

// mild: small scales and offsets only, so that test-side integer arithmetic on the
// transformed points (a - normal) stays exact in doubles.
Transform random_transform(tp::Rng& rng, bool mild = false) {
  Transform t;
  int perm[3] = {0, 1, 2};
  for (int i = 2; i > 0; --i) std::swap(perm[i], perm[rng.below(i + 1)]);
  static const double kOffsets[] = {0.0, 1.0, -37.0, 1e6, 0x1p40, -0x1p45};
  static const int kScales[] = {0, 0, -3, 5, -300, 300, -900, 800};
  const double off = kOffsets[rng.below(mild ? 5 : 6)];
  for (int k = 0; k < 3; ++k) {
    t.perm[k] = perm[k];
    t.sign[k] = rng.below(2) ? 1.0 : -1.0;
    t.offset[k] = off == 0.0 ? 0.0 : off + double(rng.below(1000));
  }
  t.scale_exp = kScales[rng.below(mild ? 4 : 8)];
  return t;
}

std::array<std::uint64_t, 5> random_labels(tp::Rng& rng) {
  std::array<std::uint64_t, 5> l;
  for (;;) {
    for (auto& x : l) x = rng.below(4) == 0 ? rng.below(8) : rng.next();  // small ones collide more
    std::array<std::uint64_t, 5> s = l;
    std::sort(s.begin(), s.end());
    if (std::adjacent_find(s.begin(), s.end()) == s.end()) return l;
  }
}

// Five points of one family; `kind` picks the family.
enum class Family { kRandom, kGrid, kNearCoplanar, kCospherical, kNearCospherical, kScaled10, kOffset, kMixed };
constexpr Family kFamilies[] = {
    Family::kRandom,          Family::kGrid,     Family::kNearCoplanar, Family::kCospherical,
    Family::kNearCospherical, Family::kScaled10, Family::kOffset,       Family::kMixed};
const char* family_name(Family f) {
  switch (f) {
    case Family::kRandom:
      return "random";
    case Family::kGrid:
      return "grid";
    case Family::kNearCoplanar:
      return "near-coplanar";
    case Family::kCospherical:
      return "cospherical";
    case Family::kNearCospherical:
      return "near-cospherical";
    case Family::kScaled10:
      return "scaled 1e-100..1e100";
    case Family::kOffset:
      return "large offset";
    case Family::kMixed:
      return "mixed magnitudes";
  }
  return "?";
}

std::array<P3, 5> five_points(Family f, tp::Rng& rng) {
  std::array<P3, 5> p;
  switch (f) {
    case Family::kRandom:
      for (auto& q : p) q = random_point(rng);
      break;
    case Family::kGrid: {
      const int k = 2 + int(rng.below(4));
      for (auto& q : p) q = grid_point(rng, k);
      break;
    }
    case Family::kNearCoplanar: {
      // e and d nearly on plane abc (exactly on it before rounding), then nudged.
      for (int i = 0; i < 3; ++i) p[i] = random_point(rng);
      for (int i = 3; i < 5; ++i) {
        const double s = rng.uniform(-1, 2), t = rng.uniform(-1, 2);
        for (int k = 0; k < 3; ++k) p[i][k] = p[0][k] + s * (p[1][k] - p[0][k]) + t * (p[2][k] - p[0][k]);
        const int k = int(rng.below(3));
        p[i][k] = nudge(p[i][k], int(rng.below(5)) - 2);
      }
      if (rng.below(2)) {  // anywhere from 1e-130 to 1e130: tiny spreads need rescaling
        const double scale = std::pow(10.0, double(int(rng.below(261)) - 130));
        for (auto& q : p)
          for (auto& x : q) x *= scale;
      }
      break;
    }
    case Family::kCospherical:
    case Family::kNearCospherical: {
      const auto& s = sphere65();
      const bool cocircular = rng.below(3) == 0;
      const auto& src = cocircular ? cocircular_groups()[rng.below(cocircular_groups().size())] : s;
      const Transform t = random_transform(rng);
      for (int i = 0; i < 5; ++i) p[i] = t(i < 4 ? src[rng.below(src.size())] : s[rng.below(s.size())]);
      if (f == Family::kNearCospherical) {
        const int i = int(rng.below(5)), k = int(rng.below(3));
        p[i][k] = nudge(p[i][k], rng.below(2) ? 1 : -1);
      }
      break;
    }
    case Family::kScaled10: {
      const double scale = std::pow(10.0, double(int(rng.below(201)) - 100));
      const bool cospherical = rng.below(2);
      for (auto& q : p) {
        const P3 base = cospherical ? sphere65()[rng.below(sphere65().size())] : random_point(rng);
        for (int k = 0; k < 3; ++k) q[k] = base[k] * scale;
      }
      break;
    }
    case Family::kOffset: {
      static const double kOffsets[] = {1e6, 0x1p40 + 0.5, 1e15, -3e9};
      const double off = kOffsets[rng.below(4)];
      const bool grid = rng.below(2);
      for (auto& q : p) {
        const P3 base = grid ? grid_point(rng, 3) : random_point(rng);
        for (int k = 0; k < 3; ++k) q[k] = off + base[k] * (grid ? 1.0 : 1e-3);
      }
      break;
    }
    case Family::kMixed: {
      // Coordinates of one call spanning up to 2^2000: subnormals next to 1e300.
      static const double kMags[] = {1e-310, 1e-300, 1e-150, 1.0, 1e150, 1e300, 5e-324};
      for (auto& q : p)
        for (int k = 0; k < 3; ++k) q[k] = rng.below(4) == 0 ? 0.0 : kMags[rng.below(7)] * rng.uniform(-1, 1);
      break;
    }
  }
  return p;
}

// ---- tests -------------------------------------------------------------------------

TEST(Predicates, KnownConventions) {
  const double a[3] = {0, 0, 0}, b[3] = {1, 0, 0}, c[3] = {0, 1, 0}, d[3] = {0, 0, 1};
  EXPECT_EQ(orient3d(a, b, c, d), 1);
  EXPECT_EQ(orient3d(a, c, b, d), -1);
  EXPECT_EQ(orient3d(a, b, c, a), 0);
  const double inside[3] = {0.25, 0.25, 0.25}, on[3] = {1, 1, 1}, outside[3] = {2, 2, 2};
  EXPECT_EQ(insphere(a, b, c, d, inside), 1);
  EXPECT_EQ(insphere(a, b, c, d, on), 0);
  EXPECT_EQ(insphere(a, b, c, d, outside), -1);
  // On the sphere: the tie goes to the largest label. e largest: e is lifted most,
  // so it is outside.
  EXPECT_EQ(insphere_sos(a, b, c, d, on, 1, 2, 3, 4, 5), -1);
  // a largest: raising a's lift raises the sphere's plane on a's side of bcd, where
  // (1,1,1) is not (barycentric coordinate of e w.r.t. a is 1 - 3 = -2 < 0).
  EXPECT_EQ(insphere_sos(a, b, c, d, on, 9, 2, 3, 4, 5), -1);
  // b largest: e's barycentric coordinate w.r.t. b is +1: inside.
  EXPECT_EQ(insphere_sos(a, b, c, d, on, 1, 9, 3, 4, 5), 1);
  // Hull facet (a,c,b) seen from outside (d inside the hull is on its negative side).
  EXPECT_EQ(orient3d(a, c, b, d), -1);
  const double below[3] = {0.2, 0.2, -1}, in_circle[3] = {0.3, 0.3, 0}, out_circle[3] = {2, 2, 0};
  EXPECT_EQ(infinite_conflict_sos(a, c, b, below, 1, 2, 3, 4), 1);
  EXPECT_EQ(infinite_conflict_sos(a, c, b, d, 1, 2, 3, 4), -1);
  EXPECT_EQ(infinite_conflict_sos(a, c, b, in_circle, 1, 2, 3, 4), 1);
  EXPECT_EQ(infinite_conflict_sos(a, c, b, out_circle, 1, 2, 3, 4), -1);
}

TEST(Predicates, Orient3dMatchesExact) {
  SEEDED(seed, 101);
  tp::Rng rng(seed);
  for (Family f : kFamilies) {
    SCOPED_TRACE(family_name(f));
    for (int it = 0; it < 1500; ++it) {
      const auto p = five_points(f, rng);
      const int got = orient3d(p[0].data(), p[1].data(), p[2].data(), p[4].data());
      const int want = ref_orient3d(p[0].data(), p[1].data(), p[2].data(), p[4].data());
      ASSERT_EQ(got, want) << "iteration " << it;
    }
  }
}

// Integer tets of volume +-1/6 with edges of 2^14..2^19 units: the filter fails and
// the exact value is the smallest nonzero multiple of the lattice step, right at the
// threshold of the lattice test (predicates.cpp, step 2).
TEST(Predicates, Orient3dUnimodularTets) {
  SEEDED(seed, 111);
  tp::Rng rng(seed);
  for (int it = 0; it < 3000; ++it) {
    double m[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    const double target = std::ldexp(1.0, 14 + int(rng.below(6)));
    for (double big = 1; big < target;) {
      const int i = int(rng.below(3)), j = (i + 1 + int(rng.below(2))) % 3;
      const double k = double(int(rng.below(7)) - 3);
      for (int c = 0; c < 3; ++c) {
        m[i][c] += k * m[j][c];
        big = std::max(big, std::fabs(m[i][c]));
      }
    }
    const int sc = int(rng.below(81)) - 40;
    P3 p[4];
    for (int c = 0; c < 3; ++c) p[0][c] = double(rng.below(1 << 20));
    for (int i = 1; i < 4; ++i)
      for (int c = 0; c < 3; ++c) p[i][c] = p[0][c] + m[i - 1][c];
    for (auto& q : p)
      for (auto& x : q) x = std::ldexp(x, sc);
    const int want = ref_orient3d(p[0].data(), p[1].data(), p[2].data(), p[3].data());
    ASSERT_NE(want, 0);
    ASSERT_EQ(orient3d(p[0].data(), p[1].data(), p[2].data(), p[3].data()), want) << "iteration " << it;
  }
}

TEST(Predicates, InsphereMatchesExact) {
  SEEDED(seed, 202);
  tp::Rng rng(seed);
  for (Family f : kFamilies) {
    SCOPED_TRACE(family_name(f));
    int zeros = 0, done = 0;
    for (int it = 0; done < 1500 && it < 20000; ++it) {
      auto p = five_points(f, rng);
      const int o = orient3d(p[0].data(), p[1].data(), p[2].data(), p[3].data());
      if (o == 0) continue;
      if (o < 0) std::swap(p[0], p[1]);
      const int got = insphere(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data());
      const int want = ref_insphere(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data());
      ASSERT_EQ(got, want) << "iteration " << it;
      zeros += want == 0;
      ++done;
    }
    EXPECT_EQ(done, 1500);
    if (f == Family::kGrid || f == Family::kCospherical) {
      EXPECT_GT(zeros, 50);  // the ties are exercised
    }
  }
}

// Exact evaluations whose coordinates span close to the limit of each integer width
// of the fallback (61, 125, 253 bits per coordinate, and the full double range):
// cospherical / coplanar points of size 2^E, one zero coordinate replaced by 2^(E-S).
TEST(Predicates, ExactAtIntegerWidthBoundaries) {
  SEEDED(seed, 121);
  tp::Rng rng(seed);
  std::vector<P3> with_zero;
  for (const P3& q : sphere65())
    if (q[0] == 0 || q[1] == 0 || q[2] == 0) with_zero.push_back(q);
  const int spans[] = {58,  59,  60,  61,  62,  63,  64,  65,  122, 123, 124,  125,  126,  127, 128,
                       129, 130, 250, 251, 252, 253, 254, 255, 256, 257, 1000, 2000, 2090, 2097};
  for (int span : spans) {
    SCOPED_TRACE("span " + std::to_string(span));
    for (int it = 0; it < 60; ++it) {
      // E = exponent bound of the largest coordinate (65 * 2^k < 2^(k+7)).
      const int lo_k = std::max(-1074 + span - 7, -1000), hi_k = 1016;
      if (lo_k > hi_k) break;
      const int k = lo_k + int(rng.below(hi_k - lo_k + 1));
      const int e_top = k + 7;
      const bool coplanar = it % 2 == 1;
      const auto& group = coplanar ? cocircular_groups()[rng.below(cocircular_groups().size())] : sphere65();
      std::array<P3, 5> p;
      for (int i = 0; i < 5; ++i) {
        const auto& src = i == 4 ? with_zero : group;
        p[i] = src[rng.below(src.size())];
        for (auto& x : p[i]) x = std::ldexp(x, k);
      }
      const int axis = p[4][0] == 0 ? 0 : (p[4][1] == 0 ? 1 : 2);
      p[4][axis] = std::ldexp(rng.below(2) ? 1.0 : -1.0, e_top - span);
      // orient3d of four (coplanar before the nudge when `coplanar`), then insphere.
      const int o = orient3d(p[0].data(), p[1].data(), p[2].data(), p[4].data());
      ASSERT_EQ(o, ref_orient3d(p[0].data(), p[1].data(), p[2].data(), p[4].data())) << "iteration " << it;
      const int t = orient3d(p[0].data(), p[1].data(), p[2].data(), p[3].data());
      if (t == 0) continue;
      if (t < 0) std::swap(p[0], p[1]);
      ASSERT_EQ(insphere(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data()),
                ref_insphere(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data()))
          << "iteration " << it;
    }
  }
}

// The sign convention, checked against geometry: the circumcentre in rationals.
TEST(Predicates, InsphereAgreesWithCircumcentre) {
  SEEDED(seed, 303);
  tp::Rng rng(seed);
  for (int it = 0; it < 300; ++it) {
    auto p = five_points(it % 2 ? Family::kRandom : Family::kGrid, rng);
    const int o = orient3d(p[0].data(), p[1].data(), p[2].data(), p[3].data());
    if (o == 0) continue;
    if (o < 0) std::swap(p[0], p[1]);
    std::array<std::array<cpp_rational, 3>, 5> r;
    for (int i = 0; i < 5; ++i)
      for (int k = 0; k < 3; ++k) r[i][k] = to_rational(p[i][k]);
    // Centre x solves 2 (p_i - a) . x = |p_i|^2 - |a|^2, i = b, c, d (Cramer).
    cpp_rational m[3][3], rhs[3];
    for (int i = 0; i < 3; ++i) {
      rhs[i] = 0;
      for (int k = 0; k < 3; ++k) {
        m[i][k] = 2 * (r[i + 1][k] - r[0][k]);
        rhs[i] += r[i + 1][k] * r[i + 1][k] - r[0][k] * r[0][k];
      }
    }
    const auto det = [](const cpp_rational(&x)[3][3]) {
      return x[0][0] * (x[1][1] * x[2][2] - x[1][2] * x[2][1]) - x[0][1] * (x[1][0] * x[2][2] - x[1][2] * x[2][0]) +
             x[0][2] * (x[1][0] * x[2][1] - x[1][1] * x[2][0]);
    };
    const cpp_rational dm = det(m);
    cpp_rational centre[3];
    for (int k = 0; k < 3; ++k) {
      cpp_rational mk[3][3];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) mk[i][j] = j == k ? rhs[i] : m[i][j];
      centre[k] = det(mk) / dm;
    }
    cpp_rational r2 = 0, e2 = 0;
    for (int k = 0; k < 3; ++k) {
      r2 += (r[0][k] - centre[k]) * (r[0][k] - centre[k]);
      e2 += (r[4][k] - centre[k]) * (r[4][k] - centre[k]);
    }
    const int want = r2 > e2 ? 1 : (r2 < e2 ? -1 : 0);
    ASSERT_EQ(insphere(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data()), want) << "iteration " << it;
  }
}

TEST(Predicates, InsphereSosMatchesReferenceAndNeverZero) {
  SEEDED(seed, 404);
  tp::Rng rng(seed);
  for (Family f : {Family::kGrid, Family::kCospherical, Family::kOffset, Family::kRandom}) {
    SCOPED_TRACE(family_name(f));
    int ties = 0;
    for (int it = 0; it < 2500; ++it) {
      auto p = five_points(f, rng);
      const int o = orient3d(p[0].data(), p[1].data(), p[2].data(), p[3].data());
      if (o == 0) continue;
      if (o < 0) std::swap(p[0], p[1]);
      const auto l = random_labels(rng);
      const int got =
          insphere_sos(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data(), l[0], l[1], l[2], l[3], l[4]);
      ASSERT_NE(got, 0) << "iteration " << it;
      ASSERT_EQ(got, ref_insphere_sos(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data(), l))
          << "iteration " << it;
      ties += insphere(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data()) == 0;
    }
    if (f == Family::kGrid || f == Family::kCospherical) {
      EXPECT_GT(ties, 100);
    }
  }
}

// Even permutations of (a,b,c,d) keep the answer; odd ones (negative orientation)
// reverse it: the perturbed polynomial is antisymmetric.
TEST(Predicates, InsphereSosPermutations) {
  SEEDED(seed, 505);
  tp::Rng rng(seed);
  int perm[4] = {0, 1, 2, 3};
  std::vector<std::array<int, 5>> perms;  // 4 indices + parity
  do {
    int inv = 0;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) inv += perm[i] > perm[j];
    perms.push_back({perm[0], perm[1], perm[2], perm[3], inv % 2 ? -1 : 1});
  } while (std::next_permutation(perm, perm + 4));
  for (int it = 0; it < 1500; ++it) {
    auto p = five_points(it % 2 ? Family::kGrid : Family::kCospherical, rng);
    const int o = orient3d(p[0].data(), p[1].data(), p[2].data(), p[3].data());
    if (o == 0) continue;
    if (o < 0) std::swap(p[0], p[1]);
    const auto l = random_labels(rng);
    const int base =
        insphere_sos(p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data(), l[0], l[1], l[2], l[3], l[4]);
    for (const auto& q : perms) {
      const int got = insphere_sos(p[q[0]].data(), p[q[1]].data(), p[q[2]].data(), p[q[3]].data(), p[4].data(), l[q[0]],
                                   l[q[1]], l[q[2]], l[q[3]], l[4]);
      ASSERT_EQ(got, q[4] * base) << "iteration " << it;
    }
  }
}

// Five cospherical points: under the perturbation exactly one of their two
// triangulations is Delaunay (the lower hull of the perturbed lifted points), so the
// tets whose fifth point is outside must tile the convex hull: the empty tets' volumes
// add up to half the sum over all (non-flat) tets, since the 2-tet and the 3-tet
// triangulation each cover the hull once. Also checks the shared-facet symmetry.
TEST(Predicates, FiveCosphericalPointsTriangulateUnderPerturbation) {
  SEEDED(seed, 606);
  tp::Rng rng(seed);
  int with_coplanar = 0;
  for (int it = 0; it < 1500; ++it) {
    const Transform t = random_transform(rng);
    std::array<P3, 5> p;
    const bool cocircular = it % 3 == 0;
    const auto& group = cocircular ? cocircular_groups()[rng.below(cocircular_groups().size())] : sphere65();
    for (int i = 0; i < 5; ++i) {
      const auto& src = i < 4 ? group : sphere65();
      p[i] = t(src[rng.below(src.size())]);
    }
    bool distinct = true;
    for (int i = 0; i < 5; ++i)
      for (int j = i + 1; j < 5; ++j) distinct = distinct && p[i] != p[j];
    if (!distinct) continue;
    const auto l = random_labels(rng);
    const auto q = to_int({p[0].data(), p[1].data(), p[2].data(), p[3].data(), p[4].data()});
    cpp_int all = 0, empty = 0;
    int n_empty = 0, n_flat = 0;
    int empty_of[5];
    for (int x = 0; x < 5; ++x) {
      std::array<int, 4> v;
      for (int i = 0, k = 0; i < 5; ++i)
        if (i != x) v[k++] = i;
      const int o = orient3d(p[v[0]].data(), p[v[1]].data(), p[v[2]].data(), p[v[3]].data());
      empty_of[x] = 0;
      if (o == 0) {
        ++n_flat;
        continue;
      }
      if (o < 0) std::swap(v[0], v[1]);
      const cpp_int vol = abs(det3(q[v[0]], q[v[1]], q[v[2]], q[v[3]]));
      all += vol;
      const int s = insphere_sos(p[v[0]].data(), p[v[1]].data(), p[v[2]].data(), p[v[3]].data(), p[x].data(), l[v[0]],
                                 l[v[1]], l[v[2]], l[v[3]], l[x]);
      ASSERT_NE(s, 0);
      empty_of[x] = s < 0 ? 1 : -1;
      if (s < 0) {
        empty += vol;
        ++n_empty;
      }
    }
    if (n_flat == 5) continue;  // five co-circular points: no tets at all
    with_coplanar += n_flat > 0;
    ASSERT_LE(n_flat, 1) << "iteration " << it;  // two flat quadruples share 3 points: all 5 flat
    ASSERT_EQ(2 * empty, all) << "iteration " << it;
    ASSERT_TRUE(n_flat == 1 ? n_empty == 2 : (n_empty == 2 || n_empty == 3)) << "iteration " << it;
    // Two tets sharing a facet, x and y opposite: both empty or both not.
    for (int x = 0; x < 5; ++x)
      for (int y = x + 1; y < 5; ++y) {
        if (empty_of[x] == 0 || empty_of[y] == 0) continue;
        // Facet = the other three; x and y on opposite sides iff the two tets
        // (facet + x) and (facet + y) do not overlap, which for five points in
        // convex position is when segment xy crosses the facet's plane.
        std::array<int, 3> f;
        for (int i = 0, k = 0; i < 5; ++i)
          if (i != x && i != y) f[k++] = i;
        const int sx = orient3d(p[f[0]].data(), p[f[1]].data(), p[f[2]].data(), p[x].data());
        const int sy = orient3d(p[f[0]].data(), p[f[1]].data(), p[f[2]].data(), p[y].data());
        if (sx * sy < 0) {  // tet(f+x) tested with y, tet(f+y) tested with x
          ASSERT_EQ(empty_of[y], empty_of[x]) << "iteration " << it;
        }
      }
  }
  EXPECT_GT(with_coplanar, 50);
}

// The hull-facet test agrees with every finite tet on either side of the facet when e
// is coplanar (in particular co-circular): the Devillers-Teillaud limit of the
// spheres through a, b, c and a point running to infinity. This is what keeps the
// kernel's cavity a connected star around e.
TEST(Predicates, InfiniteConflictAgreesWithFiniteTets) {
  SEEDED(seed, 707);
  tp::Rng rng(seed);
  int cocircular = 0, coplanar = 0, conflicts = 0;
  for (int it = 0; it < 2000; ++it) {
    const auto& g = cocircular_groups()[rng.below(cocircular_groups().size())];
    std::array<std::size_t, 4> idx;
    for (;;) {
      for (auto& i : idx) i = rng.below(g.size());
      std::array<std::size_t, 4> s = idx;
      std::sort(s.begin(), s.end());
      if (std::adjacent_find(s.begin(), s.end()) == s.end()) break;
    }
    const Transform tr = random_transform(rng, /*mild=*/true);
    P3 a = g[idx[0]], b = g[idx[1]], c = g[idx[2]], e = g[idx[3]];
    if (it % 4 == 3) {  // coplanar, usually not on the circle
      const double s = double(int(rng.below(7)) - 3), t = double(int(rng.below(7)) - 3);
      for (int k = 0; k < 3; ++k) e[k] = a[k] + s * (b[k] - a[k]) + t * (c[k] - a[k]);
    }
    if (it % 8 == 7) e = grid_point(rng, 80);  // anywhere
    a = tr(a);
    b = tr(b);
    c = tr(c);
    e = tr(e);
    // Orient the facet: a random side is the inside.
    if (rng.below(2)) std::swap(b, c);
    const int side = orient3d(a.data(), b.data(), c.data(), e.data());
    if (e == a || e == b || e == c) continue;
    const std::array<std::uint64_t, 4> l4 = [&] {
      const auto l = random_labels(rng);
      return std::array<std::uint64_t, 4>{l[0], l[1], l[2], l[3]};
    }();
    const int got = infinite_conflict_sos(a.data(), b.data(), c.data(), e.data(), l4[0], l4[1], l4[2], l4[3]);
    ASSERT_NE(got, 0) << "iteration " << it;
    ASSERT_EQ(got, ref_infinite(a.data(), b.data(), c.data(), e.data(), l4)) << "iteration " << it;
    conflicts += got > 0;
    if (side != 0) {
      ASSERT_EQ(got, side);
      continue;
    }
    ++coplanar;
    cocircular +=
        insphere(a.data(), c.data(), b.data(), inner_point(a.data(), b.data(), c.data()).data(), e.data()) == 0;
    // Finite tets behind (a,c,b,d) and in front (a,b,c,d) of the facet.
    for (int k = 0; k < 12; ++k) {
      P3 d = grid_point(rng, 200);
      for (auto& x : d) x -= 100;
      d = tr(d);
      const int o = orient3d(a.data(), b.data(), c.data(), d.data());
      if (o == 0) continue;
      const int fin =
          o < 0
              ? insphere_sos(a.data(), c.data(), b.data(), d.data(), e.data(), l4[0], l4[2], l4[1], rng.next(), l4[3])
              : insphere_sos(a.data(), b.data(), c.data(), d.data(), e.data(), l4[0], l4[1], l4[2], rng.next(), l4[3]);
      ASSERT_EQ(fin, got) << "iteration " << it << " d side " << o;
    }
  }
  EXPECT_GT(coplanar, 500);
  EXPECT_GT(cocircular, 200);
  EXPECT_GT(conflicts, 100);
}

// The exact circumcentre of a tet, as its first vertex (`corner`) and the offset from
// it: N / D with u, v, w the edges from the first vertex, N = |u|^2 (v x w) + |v|^2
// (w x u) + |w|^2 (u x v), D = 2 u.(v x w). Not valid when D = 0 (a flat tet).
struct ExactCentre {
  bool valid = false;
  cpp_rational corner[3], offset[3];
};
ExactCentre exact_centre(const std::array<P3, 4>& p) {
  std::array<std::array<cpp_rational, 3>, 4> r;
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) r[i][k] = to_rational(p[i][k]);
  cpp_rational u[3], v[3], w[3];
  for (int k = 0; k < 3; ++k) u[k] = r[1][k] - r[0][k], v[k] = r[2][k] - r[0][k], w[k] = r[3][k] - r[0][k];
  const auto cross = [](const cpp_rational* x, const cpp_rational* y, int k) {
    const int i = (k + 1) % 3, j = (k + 2) % 3;
    return x[i] * y[j] - x[j] * y[i];
  };
  const auto dot = [](const cpp_rational* x, const cpp_rational* y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
  const cpp_rational den = 2 * (u[0] * cross(v, w, 0) + u[1] * cross(v, w, 1) + u[2] * cross(v, w, 2));
  ExactCentre e;
  for (int k = 0; k < 3; ++k) e.corner[k] = r[0][k];
  if (den == 0) return e;
  e.valid = true;
  for (int k = 0; k < 3; ++k)
    e.offset[k] = (dot(u, u) * cross(v, w, k) + dot(v, v) * cross(w, u, k) + dot(w, w) * cross(u, v, k)) / den;
  return e;
}

// circumsphere(): the bound must contain the exact centre and radius.
TEST(Predicates, CircumsphereBoundIsSound) {
  SEEDED(seed, 808);
  tp::Rng rng(seed);
  int valid = 0, invalid = 0, huge = 0;
  for (int it = 0; it < 3750; ++it) {
    std::array<P3, 4> p;
    const int kind = it % 5;
    for (auto& q : p) q = random_point(rng);
    if (kind == 4) {  // LiDAR-like: a tilted plane quantised to 1 cm, UTM-sized offsets (the double-word path)
      for (auto& q : p) {
        const double gx = double(rng.below(2000)), gy = double(rng.below(2000));
        const double gz = std::round(0.3 * gx + 0.1 * gy) + double(rng.below(3)) - 1.0;
        q = {512345.0 + gx / 100, 4123456.0 + gy / 100, 100.0 + gz / 100};
      }
    } else if (kind >= 1) {  // nearly flat: d close to plane abc
      const double s = rng.uniform(-1, 2), t = rng.uniform(-1, 2);
      const double h = std::pow(10.0, -rng.uniform(0, 17));
      for (int k = 0; k < 3; ++k) p[3][k] = p[0][k] + s * (p[1][k] - p[0][k]) + t * (p[2][k] - p[0][k]);
      p[3][rng.below(3)] += h;
    }
    if (kind == 2) {  // scaled and offset
      const double sc = std::pow(10.0, double(int(rng.below(121)) - 60));
      const double off = rng.below(2) ? 1e7 * sc : 0.0;
      for (auto& q : p)
        for (auto& x : q) x = x * sc + off;
    }
    if (kind == 3) {  // integer cospherical tets are exact-friendly
      const Transform t = random_transform(rng);
      for (auto& q : p) q = t(sphere65()[rng.below(sphere65().size())]);
    }
    const int o = orient3d(p[0].data(), p[1].data(), p[2].data(), p[3].data());
    if (o == 0) continue;
    if (o < 0) std::swap(p[0], p[1]);
    const Circumsphere cs = circumsphere(p[0].data(), p[1].data(), p[2].data(), p[3].data());
    if (!cs.valid) {
      ++invalid;
      continue;
    }
    ++valid;
    ASSERT_GE(cs.center_error, 0);
    ASSERT_GE(cs.radius_error, 0);
    const ExactCentre ec = exact_centre(p);
    cpp_rational r2 = 0;
    for (int k = 0; k < 3; ++k) {
      const cpp_rational& x = ec.offset[k];
      r2 += x * x;
      const cpp_rational err = abs(ec.corner[k] + x - to_rational(cs.center[k]));
      ASSERT_LE(err, to_rational(cs.center_error)) << "iteration " << it << " axis " << k;
    }
    const cpp_rational lo = to_rational(cs.radius) - to_rational(cs.radius_error);
    const cpp_rational hi = to_rational(cs.radius) + to_rational(cs.radius_error);
    if (lo > 0) {
      ASSERT_LE(lo * lo, r2) << "iteration " << it;
    }
    ASSERT_LE(r2, hi * hi) << "iteration " << it;
    // Tight enough to be useful on every shape, the flattest included (their huge
    // balls are where the pipeline's queries would otherwise scan slabs of points):
    // the fast path is taken only when its bound is within 2^-36 of the tet's extent,
    // the exact path is within a few ulps of the offset and the centre.
    double extent = 0;
    for (int i = 1; i < 4; ++i)
      for (int k = 0; k < 3; ++k) extent = std::max(extent, std::fabs(p[i][k] - p[0][k]));
    const double centre = std::max({std::fabs(cs.center[0]), std::fabs(cs.center[1]), std::fabs(cs.center[2])});
    EXPECT_LE(cs.center_error, 2e-11 * extent + 1e-15 * (centre + cs.radius)) << "iteration " << it;
    EXPECT_LE(cs.radius_error, 4e-11 * extent + 2e-15 * cs.radius) << "iteration " << it;
    if (kind == 1 && cs.radius > 1e9 * std::max(1.0, std::fabs(p[0][0]))) ++huge;
  }
  EXPECT_GT(valid, 3200);
  EXPECT_EQ(invalid, 0);  // only an exactly flat tet (skipped above) has no sphere
  EXPECT_GT(huge, 20);    // the exact path was exercised
}

// circumcentre_side(): the exact sign of the centre's coordinate against a plane, on
// planes through the centre (rounded, and the doubles either side of it) and through
// exactly representable centres, against rational arithmetic.
TEST(Predicates, CircumcentreSideIsExact) {
  SEEDED(seed, 809);
  tp::Rng rng(seed);
  int zeros = 0, checked = 0;
  for (int it = 0; it < 2000; ++it) {
    std::array<P3, 4> p;
    for (auto& q : p) q = random_point(rng);
    if (it % 4 == 1) {  // nearly flat: the centre far away
      const double s = rng.uniform(-1, 2), t = rng.uniform(-1, 2);
      for (int k = 0; k < 3; ++k) p[3][k] = p[0][k] + s * (p[1][k] - p[0][k]) + t * (p[2][k] - p[0][k]);
      p[3][rng.below(3)] += std::pow(10.0, -rng.uniform(0, 12));
    } else if (it % 4 == 2) {  // a box's corners: the centre a double, on the plane exactly
      const double x = double(rng.below(64)) / 8, y = double(rng.below(64)) / 8, z = double(rng.below(64)) / 8;
      const double h = double(1 + rng.below(16)) / 4;
      p = {P3{x, y, z}, P3{x + h, y, z}, P3{x, y + h, z}, P3{x, y, z + h}};
    }
    const ExactCentre ec = exact_centre(p);
    if (!ec.valid) {
      EXPECT_EQ(circumcentre_side(p[0].data(), p[1].data(), p[2].data(), p[3].data(), 0, 0.5), 0);
      continue;
    }
    for (int axis = 0; axis < 3; ++axis) {
      const cpp_rational c = ec.corner[axis] + ec.offset[axis];
      const double near = static_cast<double>(c);
      for (const double t : {near, std::nextafter(near, -INFINITY), std::nextafter(near, INFINITY), near * 0.5}) {
        if (!std::isfinite(t)) continue;
        const cpp_rational d = c - to_rational(t);
        const int want = d > 0 ? 1 : d < 0 ? -1 : 0;
        ASSERT_EQ(circumcentre_side(p[0].data(), p[1].data(), p[2].data(), p[3].data(), axis, t), want)
            << "iteration " << it << " axis " << axis << " t " << t;
        // The order of the vertices does not matter.
        ASSERT_EQ(circumcentre_side(p[2].data(), p[0].data(), p[3].data(), p[1].data(), axis, t), want);
        zeros += want == 0;
        ++checked;
      }
    }
  }
  EXPECT_GT(zeros, 300);  // centres exactly on the plane were met
  EXPECT_GT(checked, 20000);
}

TEST(Predicates, StatsCountFilterFailures) {
  reset_predicate_stats();
  const double a[3] = {0, 0, 0}, b[3] = {1, 0, 0}, c[3] = {0, 1, 0}, d[3] = {0, 0, 1}, e[3] = {1, 1, 1};
  const double f[3] = {0.1, 0.2, 0.3};
  EXPECT_EQ(orient3d(a, b, c, d), 1);
  EXPECT_EQ(orient3d(a, b, c, e), 1);
  EXPECT_EQ(insphere(a, b, c, d, f), 1);
  EXPECT_EQ(predicate_stats().orient3d_calls, 2u);
  EXPECT_EQ(predicate_stats().orient3d_exact, 0u);
  EXPECT_EQ(predicate_stats().insphere_exact, 0u);
  const double g[3] = {1, 1, 0};                            // coplanar with a, b, c
  EXPECT_EQ(orient3d(a, b, c, g), 0);                       // zero axis (all z equal): settled at once
  const double h[3] = {2, 3, 1e-30}, k[3] = {1, 1, 1e-30};  // coplanar, not axis-aligned
  EXPECT_EQ(orient3d(a, h, k, std::array<double, 3>{3, 4, 2e-30}.data()), 0);
  EXPECT_EQ(insphere(a, b, c, d, e), 0);  // cospherical grid points: the lattice test
  EXPECT_EQ(insphere_sos(a, b, c, d, e, 1, 2, 3, 4, 5), -1);
  const PredicateStats& s = predicate_stats();
  EXPECT_EQ(s.insphere_calls, 3u);
  EXPECT_EQ(s.insphere_exact, 2u);
  EXPECT_EQ(s.insphere_full_exact, 0u);
  EXPECT_EQ(s.insphere_perturbed, 1u);
  EXPECT_GE(s.orient3d_exact, 2u);
  reset_predicate_stats();
  EXPECT_EQ(predicate_stats().orient3d_calls, 0u);
}

}  // namespace
}  // namespace tetstream::core
