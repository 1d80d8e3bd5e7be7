#pragma once
// Exact floating-point expansion arithmetic, the exact fallback of core/predicates.
//
// An expansion is a sum x = e[0] + e[1] + ... + e[n-1] of doubles, nonoverlapping and
// sorted by increasing magnitude, so its sign is the sign of its last component. The
// algorithms are the classical error-free transformations (Knuth's two-sum, Dekker's
// fast-two-sum, Veltkamp/Dekker splitting and two-product) and the expansion sum and
// scale of Priest and Shewchuk ("Adaptive precision floating-point arithmetic and fast
// robust geometric predicates", 1997), reimplemented from the published math.
//
// Exactness needs IEEE binary64 with round-to-nearest-even, no FMA contraction
// (-ffp-contract=off) and no fast-math, and no overflow or underflow. "No underflow"
// here means: every input is an integer multiple of 2^g and, for a product of degree k
// in the inputs, k*g >= -1074, so every exact intermediate is a multiple of 2^-1074 and
// therefore representable (subnormals included). The callers in predicates.cpp scale
// their inputs by a power of two to make this hold; see the range notes there.
//
// Conventions: every function returns the length of its output, which is at least 1
// (a zero value is the single component 0) and carries no other zero components.
// Outputs never alias inputs.
#include "core/compiler.hpp"

#include <cmath>

namespace tetstream::core::expansion {

// s + err == a + b exactly, s = fl(a + b). Any a, b (Knuth).
TS_FORCE_INLINE void two_sum(double a, double b, double& s, double& err) {
  s = a + b;
  const double bv = s - a;
  const double av = s - bv;
  err = (a - av) + (b - bv);
}

// Same, when |a| >= |b| or a == 0 (Dekker).
TS_FORCE_INLINE void fast_two_sum(double a, double b, double& s, double& err) {
  s = a + b;
  err = b - (s - a);
}

// a == hi + lo with hi and lo of at most 26 significant bits each (Veltkamp).
// Requires |a| < 2^996 so that the scaled copy does not overflow.
TS_FORCE_INLINE void split(double a, double& hi, double& lo) {
  const double c = 134217729.0 * a;  // 2^27 + 1
  const double big = c - a;
  hi = c - big;
  lo = a - hi;
}

// p + err == a * b exactly, p = fl(a * b), with b already split (Dekker).
TS_FORCE_INLINE void two_product_split(double a, double b, double bhi, double blo, double& p, double& err) {
  p = a * b;
  double ahi, alo;
  split(a, ahi, alo);
  const double e1 = p - ahi * bhi;
  const double e2 = e1 - alo * bhi;
  const double e3 = e2 - ahi * blo;
  err = alo * blo - e3;
}

TS_FORCE_INLINE void two_product(double a, double b, double& p, double& err) {
  double bhi, blo;
  split(b, bhi, blo);
  two_product_split(a, b, bhi, blo, p, err);
}

// h = e + f. h has room for elen + flen components. The merge by magnitude followed
// by a chain of two-sums (the first a fast-two-sum) is Shewchuk's Theorem 13; zero
// components are dropped.
inline int sum(int elen, const double* e, int flen, const double* f, double* h) {
  int i = 0, j = 0, k = 0;
  const int n = elen + flen;
  auto next = [&]() -> double {
    if (j >= flen || (i < elen && std::fabs(e[i]) < std::fabs(f[j]))) return e[i++];
    return f[j++];
  };
  double q = next();
  if (n > 1) {
    double qn, hh;
    fast_two_sum(next(), q, qn, hh);
    q = qn;
    if (hh != 0.0) h[k++] = hh;
    for (int m = 2; m < n; ++m) {
      two_sum(q, next(), qn, hh);
      q = qn;
      if (hh != 0.0) h[k++] = hh;
    }
  }
  if (q != 0.0 || k == 0) h[k++] = q;
  return k;
}

// e = -e, in place (exact).
inline void negate(int n, double* e) {
  for (int m = 0; m < n; ++m) e[m] = -e[m];
}

// h = b * e. h has room for 2 * elen components (Shewchuk's scale-expansion).
inline int scale(int elen, const double* e, double b, double* h) {
  double bhi, blo;
  split(b, bhi, blo);
  int k = 0;
  double q, hh;
  two_product_split(e[0], b, bhi, blo, q, hh);
  if (hh != 0.0) h[k++] = hh;
  for (int m = 1; m < elen; ++m) {
    double p1, p0, s;
    two_product_split(e[m], b, bhi, blo, p1, p0);
    two_sum(q, p0, s, hh);
    if (hh != 0.0) h[k++] = hh;
    fast_two_sum(p1, s, q, hh);
    if (hh != 0.0) h[k++] = hh;
  }
  if (q != 0.0 || k == 0) h[k++] = q;
  return k;
}

// h = a*b - c*d for doubles (at most 4 components).
inline int two_by_two(double a, double b, double c, double d, double* h) {
  double p[2], q[2];
  two_product(a, b, p[1], p[0]);
  two_product(c, d, q[1], q[0]);
  q[0] = -q[0];
  q[1] = -q[1];
  return sum(2, p, 2, q, h);
}

inline int sign(int n, const double* e) { return (e[n - 1] > 0.0) - (e[n - 1] < 0.0); }

}  // namespace tetstream::core::expansion
