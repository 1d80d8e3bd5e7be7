#pragma once
// Double-word ("double-double") arithmetic: a value hi + lo of two doubles with
// |lo| <= ulp(hi) / 2, about 106 significant bits, from error-free transformations
// (Knuth's TwoSum, Dekker's TwoProduct with Veltkamp's split: no FMA needed, so the
// results do not depend on the build's -march).
//
// Used where one more tier of precision between plain doubles and exact integers
// pays: the circumcentre of a flat tetrahedron (predicates.cpp), whose huge centre
// needs ~80 correct bits and whose exact integer evaluation was a quarter of a
// terrain's run time.
//
// Error model (Joldes, Muller & Popescu, "Tight and rigorous error bounds for basic
// building blocks of double-word arithmetic", ACM TOMS 2017): with u = 2^-53, the
// accurate sum (their Algorithm 6) has relative error below 3u^2 + 13u^3, the product
// without FMA (their Algorithm 10 with TwoProduct) below 7u^2, as long as nothing
// overflows and no partial result underflows. kRelativeError = 2^-100 (128 u^2)
// covers both with a wide margin; callers add their own absolute slack for underflow
// and keep every operand within about 2^±900 (Veltkamp's split overflows past 2^996).
namespace tetstream::core::dw {

struct DoubleWord {
  double hi, lo;
};

inline constexpr double kRelativeError = 0x1p-100;

// a + b = s + e exactly (Knuth).
inline DoubleWord two_sum(double a, double b) {
  const double s = a + b;
  const double bb = s - a;
  return {s, (a - (s - bb)) + (b - bb)};
}

// a + b = s + e exactly, when |a| >= |b| or a == 0 (Dekker).
inline DoubleWord fast_two_sum(double a, double b) {
  const double s = a + b;
  return {s, b - (s - a)};
}

// a = hi + lo with both halves of at most 26 significant bits (Veltkamp).
inline void split(double a, double& hi, double& lo) {
  const double c = 134217729.0 * a;  // 2^27 + 1
  hi = c - (c - a);
  lo = a - hi;
}

// a * b = p + e exactly (Dekker), barring overflow and underflow.
inline DoubleWord two_product(double a, double b) {
  const double p = a * b;
  double ah, al, bh, bl;
  split(a, ah, al);
  split(b, bh, bl);
  return {p, ((ah * bh - p) + ah * bl + al * bh) + al * bl};
}

inline DoubleWord exact_difference(double a, double b) { return two_sum(a, -b); }

inline DoubleWord operator+(DoubleWord x, DoubleWord y) {
  const DoubleWord s = two_sum(x.hi, y.hi), t = two_sum(x.lo, y.lo);
  const DoubleWord v = fast_two_sum(s.hi, s.lo + t.hi);
  return fast_two_sum(v.hi, t.lo + v.lo);
}

inline DoubleWord operator-(DoubleWord x) { return {-x.hi, -x.lo}; }
inline DoubleWord operator-(DoubleWord x, DoubleWord y) { return x + (-y); }

inline DoubleWord operator*(DoubleWord x, DoubleWord y) {
  const DoubleWord c = two_product(x.hi, y.hi);
  const double cross = x.hi * y.lo + x.lo * y.hi;
  return fast_two_sum(c.hi, c.lo + cross);
}

}  // namespace tetstream::core::dw
