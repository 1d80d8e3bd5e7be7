// Exact fallbacks of the predicates (the inline filters are in predicates.hpp).
//
// When the filter cannot decide, the fallback tries, in order:
//   1. Trivial zeros: one axis with all differences exactly 0 (fl(x - y) == 0 iff x == y).
//   2. The lattice test. Every input is an integer multiple of 2^g, where g is the
//      lowest set bit over all the coordinates, so the exact determinant (a polynomial
//      of degree k in the differences: 3 for orient3d, 5 for insphere) is a multiple
//      of 2^(k g). The filter failed, so |computed| <= bound and |exact| <= 2 bound;
//      if 2 bound < 2^(k g) the exact value is 0. This settles the exact zeros of grid
//      and other lattice inputs (the common degeneracy) at filter cost.
//   3. Expansion arithmetic (core/expansion.hpp) on the raw coordinates, evaluating
//      the determinant of rows (p, 1) (orient3d) or (p, |p|^2, 1) (insphere) by
//      cofactors. It is exact when no intermediate overflows or underflows; with
//      |coord| < 2^H and all coordinates multiples of 2^g that holds for
//      orient3d: H = 320, g >= -356 (degree 3: 3 g >= -1074; |det| < 2^970);
//      insphere: H = 195, g >= -214 (degree 5: 5 g >= -1074; |det| < 2^984),
//      and the split of any intermediate stays below 2^996. Other inputs are first
//      multiplied by a power of two 2^s (exact, and the sign of a homogeneous
//      polynomial is unchanged) to bring the largest coordinate to 2^H, which works
//      whenever max / 2^g <= 2^(H - gmin) (about 2^660 for orient3d, 2^400 for insphere).
//   4. Otherwise (coordinates of one call spanning more than that, e.g. 1e-300 next
//      to 1e300): exact big integers, the coordinates times 2^-g. Never seen on real
//      data; here so that every finite input is exact.
#include "core/predicates.hpp"

#include "core/expansion.hpp"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>

