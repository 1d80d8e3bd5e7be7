#pragma once
// Conservative comparisons of computed distances with a ball's radius: the one place
// where the certificate's range tests, its queries and the point index decide that a
// point or a box may lie in a ball. Each may answer "may reach" when it does not,
// never the reverse: a relative slack of 1e-12 on the squared radius covers the
// rounding of the few operations that computed the squares (a few units of 2^-53
// each), and an absolute 2^-1060 covers squares that round into the subnormals
// (each off by up to 2^-1075 whatever its size), where a relative slack does not.
// Squares that overflow compare as inf <= inf ("may reach") only when the distance
// and the radius both pass 2^511.

namespace tetstream::pipeline {

// r^2 enlarged by the relative slack.
inline double conservative_square(double r) { return r * r * (1 + 1e-12); }

// Whether a point at computed squared distance d2 from the centre may lie in the
// closed ball whose conservative_square is r2.
// (A NaN distance may reach: the exact test that follows decides.)
inline bool may_reach(double d2, double r2) { return !(d2 > r2 + 0x1p-1060); }

// The square of the distance from c to the interval [lo, hi] along one axis: the term
// each axis adds to a box's squared distance (box_meets_ball).
inline double axis_gap_square(double lo, double hi, double c) {
  double d = 0;
  if (c < lo)
    d = lo - c;
  else if (c > hi)
    d = c - hi;
  return d * d;
}

// Whether the box [lo, hi] meets the closed ball (c, r). Any finite or infinite box
// and ball.
inline bool box_meets_ball(const double* lo, const double* hi, const double* c, double r) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) d2 += axis_gap_square(lo[k], hi[k], c[k]);
  return may_reach(d2, conservative_square(r));
}

// A ball as the point index's region (PointIndex::for_each_candidate_where): the
// index knows it is a ball and tests a leaf's cells axis by axis (the same sums,
// from tables: the same answers as box_meets_ball).
struct BallRegion {
  const double* center;
  double radius;
  bool operator()(const double* lo, const double* hi) const { return box_meets_ball(lo, hi, center, radius); }
};

}  // namespace tetstream::pipeline
