#pragma once
// Exact geometric predicates with one consistent symbolic perturbation.
//
// Every predicate here returns the exact sign of its determinant for the given
// doubles: a semi-static floating-point filter (inline, below) answers almost always,
// and an exact fallback (out of line, predicates.cpp) answers when the filter cannot.
// Compile with -ffp-contract=off (the top-level CMakeLists does): the filter bounds
// assume every operation is rounded as written.
//
// Inputs must be finite doubles; any finite doubles are handled exactly (subnormals,
// 1e-300 next to 1e300, ...): the exact fallback is fixed-width integer arithmetic on
// the mantissas, 1 to 33 limbs wide (see predicates.cpp). Non-finite input gives 0.
//
// Conventions (one picture for the whole kernel):
//   orient3d(a,b,c,d) = sign det[b-a, c-a, d-a]  (rows are the difference vectors)
//     > 0  when (a,b,c,d) is a positively oriented tetrahedron, e.g.
//          a=(0,0,0) b=(1,0,0) c=(0,1,0) d=(0,0,1);
//          equivalently d lies on the side of plane abc that a,b,c turn
//          counter-clockwise around.
//   insphere(a,b,c,d,e)   for positively oriented (a,b,c,d):
//     > 0  when e lies strictly inside the circumsphere of a,b,c,d,
//     < 0  strictly outside, 0 on it.
//     It is the sign of the lifted polynomial
//       I = O_a w_a + O_b w_b + O_c w_c + O_d w_d - O w_e,   w_p = |p|^2,
//     where O = det[b-a,c-a,d-a] and O_p is the same determinant with e in p's place
//     (O_p / O are e's barycentric coordinates): I / O is how far the lifted point
//     (e, w_e) lies below the hyperplane through the lifted a, b, c, d, which is
//     positive exactly when e is inside the sphere. (I = -det of the 5x5 matrix with
//     rows (p, |p|^2, 1); it is antisymmetric in a, b, c, d.)
//
// Symbolic perturbation (Devillers & Teillaud 2011 / Edelsbrunner & Muecke): each
// point p is lifted to w_p + eps_p, eps_p = eps^(2^-rank), where rank orders labels and
// the LARGEST label gets the LARGEST perturbation (eps_p >> eps_q whenever
// label_p > label_q). I is linear in each w, so the perturbed polynomial is exactly
//   I_eps = I + O_a eps_a + O_b eps_b + O_c eps_c + O_d eps_d - O eps_e,
// and for eps -> 0+ its sign is sign(I) if I != 0, else the sign of the coefficient
// of the largest label whose coefficient is nonzero. The O_p are orient3d of four of
// the five points, and the coefficient of e is -O != 0 whenever (a,b,c,d) is not flat,
// so the perturbed insphere is never 0. It is a genuine perturbation (the regular
// triangulation of the points with tiny weights -eps_p), so all the answers are
// mutually consistent, and since labels are global and stable, two windows that share
// points give the same answers.
#include "core/compiler.hpp"

#include <cmath>
#include <cstdint>