namespace tetstream::core {
namespace {

namespace ex = expansion;

// ---- bits of a double ------------------------------------------------------------

// Exponent of the lowest set bit of x != 0: x is an odd integer times 2^lowbit.
int lowbit_exponent(double x) {
  const std::uint64_t bits = std::bit_cast<std::uint64_t>(x);
  const int biased = int((bits >> 52) & 0x7ff);
  std::uint64_t mant = bits & ((std::uint64_t(1) << 52) - 1);
  if (biased != 0) mant |= std::uint64_t(1) << 52;
  return std::countr_zero(mant) + (biased != 0 ? biased - 1075 : -1074);
}

// Smallest k with |x| < 2^k, for finite x != 0 (for subnormals: -1022, an upper bound).
int ceil_exponent(double x) {
  const std::uint64_t bits = std::bit_cast<std::uint64_t>(x);
  const int biased = int((bits >> 52) & 0x7ff);
  return biased != 0 ? biased - 1022 : -1022;
}

struct Range {
  bool finite = true;
  int max_exp = std::numeric_limits<int>::min();  // every |coord| < 2^max_exp
  int low = std::numeric_limits<int>::max();      // every coord is a multiple of 2^low
};

Range scan(const double* const* p, int np) {
  Range r;
  for (int i = 0; i < np; ++i) {
    for (int k = 0; k < 3; ++k) {
      const double x = p[i][k];
      if (!std::isfinite(x)) {
        r.finite = false;
        return r;
      }
      if (x == 0.0) continue;
      r.max_exp = std::max(r.max_exp, ceil_exponent(x));
      r.low = std::min(r.low, lowbit_exponent(x));
    }
  }
  return r;
}

// ---- big integers (step 4) ----------------------------------------------------------

// Sign-magnitude integer with a fixed capacity. A coordinate times 2^-g has at most
// 1024 + 1074 = 2098 bits; a degree-5 polynomial of differences stays below 2^10510.
struct Big {
  static constexpr int kCap = 168;  // 64-bit limbs: 10752 bits
  int n = 0;                        // limbs in use; d[n-1] != 0
  bool neg = false;
  std::uint64_t d[kCap];
};

using u128 = unsigned __int128;

Big big_from(double x, int g) {
  Big r;
  if (x == 0.0) return r;
  const std::uint64_t bits = std::bit_cast<std::uint64_t>(x);
  const int biased = int((bits >> 52) & 0x7ff);
  std::uint64_t m = bits & ((std::uint64_t(1) << 52) - 1);
  int q = -1074;
  if (biased != 0) {
    m |= std::uint64_t(1) << 52;
    q = biased - 1075;
  }
  const int tz = std::countr_zero(m);
  m >>= tz;
  const int shift = q + tz - g;  // >= 0 by the choice of g
  const int limb = shift / 64, bit = shift % 64;
  assert(limb + 2 <= Big::kCap);
  std::memset(r.d, 0, sizeof(std::uint64_t) * (limb + 2));
  r.d[limb] = m << bit;
  r.d[limb + 1] = bit != 0 ? m >> (64 - bit) : 0;
  r.n = limb + 2;
  while (r.n > 0 && r.d[r.n - 1] == 0) --r.n;
  r.neg = x < 0;
  return r;
}

int cmp_mag(const Big& a, const Big& b) {
  if (a.n != b.n) return a.n < b.n ? -1 : 1;
  for (int i = a.n - 1; i >= 0; --i)
    if (a.d[i] != b.d[i]) return a.d[i] < b.d[i] ? -1 : 1;
  return 0;
}

void add_mag(const Big& a, const Big& b, Big& r) {  // |r| = |a| + |b|
  const Big& x = a.n >= b.n ? a : b;
  const Big& y = a.n >= b.n ? b : a;
  std::uint64_t carry = 0;
  for (int i = 0; i < x.n; ++i) {
    const u128 s = u128(x.d[i]) + (i < y.n ? y.d[i] : 0) + carry;
    r.d[i] = std::uint64_t(s);
    carry = std::uint64_t(s >> 64);
  }
  r.n = x.n;
  if (carry != 0) {
    assert(r.n < Big::kCap);
    r.d[r.n++] = carry;
  }
}

void sub_mag(const Big& x, const Big& y, Big& r) {  // |r| = |x| - |y|, |x| >= |y|
  std::uint64_t borrow = 0;
  for (int i = 0; i < x.n; ++i) {
    const std::uint64_t yi = i < y.n ? y.d[i] : 0;
    const std::uint64_t t = x.d[i] - yi;
    const std::uint64_t nb = (x.d[i] < yi) || (t < borrow);
    r.d[i] = t - borrow;
    borrow = nb;
  }
  r.n = x.n;
  while (r.n > 0 && r.d[r.n - 1] == 0) --r.n;
}

Big operator+(const Big& a, const Big& b) {
  Big r;
  if (a.neg == b.neg) {
    add_mag(a, b, r);
    r.neg = a.neg;
  } else if (cmp_mag(a, b) >= 0) {
    sub_mag(a, b, r);
    r.neg = a.neg;
  } else {
    sub_mag(b, a, r);
    r.neg = b.neg;
  }
  if (r.n == 0) r.neg = false;
  return r;
}

Big operator-(const Big& a) {
  Big r = a;
  if (r.n != 0) r.neg = !r.neg;
  return r;
}

Big operator-(const Big& a, const Big& b) { return a + (-b); }

Big operator*(const Big& a, const Big& b) {
  Big r;
  if (a.n == 0 || b.n == 0) return r;
  assert(a.n + b.n <= Big::kCap);
  r.n = a.n + b.n;
  std::memset(r.d, 0, sizeof(std::uint64_t) * r.n);
  for (int i = 0; i < a.n; ++i) {
    std::uint64_t carry = 0;
    for (int j = 0; j < b.n; ++j) {
      const u128 t = u128(a.d[i]) * b.d[j] + r.d[i + j] + carry;
      r.d[i + j] = std::uint64_t(t);
      carry = std::uint64_t(t >> 64);
    }
    r.d[i + b.n] = carry;
  }
  while (r.n > 0 && r.d[r.n - 1] == 0) --r.n;
  r.neg = a.neg != b.neg;
  return r;
}

int big_sign(const Big& a) { return a.n == 0 ? 0 : (a.neg ? -1 : 1); }

int orient3d_big(const double* const* p, int g) {
  Big q[4][3];
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) q[i][k] = big_from(p[i][k], g);
  const Big ux = q[1][0] - q[0][0], uy = q[1][1] - q[0][1], uz = q[1][2] - q[0][2];
  const Big vx = q[2][0] - q[0][0], vy = q[2][1] - q[0][1], vz = q[2][2] - q[0][2];
  const Big wx = q[3][0] - q[0][0], wy = q[3][1] - q[0][1], wz = q[3][2] - q[0][2];
  return big_sign(ux * (vy * wz - vz * wy) - uy * (vx * wz - vz * wx) + uz * (vx * wy - vy * wx));
}

int insphere_big(const double* const* p, int g) {
  Big t[4][3];
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) t[i][k] = big_from(p[i][k], g) - big_from(p[4][k], g);
  const auto m2 = [&](int i, int j) { return t[i][0] * t[j][1] - t[j][0] * t[i][1]; };
  const auto m3 = [&](int i, int j, int k) {
    return t[i][2] * m2(j, k) - t[j][2] * m2(i, k) + t[k][2] * m2(i, j);
  };
  const auto lift = [&](int i) { return t[i][0] * t[i][0] + t[i][1] * t[i][1] + t[i][2] * t[i][2]; };
  return big_sign(lift(0) * m3(1, 2, 3) - lift(1) * m3(0, 2, 3) + lift(2) * m3(0, 1, 3) -
                  lift(3) * m3(0, 1, 2));
}

