#pragma once
// The plane of a facet with a fast, exact side test and a conservative box test: the
// certificate's hull-facet checks (pipeline/window/certificate.hpp) and the hull
// filter's inscribed box (pipeline/sort/hull.cpp).
#include "core/predicates.hpp"

#include <cmath>
#include <limits>

namespace tetstream::core {

// The plane of a hull facet (a, b, c), for a fast and exact sign of
// orient3d(a, b, c, p) = sign n.(p - a), n = (b - a) x (c - a) (negative: the
// interior side). For p with |p_k - a_k| <= extent[k], the value computed in doubles
// is within `error` of the exact one: the differences, the cross product and the dot
// product each round (about 8 eps sum_k N_k |p_k - a_k|, N_k = the two products of
// n_k in absolute value; doubled here for margin). Inside that margin only the exact
// predicate decides.
struct FacetPlane {
  FacetPlane(const double* pa, const double* pb, const double* pc, const double* extent) : a(pa), b(pb), c(pc) {
    constexpr double kEps = 0x1p-53;
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double bound = 0;
    for (int k = 0; k < 3; ++k) {
      const int i = (k + 1) % 3, j = (k + 2) % 3;
      n[k] = u[i] * v[j] - u[j] * v[i];
      bound += (std::fabs(u[i] * v[j]) + std::fabs(u[j] * v[i])) * extent[k];
    }
    // The bound assumes nothing overflows or underflows. With every extent at most
    // 2^300 nothing overflows, and an underflowing product (absolute error at most
    // 2^-1074, carried up by a difference of at most 2^300) adds far less than the
    // 2^-700 added here. Larger or non-finite extents: an infinite margin, so that
    // only the exact predicate decides.
    const bool in_range = extent[0] <= 0x1p300 && extent[1] <= 0x1p300 && extent[2] <= 0x1p300;
    error = in_range ? 16 * kEps * bound * (1 + 16 * kEps) + 0x1p-700 : std::numeric_limits<double>::infinity();
  }
  double value(const double* p) const { return n[0] * (p[0] - a[0]) + n[1] * (p[1] - a[1]) + n[2] * (p[2] - a[2]); }
  // orient3d(a, b, c, p) < 0, exactly.
  bool strictly_below(const double* p) const {
    const double g = value(p);
    if (g < -error) return true;
    if (g > error) return false;
    return orient3d(a, b, c, p) < 0;
  }
  // Whether the box [lo, hi] (within the extent of the bound) may hold a point with
  // orient3d(a, b, c, p) >= 0: conservative, never false when one exists. The largest
  // value over a box is at the corner farthest along n.
  bool box_may_reach(const double* lo, const double* hi) const {
    double corner[3];
    for (int k = 0; k < 3; ++k) corner[k] = n[k] >= 0 ? hi[k] : lo[k];
    return !(value(corner) < -error);  // NaN (an overflow): may reach
  }
  const double *a, *b, *c;
  double n[3], error;
};

}  // namespace tetstream::core
