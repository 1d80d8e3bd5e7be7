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
//   3. Exact integer arithmetic on the mantissas: every coordinate times 2^-g is an
//      integer below 2^span, span = (exponent of the largest coordinate) - g, and the
//      determinant is evaluated on those integers (the sign of a homogeneous
//      polynomial does not change under the positive scale 2^-g) in fixed-width
//      two's complement integers of 1, 2, 4 or 33 64-bit limbs per difference, the
//      narrowest that holds the call. One limb (span <= 61) covers most real calls
//      (e.g. coordinates within 2^8 of each other in magnitude, or any offset
//      lattice); 33 limbs cover any finite doubles (span <= 2098), subnormals
//      included. No allocation, no overflow, no rounding: exact for every finite input.
// (An earlier expansion-arithmetic version of step 3 was about 10x slower on nearly
// cospherical inputs, where almost every insphere call lands here: ~130 ns vs ~1.7 us.)
#include "core/predicates.hpp"

#include "core/double_word.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

namespace tetstream::core {
namespace {

// ---- bits of a double ------------------------------------------------------------

// Exponent of the lowest set bit of x != 0: x is an odd integer times 2^lowbit.
TS_FORCE_INLINE int lowbit_exponent(double x) {
  const std::uint64_t bits = std::bit_cast<std::uint64_t>(x);
  const int biased = int((bits >> 52) & 0x7ff);
  std::uint64_t mant = bits & ((std::uint64_t(1) << 52) - 1);
  if (biased != 0) mant |= std::uint64_t(1) << 52;
  return std::countr_zero(mant) + (biased != 0 ? biased - 1075 : -1074);
}

// Smallest k with |x| < 2^k, for finite x != 0 (for subnormals: -1022, an upper bound).
TS_FORCE_INLINE int ceil_exponent(double x) {
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

// ---- fixed-width integers (step 3) -------------------------------------------------

// A two's complement integer of L 64-bit limbs, little-endian.
template <int L>
struct Int {
  std::uint64_t w[L];
};

using u128 = unsigned __int128;

template <int L>
TS_FORCE_INLINE bool is_negative(const Int<L>& a) {
  return (a.w[L - 1] >> 63) != 0;
}

template <int L>
TS_FORCE_INLINE int sign(const Int<L>& a) {
  if (is_negative(a)) return -1;
  for (int i = 0; i < L; ++i)
    if (a.w[i] != 0) return 1;
  return 0;
}

template <int L>
TS_FORCE_INLINE Int<L> operator+(const Int<L>& a, const Int<L>& b) {
  Int<L> r;
  std::uint64_t carry = 0;
  for (int i = 0; i < L; ++i) {
    const u128 t = u128(a.w[i]) + b.w[i] + carry;
    r.w[i] = std::uint64_t(t);
    carry = std::uint64_t(t >> 64);
  }
  return r;
}

template <int L>
TS_FORCE_INLINE Int<L> operator-(const Int<L>& a) {
  Int<L> r;
  std::uint64_t carry = 1;
  for (int i = 0; i < L; ++i) {
    const u128 t = u128(~a.w[i]) + carry;
    r.w[i] = std::uint64_t(t);
    carry = std::uint64_t(t >> 64);
  }
  return r;
}

template <int L>
TS_FORCE_INLINE Int<L> operator-(const Int<L>& a, const Int<L>& b) {
  Int<L> r;
  std::uint64_t borrow = 0;
  for (int i = 0; i < L; ++i) {
    const u128 t = u128(a.w[i]) - b.w[i] - borrow;
    r.w[i] = std::uint64_t(t);
    borrow = std::uint64_t(t >> 64) & 1;
  }
  return r;
}

// Exact product; it always fits A + B limbs (|a b| < 2^(64A-1) 2^(64B-1)). Branch-free
// (the signs of these operands are unpredictable): the unsigned product of the two's
// complement words, minus 2^(64A) b if a < 0 and 2^(64B) a if b < 0, modulo 2^(64(A+B)).
template <int A, int B>
TS_FORCE_INLINE Int<A + B> operator*(const Int<A>& a, const Int<B>& b) {
  Int<A + B> r;
  if constexpr (A == 1 && B == 1) {
    const __int128 p = __int128(std::int64_t(a.w[0])) * std::int64_t(b.w[0]);
    r.w[0] = std::uint64_t(p);
    r.w[1] = std::uint64_t(u128(p) >> 64);
    return r;
  } else {
    for (int i = 0; i < A + B; ++i) r.w[i] = 0;
    for (int i = 0; i < A; ++i) {
      std::uint64_t carry = 0;
      for (int j = 0; j < B; ++j) {
        const u128 t = u128(a.w[i]) * b.w[j] + r.w[i + j] + carry;
        r.w[i + j] = std::uint64_t(t);
        carry = std::uint64_t(t >> 64);
      }
      r.w[i + B] = carry;
    }
    const std::uint64_t ma = 0 - (a.w[A - 1] >> 63), mb = 0 - (b.w[B - 1] >> 63);
    std::uint64_t borrow = 0;
    for (int j = 0; j < B; ++j) {
      const u128 t = u128(r.w[A + j]) - (b.w[j] & ma) - borrow;
      r.w[A + j] = std::uint64_t(t);
      borrow = std::uint64_t(t >> 64) & 1;
    }
    borrow = 0;
    for (int i = 0; i < A; ++i) {
      const u128 t = u128(r.w[B + i]) - (a.w[i] & mb) - borrow;
      r.w[B + i] = std::uint64_t(t);
      borrow = std::uint64_t(t >> 64) & 1;
    }
    return r;
  }
}

// x * 2^-low as an L-limb integer; requires x to be a multiple of 2^low and
// |x| < 2^(low + 64L - 1).
template <int L>
TS_FORCE_INLINE Int<L> to_int(double x, int low) {
  Int<L> r;
  for (int i = 0; i < L; ++i) r.w[i] = 0;
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
  const int shift = q + tz - low;  // >= 0 since low is the lowest set bit of all inputs
  const int limb = shift / 64, bit = shift % 64;
  r.w[limb] = m << bit;
  if (bit != 0 && limb + 1 < L) r.w[limb + 1] = m >> (64 - bit);
  return x < 0 ? -r : r;
}

// Sizes. With every |coordinate| < 2^(low + span), span <= 64K - 3, the scaled
// differences have |t| < 2^(64K-2) and fit K limbs; then
//   2x2 minors  |x y - x y| < 2^(128K-3)             fit 2K limbs,
//   3x3 minors  3 terms < 3 * 2^(192K-5) < 2^(192K-3) fit 3K limbs,
//   lifts       3 squares < 2^(128K-2)                fit 2K limbs,
//   insphere    4 terms < 4 * 2^(320K-5) = 2^(320K-3) fit 5K limbs,
// so no intermediate overflows its two's complement width.
template <int K>
int orient3d_int(const double* const* p, int low) {
  Int<K> t[3][3];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) t[i][k] = to_int<K>(p[i + 1][k], low) - to_int<K>(p[0][k], low);
  const Int<2 * K> m0 = t[1][1] * t[2][2] - t[1][2] * t[2][1];
  const Int<2 * K> m1 = t[1][0] * t[2][2] - t[1][2] * t[2][0];
  const Int<2 * K> m2 = t[1][0] * t[2][1] - t[1][1] * t[2][0];
  return sign(t[0][0] * m0 - t[0][1] * m1 + t[0][2] * m2);
}

// The same determinant as the filter: (L_a M_bcd - L_b M_acd) + (L_c M_abd - L_d M_abc)
// on the differences to e (predicates.hpp).
template <int K>
int insphere_int(const double* const* p, int low) {
  Int<K> t[4][3];
  for (int k = 0; k < 3; ++k) {
    const Int<K> e = to_int<K>(p[4][k], low);
    for (int i = 0; i < 4; ++i) t[i][k] = to_int<K>(p[i][k], low) - e;
  }
  Int<2 * K> m[4][4];
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) m[i][j] = t[i][0] * t[j][1] - t[j][0] * t[i][1];
  const auto minor3 = [&](int i, int j, int k) { return t[i][2] * m[j][k] - t[j][2] * m[i][k] + t[k][2] * m[i][j]; };
  const auto lift = [&](int i) { return t[i][0] * t[i][0] + t[i][1] * t[i][1] + t[i][2] * t[i][2]; };
  return sign((lift(0) * minor3(1, 2, 3) - lift(1) * minor3(0, 2, 3)) +
              (lift(2) * minor3(0, 1, 3) - lift(3) * minor3(0, 1, 2)));
}

// Calls f.template operator()<K>() with the narrowest limb count K that holds a call
// whose coordinates span `span` bits (max_exp - low): span <= 64K - 3. Any finite
// doubles have span <= 1024 + 1074 = 2098 <= 64 * 33 - 3.
template <class F>
auto with_exact_width(int span, F&& f) {
  if (span <= 61) return f.template operator()<1>();
  if (span <= 125) return f.template operator()<2>();
  if (span <= 253) return f.template operator()<4>();
  return f.template operator()<33>();
}

// Exact sign for any finite input.
template <int kPoints>
int exact_sign(const double* const* p, const Range& r) {
  return with_exact_width(r.max_exp - r.low, [&]<int K>() {
    if constexpr (kPoints == 5) {
      return insphere_int<K>(p, r.low);
    } else {
      return orient3d_int<K>(p, r.low);
    }
  });
}

// Points in decreasing label order, ties in index order (a stable sort). Each
// point's place is counted without branches: on random labels the comparisons of an
// insertion sort mispredict often, and this runs on every perturbed decision.
void sort_by_label_desc(const std::uint64_t* label, int n, int* order) {
  for (int i = 0; i < n; ++i) {
    int rank = 0;
    for (int j = 0; j < n; ++j) rank += int(label[j] > label[i]) | (int(label[j] == label[i]) & int(j < i));
    order[rank] = i;
  }
}

}  // namespace