// ---- expansions (step 3) ------------------------------------------------------------

constexpr int kOrientMaxExp = 320, kOrientMinLow = -356;
constexpr int kInsphereMaxExp = 195, kInsphereMinLow = -214;

struct Exp4 {  // 2x2 xy-minor: at most 4 components
  int n;
  double v[4];
};
struct Exp24 {  // 3x3 xyz-minor: at most 24 components
  int n;
  double v[24];
};
struct Exp96 {  // 4x4 minor with a column of ones (an orient3d): at most 96 components
  int n;
  double v[96];
};

// M = z_i m_jk - z_j m_ik + z_k m_ij, the determinant of rows i, j, k in (x, y, z).
void minor3(double zi, const Exp4& mjk, double zj, const Exp4& mik, double zk, const Exp4& mij,
            Exp24& out) {
  double t1[8], t2[8], t3[8], s[16];
  const int n1 = ex::scale(mjk.n, mjk.v, zi, t1);
  const int n2 = ex::scale(mik.n, mik.v, -zj, t2);
  const int n3 = ex::scale(mij.n, mij.v, zk, t3);
  const int ns = ex::sum(n1, t1, n2, t2, s);
  out.n = ex::sum(ns, s, n3, t3, out.v);
}

// orient3d(p,q,r,s) = M(qrs) - M(prs) + M(pqs) - M(pqr), from the 3x3 minors.
void orient_from_minors(const Exp24& qrs, const Exp24& prs, const Exp24& pqs, const Exp24& pqr,
                        Exp96& out) {
  double a[48], b[48];
  double neg[24];
  for (int i = 0; i < prs.n; ++i) neg[i] = -prs.v[i];
  const int na = ex::sum(qrs.n, qrs.v, prs.n, neg, a);
  for (int i = 0; i < pqr.n; ++i) neg[i] = -pqr.v[i];
  const int nb = ex::sum(pqs.n, pqs.v, pqr.n, neg, b);
  out.n = ex::sum(na, a, nb, b, out.v);
}

int orient3d_expansion(const double* const* p) {
  Exp4 m[4][4];
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j)
      m[i][j].n = ex::two_by_two(p[i][0], p[j][1], p[j][0], p[i][1], m[i][j].v);
  const auto z = [&](int i) { return p[i][2]; };
  Exp24 bcd, acd, abd, abc;
  minor3(z(1), m[2][3], z(2), m[1][3], z(3), m[1][2], bcd);
  minor3(z(0), m[2][3], z(2), m[0][3], z(3), m[0][2], acd);
  minor3(z(0), m[1][3], z(1), m[0][3], z(3), m[0][1], abd);
  minor3(z(0), m[1][2], z(1), m[0][2], z(2), m[0][1], abc);
  Exp96 o;
  orient_from_minors(bcd, acd, abd, abc, o);
  return ex::sign(o.n, o.v);
}