namespace tetstream::core {

// Counters of filter failures, for profiling (per thread; summed by the caller).
//   *_exact      calls the inline filter could not decide (went out of line);
//   *_full_exact of those, calls that needed exact integer arithmetic (the rest
//                were settled by the cheap lattice test, see predicates.cpp);
//   insphere_perturbed  insphere_sos calls whose exact insphere was 0 (tie-break).
struct PredicateStats {
  std::uint64_t orient3d_calls = 0, orient3d_exact = 0;
  std::uint64_t insphere_calls = 0, insphere_exact = 0, insphere_perturbed = 0;
  std::uint64_t orient3d_full_exact = 0, insphere_full_exact = 0;
};

namespace detail {
// constinit: no dynamic initialisation, so an access is one %fs-relative add.
inline constinit thread_local PredicateStats tls_predicate_stats{};
}  // namespace detail

inline PredicateStats& predicate_stats();  // thread_local
inline void reset_predicate_stats();

// Exact sign of orient3d: -1, 0 or +1.
inline int orient3d(const double* a, const double* b, const double* c, const double* d);

// Exact sign of insphere (unperturbed): -1, 0 or +1. Requires orient3d(a,b,c,d) > 0
// (for a negatively oriented tet the sign is reversed: it is the sign of I above).
inline int insphere(const double* a, const double* b, const double* c, const double* d, const double* e);

// Perturbed insphere for a positively oriented finite tetrahedron (a,b,c,d) and a
// query e; labels la..le are distinct. Returns +1 (e in conflict: inside the
// perturbed sphere) or -1; never 0. (Exactly the sign of I_eps above, so for a
// negatively oriented (a,b,c,d) it returns the opposite answer: antisymmetric.)
inline int insphere_sos(const double* a, const double* b, const double* c, const double* d, const double* e,
                        std::uint64_t la, std::uint64_t lb, std::uint64_t lc, std::uint64_t ld, std::uint64_t le);

// Conflict test of e with the infinite tetrahedron on hull facet (a,b,c): the facet
// is oriented so that orient3d(a,b,c,p) < 0 for points p inside the hull. Returns
// +1 when e conflicts: orient3d(a,b,c,e) > 0, or e is coplanar with a,b,c and lies
// inside their circumcircle under the same perturbation that insphere_sos applies
// (so the answer agrees with insphere_sos of any finite tet (a,c,b,d) behind the
// facet, and of any finite tet (a,b,c,d') in front of it). Returns -1 otherwise;
// never 0 for distinct labels and a non-degenerate triangle abc.
inline int infinite_conflict_sos(const double* a, const double* b, const double* c, const double* e, std::uint64_t la,
                                 std::uint64_t lb, std::uint64_t lc, std::uint64_t le);

// Circumsphere of a positively oriented tetrahedron, in floating point, with a
// rigorous bound on its error: the true centre c* and squared radius r2* satisfy
// |c*_k - center[k]| <= center_error for each k, and |sqrt(r2*) - radius| <= radius_error.
// Used by the pipeline's certificate (docs/certificate.md), which treats "too close
// to call" as failing, so only soundness of the bound matters, not tightness.
struct Circumsphere {
  double center[3];
  double radius;
  double center_error;
  double radius_error;
  bool valid;  // false when the tetrahedron is too flat for a meaningful bound
};
Circumsphere circumsphere(const double* a, const double* b, const double* c, const double* d);

// The sign of c_axis - t, where c is the exact circumcentre of the tetrahedron abcd:
// +1 when the centre lies past the plane x_axis = t, -1 before it, 0 on it. Exact for
// any finite input (integer arithmetic: callers filter with circumsphere() first);
// 0 also for a flat tetrahedron, which has no centre. With u_i = p_i - a and
// s = t - a_axis, c_axis - t = det(U with column `axis` replaced by |u_i|^2 - 2 s u_i,axis)
// / (2 det U) (Cramer's rule on 2 U (c - a) = |u_i|^2).
int circumcentre_side(const double* a, const double* b, const double* c, const double* d, int axis, double t);

// ---------------------------------------------------------------------------------
// Inline filters. Everything below is implementation; the kernel sees only signs.
//
// Error model: IEEE binary64, round to nearest, u = 2^-53, no FMA. Each rounded
// operation gives fl(x op y) = (x op y)(1 + d), |d| <= u, as long as nothing
// overflows or underflows. Expand a computed polynomial into its monomials in the
// *exact* input differences (b_x - a_x, ...): each monomial picks up one factor
// (1 + d) per rounding on its path to the root, the subtractions of the inputs
// included, and at a product node the counts of both operands add. With at most n
// factors per monomial, |computed - exact| <= gamma_n * P, gamma_n = n u / (1 - n u),
// where P is the sum of the absolute values of the monomials (Higham, "Accuracy and
// Stability of Numerical Algorithms", ch. 3). The semi-static bound replaces P by an
// upper bound built from the per-axis maxima of the computed differences.
//
// orient3d: u_ = b-a, v_ = c-a, w_ = d-a (1 rounding each);
//   det = ux (vy wz - vz wy) - uy (vx wz - vz wx) + uz (vx wy - vy wx)
//   2x2 minor: 1+1 (operands) +1 (product) +1 (minus) = 4; times ux: 4+1+1 = 6;
//   two additions: n = 8. Each of the 6 monomials is one x, one y and one z
//   difference, so P <= 6 MX MY MZ (exact maxima); the computed maxima satisfy
//   MX_exact <= MX / (1 - u). So |err| <= 6 gamma_8 MX MY MZ / (1-u)^3, and the
//   bound itself, C * MX * MY * MZ evaluated with 3 roundings, must be at least that:
//   C >= 48 u (1 + 14 u + O(u^2)). We use C = 48 u (1 + 2^-40).
//
// insphere: X_p = p_x - e_x etc. for p in a,b,c,d (1 rounding);
//   m_pq = X_p Y_q - X_q Y_p                     (n = 4)
//   M_pqr = (Z_p m_qr - Z_q m_pr) + Z_r m_pq     (1 + 4 + 1, then +2: n = 8)
//   L_p = (X_p^2 + Y_p^2) + Z_p^2                (3, then +2: n = 5)
//   I = (L_a M_bcd - L_b M_acd) + (L_c M_abd - L_d M_abc)   (5 + 8 + 1, +2: n = 16)
//   (this is the 4x4 determinant [X Y Z L] of the translated points, negated, which
//   equals I above: translation leaves I unchanged.) P <= 4 * ML * 3 * MZ * 2 MX MY =
//   24 MX MY MZ ML, with ML = max_p L_p; computed L_p >= exact L_p (1-u)^5. So
//   |err| <= 24 gamma_16 MX MY MZ ML / (1-u)^8; the bound C*MX*MY*MZ*ML has 4 roundings:
//   C >= 384 u (1 + 28 u + O(u^2)). We use C = 384 u (1 + 2^-40).
//
// Underflow and overflow: the filters run only when every per-axis maximum lies in
// [lo, hi] (orient3d: [2^-300, 2^300]; insphere: [2^-140, 2^200]). Then nothing
// overflows (insphere: |L M| <= 18 * 2^1000 and the sums stay below 2^1007), and an
// underflowing product (absolute error <= 2^-1075), carried up to the root by factors
// bounded by the other maxima, adds at most 2^-600 times the bound, which the
// 2^-40 slack in C absorbs. Out of range (tiny or huge spreads, zero spread on an axis,
// NaN) goes to the exact fallback, which handles every finite input.
namespace detail {

inline constexpr double kOrientBoundC = 0x1.8p-48 * (1.0 + 0x1p-40);    // 48 u (1 + 2^-40)
inline constexpr double kInsphereBoundC = 0x1.8p-45 * (1.0 + 0x1p-40);  // 384 u (1 + 2^-40)
inline constexpr double kOrientLo = 0x1p-300, kOrientHi = 0x1p300;
inline constexpr double kInsphereLo = 0x1p-140, kInsphereHi = 0x1p200;

struct FilterValue {
  double det;    // the computed determinant
  double bound;  // |det - exact| <= bound, when in_range
  bool in_range;
  bool zero_axis;  // some axis has all differences exactly 0: the exact value is 0
};

TS_FORCE_INLINE double max3(double a, double b, double c) {
  const double m = a > b ? a : b;
  return m > c ? m : c;
}
TS_FORCE_INLINE double min3(double a, double b, double c) {
  const double m = a < b ? a : b;
  return m < c ? m : c;
}
TS_FORCE_INLINE double max4(double a, double b, double c, double d) {
  const double m = a > b ? a : b, n = c > d ? c : d;
  return m > n ? m : n;
}

TS_FORCE_INLINE FilterValue orient3d_filter(const double* a, const double* b, const double* c, const double* d) {
  const double ux = b[0] - a[0], uy = b[1] - a[1], uz = b[2] - a[2];
  const double vx = c[0] - a[0], vy = c[1] - a[1], vz = c[2] - a[2];
  const double wx = d[0] - a[0], wy = d[1] - a[1], wz = d[2] - a[2];
  const double det = ux * (vy * wz - vz * wy) - uy * (vx * wz - vz * wx) + uz * (vx * wy - vy * wx);
  const double mx = max3(std::fabs(ux), std::fabs(vx), std::fabs(wx));
  const double my = max3(std::fabs(uy), std::fabs(vy), std::fabs(wy));
  const double mz = max3(std::fabs(uz), std::fabs(vz), std::fabs(wz));
  const double lo = min3(mx, my, mz), hi = max3(mx, my, mz);
  FilterValue f;
  f.det = det;
  f.bound = kOrientBoundC * mx * my * mz;
  f.in_range = lo >= kOrientLo && hi <= kOrientHi;
  f.zero_axis = lo == 0.0;
  return f;
}

TS_FORCE_INLINE FilterValue insphere_filter(const double* a, const double* b, const double* c, const double* d,
                                            const double* e) {
  const double ax = a[0] - e[0], ay = a[1] - e[1], az = a[2] - e[2];
  const double bx = b[0] - e[0], by = b[1] - e[1], bz = b[2] - e[2];
  const double cx = c[0] - e[0], cy = c[1] - e[1], cz = c[2] - e[2];
  const double dx = d[0] - e[0], dy = d[1] - e[1], dz = d[2] - e[2];
  const double ab = ax * by - bx * ay, ac = ax * cy - cx * ay, ad = ax * dy - dx * ay;
  const double bc = bx * cy - cx * by, bd = bx * dy - dx * by, cd = cx * dy - dx * cy;
  const double abc = az * bc - bz * ac + cz * ab;
  const double abd = az * bd - bz * ad + dz * ab;
  const double acd = az * cd - cz * ad + dz * ac;
  const double bcd = bz * cd - cz * bd + dz * bc;
  const double la = ax * ax + ay * ay + az * az;
  const double lb = bx * bx + by * by + bz * bz;
  const double lc = cx * cx + cy * cy + cz * cz;
  const double ld = dx * dx + dy * dy + dz * dz;
  const double det = (la * bcd - lb * acd) + (lc * abd - ld * abc);
  const double mx = max4(std::fabs(ax), std::fabs(bx), std::fabs(cx), std::fabs(dx));
  const double my = max4(std::fabs(ay), std::fabs(by), std::fabs(cy), std::fabs(dy));
  const double mz = max4(std::fabs(az), std::fabs(bz), std::fabs(cz), std::fabs(dz));
  const double ml = max4(la, lb, lc, ld);
  const double lo = min3(mx, my, mz), hi = max3(mx, my, mz);
  FilterValue f;
  f.det = det;
  f.bound = kInsphereBoundC * mx * my * mz * ml;
  f.in_range = lo >= kInsphereLo && hi <= kInsphereHi;
  f.zero_axis = lo == 0.0;
  return f;
}

// Out-of-line exact paths (predicates.cpp).
// f is the filter's value for the same arguments (the fallback reuses it).
TS_NOINLINE int orient3d_fallback(const double* a, const double* b, const double* c, const double* d,
                                  const FilterValue& f);
TS_NOINLINE int insphere_fallback(const double* a, const double* b, const double* c, const double* d, const double* e,
                                  const FilterValue& f);
TS_NOINLINE int insphere_sos_tiebreak(const double* a, const double* b, const double* c, const double* d,
                                      const double* e, std::uint64_t la, std::uint64_t lb, std::uint64_t lc,
                                      std::uint64_t ld, std::uint64_t le);
TS_NOINLINE int infinite_conflict_coplanar(const double* a, const double* b, const double* c, const double* e,
                                           std::uint64_t la, std::uint64_t lb, std::uint64_t lc, std::uint64_t le);

}  // namespace detail

inline PredicateStats& predicate_stats() { return detail::tls_predicate_stats; }
inline void reset_predicate_stats() { detail::tls_predicate_stats = PredicateStats{}; }

TS_FORCE_INLINE int orient3d(const double* a, const double* b, const double* c, const double* d) {
  ++detail::tls_predicate_stats.orient3d_calls;
  const detail::FilterValue f = detail::orient3d_filter(a, b, c, d);
  if (TS_LIKELY(f.in_range)) {
    if (f.det > f.bound) return 1;
    if (f.det < -f.bound) return -1;
  }
  return detail::orient3d_fallback(a, b, c, d, f);
}

TS_FORCE_INLINE int insphere(const double* a, const double* b, const double* c, const double* d, const double* e) {
  ++detail::tls_predicate_stats.insphere_calls;
  const detail::FilterValue f = detail::insphere_filter(a, b, c, d, e);
  if (TS_LIKELY(f.in_range)) {
    if (f.det > f.bound) return 1;
    if (f.det < -f.bound) return -1;
  }
  return detail::insphere_fallback(a, b, c, d, e, f);
}

TS_FORCE_INLINE int insphere_sos(const double* a, const double* b, const double* c, const double* d, const double* e,
                                 std::uint64_t la, std::uint64_t lb, std::uint64_t lc, std::uint64_t ld,
                                 std::uint64_t le) {
  const int s = insphere(a, b, c, d, e);
  if (TS_LIKELY(s != 0)) return s;
  return detail::insphere_sos_tiebreak(a, b, c, d, e, la, lb, lc, ld, le);
}

inline int infinite_conflict_sos(const double* a, const double* b, const double* c, const double* e, std::uint64_t la,
                                 std::uint64_t lb, std::uint64_t lc, std::uint64_t le) {
  const int s = orient3d(a, b, c, e);
  if (TS_LIKELY(s != 0)) return s;
  return detail::infinite_conflict_coplanar(a, b, c, e, la, lb, lc, le);
}

}  // namespace tetstream::core