namespace detail {

int orient3d_fallback(const double* a, const double* b, const double* c, const double* d, const FilterValue& f) {
  PredicateStats& st = tls_predicate_stats;
  ++st.orient3d_exact;
  const double* p[4] = {a, b, c, d};
  const Range r = scan(p, 4);
  if (!r.finite) return 0;
  if (f.zero_axis) return 0;
  if (f.in_range) {
    if (f.det > f.bound) return 1;
    if (f.det < -f.bound) return -1;
    if (ceil_exponent(f.bound) <= 3 * r.low - 1) return 0;  // lattice test
  }
  ++st.orient3d_full_exact;
  return exact_sign<4>(p, r);
}

int insphere_fallback(const double* a, const double* b, const double* c, const double* d, const double* e,
                      const FilterValue& f) {
  PredicateStats& st = tls_predicate_stats;
  ++st.insphere_exact;
  const double* p[5] = {a, b, c, d, e};
  const Range r = scan(p, 5);
  if (!r.finite) return 0;
  if (f.zero_axis) return 0;
  if (f.in_range) {
    if (f.det > f.bound) return 1;
    if (f.det < -f.bound) return -1;
    if (ceil_exponent(f.bound) <= 5 * r.low - 1) return 0;  // lattice test
  }
  ++st.insphere_full_exact;
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
                          std::uint64_t la, std::uint64_t lb, std::uint64_t lc, std::uint64_t ld, std::uint64_t le) {
  ++tls_predicate_stats.insphere_perturbed;
  const std::uint64_t label[5] = {la, lb, lc, ld, le};
  int order[5];
  sort_by_label_desc(label, 5, order);
  for (int i = 0; i < 5; ++i) {
    int s = 0;
    switch (order[i]) {
      case 0:
        s = orient3d(e, b, c, d);
        break;
      case 1:
        s = orient3d(a, e, c, d);
        break;
      case 2:
        s = orient3d(a, b, e, d);
        break;
      case 3:
        s = orient3d(a, b, c, e);
        break;
      default:
        s = -orient3d(a, b, c, d);
        break;
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
int infinite_conflict_coplanar(const double* a, const double* b, const double* c, const double* e, std::uint64_t la,
                               std::uint64_t lb, std::uint64_t lc, std::uint64_t le) {
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

namespace {

// |a| = m 2^e with m in [1/2, 1), rounded to the nearest double (one rounding: the top
// 64 bits with a sticky bit for everything below them convert correctly). a != 0.
template <int L>
double scaled_magnitude(Int<L> a, int& e) {
  if (is_negative(a)) a = -a;
  int top = L - 1;
  while (a.w[top] == 0) --top;
  const int lz = std::countl_zero(a.w[top]);
  std::uint64_t bits = a.w[top] << lz;
  bool sticky = false;  // any set bit below the 64 kept in `bits`
  if (top > 0) {
    if (lz > 0) bits |= a.w[top - 1] >> (64 - lz);
    sticky = lz > 0 ? (a.w[top - 1] << lz) != 0 : a.w[top - 1] != 0;
    for (int i = top - 2; i >= 0 && !sticky; --i) sticky = a.w[i] != 0;
  }
  // 64 significant bits; the lowest is far below double precision, so or-ing the
  // sticky information into it makes the single u64 -> double rounding correct.
  if (sticky) bits |= 1;
  e = 64 * top + (64 - lz);  // |a| < 2^e, |a| >= 2^(e-1)
  return std::ldexp(double(bits), -64);
}

// The centre offset X = N / D of the circumsphere (see circumsphere() below),
// evaluated exactly on the scaled integer coordinates and rounded once per
// component: x[k] = N_k / D with N_k and D each correctly rounded, then one division.
// Returns false when D == 0 (a flat tetrahedron). Sizes as in the predicates: with
// |t| < 2^(64K-2), cross products and squared lengths fit 2K limbs, D (3 terms) 3K,
// N (3 terms of products < 2^(256K-5)) 4K.
template <int K>
bool circumcentre_offset_int(const double* const* p, int low, double x[3]) {
  Int<K> t[3][3];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) t[i][k] = to_int<K>(p[i + 1][k], low) - to_int<K>(p[0][k], low);
  const auto cross = [&](int i, int j, int k) {
    const int a = (k + 1) % 3, b = (k + 2) % 3;
    return t[i][a] * t[j][b] - t[i][b] * t[j][a];
  };
  Int<2 * K> vw[3], wu[3], uv[3], sq[3];
  for (int k = 0; k < 3; ++k) vw[k] = cross(1, 2, k), wu[k] = cross(2, 0, k), uv[k] = cross(0, 1, k);
  for (int i = 0; i < 3; ++i) sq[i] = t[i][0] * t[i][0] + t[i][1] * t[i][1] + t[i][2] * t[i][2];
  const Int<3 * K> det = t[0][0] * vw[0] + t[0][1] * vw[1] + t[0][2] * vw[2];
  const int det_sign = sign(det);
  if (det_sign == 0) return false;
  int det_exp = 0;
  const double det_mag = scaled_magnitude(det, det_exp);
  for (int k = 0; k < 3; ++k) {
    const Int<4 * K> n = sq[0] * vw[k] + sq[1] * wu[k] + sq[2] * uv[k];
    const int n_sign = sign(n);
    if (n_sign == 0) {
      x[k] = 0.0;
      continue;
    }
    int n_exp = 0;
    const double n_mag = scaled_magnitude(n, n_exp);
    // True differences are t 2^low: N scales by 2^(4 low), D = 2 det by 2^(3 low).
    x[k] = double(n_sign * det_sign) * std::ldexp(n_mag / det_mag, n_exp - det_exp + low - 1);
  }
  return true;
}

// The centre offset X = N / D in double-word arithmetic (double_word.hpp), for
// 2^-200 <= M <= 2^200 (M = the largest |difference|): the same expressions as the
// fast path, with exact differences and every sum and product rounded with relative
// error at most dw::kRelativeError = w instead of u. The forward bounds are the fast
// path's with u replaced by w: |dD| <= 12 gamma_8(w) M^3 / (1-w)^3, |dN| <= 18
// gamma_12(w) M^4 / (1-w)^4, plus 2^-1000 each for partial results that underflow
// (each such rounding errs by at most 2^-1075 absolutely, and later factors are below
// 2^402, a few dozen of them: far below 2^-1000; and the bounds themselves are at
// least 2^-900 in this range). The quotient is N.hi / D.hi in double: |lo| <= u |hi|
// on both, so it is within 3u (1 + O(u)) of N~ / D~, counted as 4u |x|. Returns false
// when D rounds to 0 (a tetrahedron this flat goes to the exact path) or r > 1/2;
// otherwise x and the per-component bound e.
bool circumcentre_offset_double_word(const double* const* p, double m, double x[3], double e[3]) {
  using dw::DoubleWord;
  constexpr double u = 0x1p-53, w = dw::kRelativeError;
  DoubleWord t[3][3];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) t[i][k] = dw::exact_difference(p[i + 1][k], p[0][k]);
  const auto cross = [&](int i, int j, int k) {
    const int a = (k + 1) % 3, b = (k + 2) % 3;
    return t[i][a] * t[j][b] - t[i][b] * t[j][a];
  };
  DoubleWord vw[3], wu[3], uv[3], sq[3];
  for (int k = 0; k < 3; ++k) vw[k] = cross(1, 2, k), wu[k] = cross(2, 0, k), uv[k] = cross(0, 1, k);
  for (int i = 0; i < 3; ++i) sq[i] = t[i][0] * t[i][0] + t[i][1] * t[i][1] + t[i][2] * t[i][2];
  const DoubleWord det = t[0][0] * vw[0] + t[0][1] * vw[1] + t[0][2] * vw[2];
  const double det2 = 2.0 * det.hi;
  const double gamma8 = 8 * w / (1 - 8 * w), gamma12 = 12 * w / (1 - 12 * w);
  const double m3 = m * m * m;
  const double err_d = 12 * gamma8 * m3 / ((1 - w) * (1 - w) * (1 - w)) + 0x1p-1000;
  const double err_n = 18 * gamma12 * m3 * m / ((1 - w) * (1 - w) * (1 - w) * (1 - w)) + 0x1p-1000;
  const double abs_d = std::fabs(det2) * (1 - u);  // <= |D~|
  if (!(err_d <= 0.5 * abs_d)) return false;
  const double ratio = err_d / abs_d;
  for (int k = 0; k < 3; ++k) {
    const DoubleWord n = sq[0] * vw[k] + sq[1] * wu[k] + sq[2] * uv[k];
    x[k] = n.hi / det2;
    const double ax = std::fabs(x[k]) * (1 + 4 * u);  // >= |N~_k / D~|
    e[k] = (ax * ratio + err_n / abs_d) * (1 + 2 * ratio) + 4 * u * std::fabs(x[k]);
  }
  return true;
}

// The exact sign of c_axis - t (circumcentre_side): the columns taken in the cyclic
// order (axis, axis + 1, axis + 2), an even permutation, so both determinants keep
// their signs. Sizes: |u|, |s| < 2^(64K-2) (K limbs); |u|^2 - 2 s u < 2^(128K-1) and the
// 2x2 minors fit 2K limbs; det U (3 terms of K x 2K) 3K; the replaced determinant
// (3 terms < 2^(256K-4)) 4K.
template <int K>
int circumcentre_side_int(const double* const* p, double t, int axis, int low) {
  const int j = (axis + 1) % 3, l = (axis + 2) % 3;
  Int<K> u[3][3];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) u[i][k] = to_int<K>(p[i + 1][k], low) - to_int<K>(p[0][k], low);
  const Int<K> s = to_int<K>(t, low) - to_int<K>(p[0][axis], low);
  Int<2 * K> minor[3], w[3];
  for (int i = 0; i < 3; ++i) {
    const int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
    minor[i] = u[i1][j] * u[i2][l] - u[i2][j] * u[i1][l];
    const Int<2 * K> lift = u[i][0] * u[i][0] + u[i][1] * u[i][1] + u[i][2] * u[i][2];
    const Int<2 * K> su = s * u[i][axis];
    w[i] = lift - (su + su);
  }
  const int det_sign = sign(u[0][axis] * minor[0] + u[1][axis] * minor[1] + u[2][axis] * minor[2]);
  return det_sign * sign(w[0] * minor[0] + w[1] * minor[1] + w[2] * minor[2]);
}

}  // namespace

int circumcentre_side(const double* a, const double* b, const double* c, const double* d, int axis, double t) {
  const double* p[5] = {a, b, c, d, nullptr};
  Range r = scan(p, 4);
  if (!r.finite || !std::isfinite(t)) return 0;
  if (t != 0.0) {
    r.max_exp = std::max(r.max_exp, ceil_exponent(t));
    r.low = std::min(r.low, lowbit_exponent(t));
  }
  if (r.max_exp == std::numeric_limits<int>::min()) return 0;  // all zero: flat
  return with_exact_width(r.max_exp - r.low, [&]<int K>() { return circumcentre_side_int<K>(p, t, axis, r.low); });
}

// Circumsphere with a rigorous error bound. With u_ = b-a, v_ = c-a, w_ = d-a, the
// centre is a + N / D, N = |u|^2 (v x w) + |v|^2 (w x u) + |w|^2 (u x v), D = 2 u.(v x w).
//
// Fast path, in floating point. Rounding counts as in predicates.hpp (differences
// included), M = max |computed difference component|:
//   D: like orient3d, n = 8, P <= 6 M^3, times 2 exactly: |dD| <= 12 gamma_8 M^3/(1-u)^3;
//   N_k: |u|^2 has n = 5, (v x w)_k n = 4, product 10, two sums: n = 12, and
//        P <= 3 * 3M^2 * 2M^2: |dN| <= 18 gamma_12 M^4 / (1-u)^4.
// For x = N/D and x~ = N~/D~ (computed N, D): x - x~ = x dD/D~ - dN/D~, so with
// r = |dD|/|D~| < 1: |x - x~| <= (|x~| r + |dN|/|D~|) / (1 - r). Multiplying by the
// rounded 1/D~ adds at most 3u|x~|, the final a + X adds u|center|. The radius |X| has relative error
// <= gamma_3 / 2 + u < 4u, and |sqrt(r2*) - |X|| <= |x* - X|_2 <= sqrt(3) max_k
// |x*_k - X_k|. The bound itself is evaluated in floating point with a few dozen
// roundings, covered by the final factor (1 + 2^-20), which also absorbs underflow
// (M >= 2^-200 makes any underflow error at most 2^-600 of the bound).
//
// Double-word path, when the fast bound is loose: the same formulas in about 106-bit
// arithmetic (circumcentre_offset_double_word), kept when its bound is as good as the
// exact path's within a factor of two. Tetrahedra flat enough to defeat it as well
// (|D| below about 2^-40 M^3) take the exact path.
//
// Exact path, when the fast bound is loose (over 2^-36 M: a flat tetrahedron, whose
// centre lies far away and whose computed centre may be off by r |X|, a large
// distance at the scale of the points), or when M is out of range: N and D exactly,
// each rounded once, then one division, so |x~_k - x_k| <= 3u |x_k| (1 + O(u))
// <= 4u |x~_k|; with the final sum the centre
// is within 4u |x~_k| + 2u |center_k| of the truth. This is what keeps the pipeline's
// queries cheap on the flat tets along the hull, whose balls are huge: a loose
// centre there widens a thin cap into a slab holding a large share of the points.
// Only an exactly flat tetrahedron (D == 0) or an overflowing result gives
// valid = false.
Circumsphere circumsphere(const double* a, const double* b, const double* c, const double* d) {
  constexpr double u = 0x1p-53;
  constexpr double kSlack = 1.0 + 0x1p-20;
  Circumsphere s{};
  s.valid = false;
  const auto finish = [&](const double x[3], const double off_err_k[3]) {
    double off_err = 0.0, center_err = 0.0;
    for (int k = 0; k < 3; ++k) {
      s.center[k] = a[k] + x[k];
      off_err = std::max(off_err, off_err_k[k]);
      center_err = std::max(center_err, off_err_k[k] + 2 * u * std::fabs(s.center[k]));
    }
    // |X|. The exact path's offsets may lie anywhere in the double range: out of
    // [2^-500, 2^500] they are scaled by a power of two (exact) first, so that the
    // squares neither underflow nor overflow.
    const double big = std::max({std::fabs(x[0]), std::fabs(x[1]), std::fabs(x[2])});
    if (big >= 0x1p-500 && big <= 0x1p500) {
      s.radius = std::sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    } else {
      const int scale = std::ilogb(std::max(big, 0x1p-1000));
      double sum = 0.0;
      for (int k = 0; k < 3; ++k) sum += std::ldexp(x[k], -scale) * std::ldexp(x[k], -scale);
      s.radius = std::ldexp(std::sqrt(sum), scale);
    }
    // 0x1p-1060: room for an underflowed (subnormal) offset or centre.
    s.center_error = center_err * kSlack + 0x1p-1060;
    s.radius_error = (1.75 * off_err + 4 * u * s.radius) * kSlack + 0x1p-1060;
    s.valid = std::isfinite(s.center[0]) && std::isfinite(s.center[1]) && std::isfinite(s.center[2]) &&
              std::isfinite(s.radius) && std::isfinite(s.center_error) && std::isfinite(s.radius_error);
  };

  const double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const double wx = d[0] - a[0], wy = d[1] - a[1], wz = d[2] - a[2];
  double m = 0.0;
  for (double t : {ux, uy, uz, vx, vy, vz, wx, wy, wz}) m = std::max(m, std::fabs(t));
  if (m >= 0x1p-200 && m <= 0x1p200) {
    const double vwx = vy * wz - vz * wy, vwy = vz * wx - vx * wz, vwz = vx * wy - vy * wx;
    const double wux = wy * uz - wz * uy, wuy = wz * ux - wx * uz, wuz = wx * uy - wy * ux;
    const double uvx = uy * vz - uz * vy, uvy = uz * vx - ux * vz, uvz = ux * vy - uy * vx;
    const double uu = ux * ux + uy * uy + uz * uz;
    const double vv = vx * vx + vy * vy + vz * vz;
    const double ww = wx * wx + wy * wy + wz * wz;
    const double det2 = 2.0 * (ux * vwx + uy * vwy + uz * vwz);
    const double gamma8 = 8 * u / (1 - 8 * u), gamma12 = 12 * u / (1 - 12 * u);
    const double m3 = m * m * m;
    const double err_d = 12 * gamma8 * m3 / ((1 - u) * (1 - u) * (1 - u));
    const double err_n = 18 * gamma12 * m3 * m / ((1 - u) * (1 - u) * (1 - u) * (1 - u));
    const double abs_d = std::fabs(det2);
    if (err_d <= 0.5 * abs_d) {
      // One division: x_k = N_k * (1 / det2) rounds twice, |fl - N_k / det2| <=
      // (2u + u^2) |N_k / det2|, covered by 3u |x_k| and |N_k / det2| <= (1 + 3u) |x_k|.
      // And 1 / (1 - ratio) <= 1 + 2 ratio for ratio <= 1/2. (The pipeline computes one
      // circumsphere per tet of every window: one division instead of six.)
      const double inv = 1.0 / det2, inv_abs = std::fabs(inv);
      const double ratio = err_d * inv_abs;
      const double x[3] = {(uu * vwx + vv * wux + ww * uvx) * inv, (uu * vwy + vv * wuy + ww * uvy) * inv,
                           (uu * vwz + vv * wuz + ww * uvz) * inv};
      double e[3];
      for (int k = 0; k < 3; ++k) {
        const double ax = std::fabs(x[k]) * (1 + 3 * u);  // >= |N_k / det2|
        e[k] = (ax * ratio + err_n * inv_abs) * (1 + 2 * ratio) + 3 * u * std::fabs(x[k]);
      }
      if (std::max({e[0], e[1], e[2]}) <= 0x1p-36 * m) {
        finish(x, e);
        return s;
      }
    }
  }

  const double* p[4] = {a, b, c, d};
  // Double-word path: kept when its bound is within twice the exact path's (4u |x_k|)
  // or as tight as the fast path demands. Flat tets, whose centres lie hundreds of
  // edge lengths away, land here (a terrain's roofs and ground: the exact path was a
  // quarter of such a run's time); only the flattest go on to exact integers.
  if (m >= 0x1p-200 && m <= 0x1p200) {
    double x[3], e[3];
    if (circumcentre_offset_double_word(p, m * (1 + 0x1p-50), x, e)) {  // m of the exact differences
      bool tight = true;
      for (int k = 0; k < 3; ++k)
        tight &= e[k] <= std::max(8 * u * std::fabs(x[k]), 0x1p-36 * m + 4 * u * std::fabs(x[k]));
      if (tight) {
        finish(x, e);
        return s;
      }
    }
  }

  // Exact path, in the narrowest integer width that holds the call.
  const Range r = scan(p, 4);
  if (!r.finite) return s;
  double x[3];
  if (!with_exact_width(r.max_exp - r.low, [&]<int K>() { return circumcentre_offset_int<K>(p, r.low, x); })) return s;
  double e[3];
  for (int k = 0; k < 3; ++k) e[k] = 4 * u * std::fabs(x[k]);
  finish(x, e);
  return s;
}

}  // namespace tetstream::core