// I = sum_r (-1)^(r+1) w_r O(the other four, in order), w_r = |p_r|^2: the lifted
// polynomial of predicates.hpp written by cofactors along the lifted column.
int insphere_expansion(const double* const* p) {
  Exp4 m[5][5];
  for (int i = 0; i < 5; ++i)
    for (int j = i + 1; j < 5; ++j)
      m[i][j].n = ex::two_by_two(p[i][0], p[j][1], p[j][0], p[i][1], m[i][j].v);
  Exp24 t[10];  // the 3x3 minors of triples i < j < k, numbered by triple_id
  int triple_id[5][5][5];
  for (int i = 0, id = 0; i < 5; ++i)
    for (int j = i + 1; j < 5; ++j)
      for (int k = j + 1; k < 5; ++k, ++id) {
        triple_id[i][j][k] = id;
        minor3(p[i][2], m[j][k], p[j][2], m[i][k], p[k][2], m[i][j], t[id]);
      }
  const auto minor = [&](int i, int j, int k) -> const Exp24& { return t[triple_id[i][j][k]]; };

  static constexpr int kTotal = 5 * 1152;
  double acc[kTotal], acc2[kTotal];
  int nacc = 1;
  acc[0] = 0.0;
  for (int r = 0; r < 5; ++r) {
    int q[4], nq = 0;
    for (int i = 0; i < 5; ++i)
      if (i != r) q[nq++] = i;
    Exp96 o;
    orient_from_minors(minor(q[1], q[2], q[3]), minor(q[0], q[2], q[3]), minor(q[0], q[1], q[3]),
                       minor(q[0], q[1], q[2]), o);
    // w_r as an expansion (at most 6 components), signed by (-1)^(r+1).
    const double sgn = (r % 2 == 0) ? -1.0 : 1.0;
    double sq[3][2], w2[4], w[6];
    for (int k = 0; k < 3; ++k) ex::two_product(p[r][k], sgn * p[r][k], sq[k][1], sq[k][0]);
    const int n2 = ex::sum(2, sq[0], 2, sq[1], w2);
    const int nw = ex::sum(n2, w2, 2, sq[2], w);
    // term = o * w (at most 1152 components), accumulated into acc.
    double term[1152], term2[1152], part[192];
    int nt = 1;
    term[0] = 0.0;
    for (int c = 0; c < nw; ++c) {
      const int np = ex::scale(o.n, o.v, w[c], part);
      nt = ex::sum(nt, term, np, part, term2);
      std::copy(term2, term2 + nt, term);
    }
    nacc = ex::sum(nacc, acc, nt, term, acc2);
    std::copy(acc2, acc2 + nacc, acc);
  }
  return ex::sign(nacc, acc);
}

// Exact sign for any finite input (steps 3 and 4).
template <int kPoints>
int exact_sign(const double* const* p, const Range& r) {
  constexpr bool kInsphere = kPoints == 5;
  constexpr int kMaxExp = kInsphere ? kInsphereMaxExp : kOrientMaxExp;
  constexpr int kMinLow = kInsphere ? kInsphereMinLow : kOrientMinLow;
  const auto run = [](const double* const* q) {
    if constexpr (kInsphere) {
      return insphere_expansion(q);
    } else {
      return orient3d_expansion(q);
    }
  };
  if (r.max_exp <= kMaxExp && r.low >= kMinLow) return run(p);
  const int s = kMaxExp - r.max_exp;
  if (r.low + s >= kMinLow) {
    double scaled[kPoints][3];
    const double* q[kPoints];
    for (int i = 0; i < kPoints; ++i) {
      for (int k = 0; k < 3; ++k) scaled[i][k] = std::ldexp(p[i][k], s);  // exact
      q[i] = scaled[i];
    }
    return run(q);
  }
  if constexpr (kInsphere) {
    return insphere_big(p, r.low);
  } else {
    return orient3d_big(p, r.low);
  }
}

// Points in decreasing label order (a 5-element insertion sort; ties keep index order).
void sort_by_label_desc(const std::uint64_t* label, int n, int* order) {
  for (int i = 0; i < n; ++i) {
    int j = i;
    while (j > 0 && label[order[j - 1]] < label[i]) {
      order[j] = order[j - 1];
      --j;
    }
    order[j] = i;
  }
}

}  // namespace

namespace detail {

int orient3d_fallback(const double* a, const double* b, const double* c, const double* d) {
  PredicateStats& st = tls_predicate_stats;
  ++st.orient3d_exact;
  const double* p[4] = {a, b, c, d};
  const Range r = scan(p, 4);
  if (!r.finite) return 0;
  const FilterValue f = orient3d_filter(a, b, c, d);
  if (f.zero_axis) return 0;
  if (f.in_range) {
    if (f.det > f.bound) return 1;
    if (f.det < -f.bound) return -1;
    if (ceil_exponent(f.bound) <= 3 * r.low - 1) return 0;  // lattice test
  }
  ++st.orient3d_expansion;
  return exact_sign<4>(p, r);
}

int insphere_fallback(const double* a, const double* b, const double* c, const double* d, const double* e) {
  PredicateStats& st = tls_predicate_stats;
  ++st.insphere_exact;
  const double* p[5] = {a, b, c, d, e};
  const Range r = scan(p, 5);
  if (!r.finite) return 0;
  const FilterValue f = insphere_filter(a, b, c, d, e);
  if (f.zero_axis) return 0;
  if (f.in_range) {
    if (f.det > f.bound) return 1;
    if (f.det < -f.bound) return -1;
    if (ceil_exponent(f.bound) <= 5 * r.low - 1) return 0;  // lattice test
  }
  ++st.insphere_expansion;
  return exact_sign<5>(p, r);
}

// I == 0: the sign of I_eps is the sign of the coefficient of the largest label whose
// coefficient is nonzero (predicates.hpp). Coefficients: O_a = orient3d(e,b,c,d),
// O_b = orient3d(a,e,c,d), O_c = orient3d(a,b,e,d), O_d = orient3d(a,b,c,e) for the tet
// vertices and -O = -orient3d(a,b,c,d) for e.
//
// Never 0 (proof sketch): the loop reaches e's coefficient at the latest, and
// -O != 0 unless a, b, c, d are coplanar. Sorting the labels needs no permutation
// sign because each coefficient is evaluated with the points in their own places.
int insphere_sos_tiebreak(const double* a, const double* b, const double* c, const double* d, const double* e,
                          std::uint64_t la, std::uint64_t lb, std::uint64_t lc, std::uint64_t ld,
                          std::uint64_t le) {
  ++tls_predicate_stats.insphere_perturbed;
  const std::uint64_t label[5] = {la, lb, lc, ld, le};
  int order[5];
  sort_by_label_desc(label, 5, order);
  for (int i = 0; i < 5; ++i) {
    int s = 0;
    switch (order[i]) {
      case 0: s = orient3d(e, b, c, d); break;
      case 1: s = orient3d(a, e, c, d); break;
      case 2: s = orient3d(a, b, e, d); break;
      case 3: s = orient3d(a, b, c, e); break;
      default: s = -orient3d(a, b, c, d); break;
    }
    if (s != 0) return s;
  }
  return 0;  // a, b, c, d coplanar: outside the contract
}

// e is exactly coplanar with the hull facet abc. The infinite tet's conflict region
// is the limit of the spheres through a, b, c and a point d' running to infinity in
// front of the facet: the open half-space in front, plus, in the plane, the disc of
// the circumcircle of abc. Every sphere through a, b, c meets the plane exactly in
// that circle, so for any point o behind the facet, insphere(a,c,b,o,e) (positively
// oriented) has the sign of "e inside the circle". Under the perturbation the answer
// does not depend on o either: the coefficient of o is orient3d(a,c,b,e) = 0, and
// those of a, b, c are orient3d of e, two of a,b,c and o, whose sign is (side of o) x
// (a sign inside the plane); the side of o is fixed (behind), and d' in front gives
// the same signs with the tet written (a,b,c,d'). So insphere_sos(a,c,b,o,e) is the
// answer, for an o we can build exactly: a moved along the axis where the facet
// normal is largest, by about the facet's size, towards the inside.
int infinite_conflict_coplanar(const double* a, const double* b, const double* c, const double* e,
                               std::uint64_t la, std::uint64_t lb, std::uint64_t lc, std::uint64_t le) {
  const double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const double n[3] = {uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx};
  double ext = 0.0;
  for (double t : {ux, uy, uz, vx, vy, vz}) ext = std::max(ext, std::fabs(t));
  int axes[3] = {0, 1, 2};
  std::sort(axes, axes + 3, [&](int i, int j) { return std::fabs(n[i]) > std::fabs(n[j]); });
  for (int k : axes) {
    for (int attempt = 0; attempt < 2; ++attempt) {
      double dir = n[k] > 0 ? -1.0 : 1.0;  // orient3d(a,b,c,o) = n_k (o_k - a_k) < 0
      if (attempt == 1) dir = -dir;
      double o[3] = {a[0], a[1], a[2]};
      o[k] = a[k] + dir * ext;
      if (o[k] == a[k] || !std::isfinite(o[k])) o[k] = std::nextafter(a[k], dir * HUGE_VAL);
      if (!std::isfinite(o[k])) continue;
      if (orient3d(a, b, c, o) < 0) return insphere_sos(a, c, b, o, e, la, lc, lb, 0, le);
    }
  }
  return -1;  // a, b, c collinear: not a facet
}

}  // namespace detail

// Circumsphere with a rigorous error bound. With u_ = b-a, v_ = c-a, w_ = d-a, the
// centre is a + N / D, N = |u|^2 (v x w) + |v|^2 (w x u) + |w|^2 (u x v), D = 2 u.(v x w).
// Rounding counts as in predicates.hpp (differences included), M = max |computed
// difference component|:
//   D: like orient3d, n = 8, P <= 6 M^3, times 2 exactly: |dD| <= 12 gamma_8 M^3/(1-u)^3;
//   N_k: |u|^2 has n = 5, (v x w)_k n = 4, product 10, two sums: n = 12, and
//        P <= 3 * 3M^2 * 2M^2: |dN| <= 18 gamma_12 M^4 / (1-u)^4.
// For x = N/D and x~ = N~/D~ (computed N, D): x - x~ = x dD/D~ - dN/D~, so with
// r = |dD|/|D~| < 1: |x - x~| <= (|x~| r + |dN|/|D~|) / (1 - r). We require r <= 1/2
// (else "too flat": valid = false). The division adds u|x~|, the final a + X adds
// u|center|. The radius |X| has relative error <= gamma_3 / 2 + u < 4u, and
// |sqrt(r2*) - |X|| <= |x* - X|_2 <= sqrt(3) max_k |x*_k - X_k|. The bound itself is
// evaluated in floating point with a few dozen roundings, covered by the final factor
// (1 + 2^-20), which also absorbs underflow (M >= 2^-200 makes any underflow error at
// most 2^-600 of the bound). M > 2^200 (overflow risk) also gives valid = false.
Circumsphere circumsphere(const double* a, const double* b, const double* c, const double* d) {
  constexpr double u = 0x1p-53;
  constexpr double kSlack = 1.0 + 0x1p-20;
  Circumsphere s{};
  s.valid = false;
  const double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const double wx = d[0] - a[0], wy = d[1] - a[1], wz = d[2] - a[2];
  double m = 0.0;
  for (double t : {ux, uy, uz, vx, vy, vz, wx, wy, wz}) m = std::max(m, std::fabs(t));
  if (!(m >= 0x1p-200 && m <= 0x1p200)) return s;  // also rejects NaN
  const double vwx = vy * wz - vz * wy, vwy = vz * wx - vx * wz, vwz = vx * wy - vy * wx;
  const double wux = wy * uz - wz * uy, wuy = wz * ux - wx * uz, wuz = wx * uy - wy * ux;
  const double uvx = uy * vz - uz * vy, uvy = uz * vx - ux * vz, uvz = ux * vy - uy * vx;
  const double uu = ux * ux + uy * uy + uz * uz;
  const double vv = vx * vx + vy * vy + vz * vz;
  const double ww = wx * wx + wy * wy + wz * wz;
  const double det2 = 2.0 * (ux * vwx + uy * vwy + uz * vwz);
  const double nx = uu * vwx + vv * wux + ww * uvx;
  const double ny = uu * vwy + vv * wuy + ww * uvy;
  const double nz = uu * vwz + vv * wuz + ww * uvz;
  const double gamma8 = 8 * u / (1 - 8 * u), gamma12 = 12 * u / (1 - 12 * u);
  const double m3 = m * m * m;
  const double err_d = 12 * gamma8 * m3 / ((1 - u) * (1 - u) * (1 - u));
  const double err_n = 18 * gamma12 * m3 * m / ((1 - u) * (1 - u) * (1 - u) * (1 - u));
  const double abs_d = std::fabs(det2);
  if (!(err_d <= 0.5 * abs_d)) return s;  // too flat (or D == 0)
  const double ratio = err_d / abs_d;
  const double x[3] = {nx / det2, ny / det2, nz / det2};
  double off_err = 0.0, center_err = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double ax = std::fabs(x[k]) * (1 + 2 * u);  // >= |x~_k|
    const double e = (ax * ratio + err_n / abs_d) / (1 - ratio) + 2 * u * std::fabs(x[k]);
    s.center[k] = a[k] + x[k];
    off_err = std::max(off_err, e);
    center_err = std::max(center_err, e + 2 * u * std::fabs(s.center[k]));
  }
  s.radius = std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
  s.center_error = center_err * kSlack;
  s.radius_error = (1.75 * off_err + 4 * u * s.radius) * kSlack;
  s.valid = std::isfinite(s.center[0]) && std::isfinite(s.center[1]) && std::isfinite(s.center[2]) &&
            std::isfinite(s.radius) && std::isfinite(s.center_error) && std::isfinite(s.radius_error);
  return s;
}

}  // namespace tetstream::core
