#pragma once
// The per-tetrahedron geometry behind `tetstream field` (docs/fields.md): what one tet
// adds to each of its four vertices, and whether it holds a grid point.
//
// Every quantity is a sum over the tets incident to a point, so a point's value is
// final once all its tets have been seen (pipeline/field_window.hpp says when):
//
//   volume        V(t) = det[b-a, c-a, d-a] / 6 (> 0: the container's tets are positive).
//                 DTFE: rho_i = (d+1) m_i / sum_t V(t) = 4 m_i / sum_t V(t).
//   hull term     for each face f of t (opposite vertex f), a hash H_f of its three
//                 labels signed by the face's orientation as t's boundary sees it,
//                 s_f = (-1)^f * (the parity of sorting its labels); a vertex gets the
//                 sum over the three faces through it. Two tets sharing a face see it
//                 with opposite orientations. At an interior point every face through
//                 it is shared by two tets of its star, so its terms cancel exactly
//                 (sums mod 2^64, in any order). A point on the hull's boundary is a
//                 vertex of at least three boundary faces (faces of one tet), whose
//                 terms cancel only if 64-bit hashes do: 1 in 2^64 for each hull point.
//                 Combinatorial, like the rows' T = 2 d - 4 (field_accumulate.hpp): no
//                 coordinates, no rounding.
//   Voronoi       the cell of an interior point p is the union over its Delaunay edges
//                 pq of the pyramids (apex p) over the Voronoi facets of pq; a facet is
//                 cut into triangles (M_pq, F_f, C_t), one per tet t around pq and face
//                 f of t through pq, where M is the edge's midpoint, F the face's
//                 circumcentre and C the tet's. So |cell(p)| is the sum over the tets t
//                 at p, the three edges pq of t and the two faces pqr of t through pq of
//                 the signed volumes  sigma * det[M-p, F-p, C-p] / 6,  sigma = the sign
//                 of orient(p, q, r, s) (s: t's fourth vertex). A circumcentre outside
//                 its tet makes a piece negative, and the signs make the sum exact;
//                 for a hull point the sum means nothing (its cell is unbounded).
#include <cstdint>

namespace tetstream::pipeline {

// What one tet adds to each of its vertices (in the tet's vertex order).
struct TetContribution {
  double volume;      // V(t), the same for all four vertices
  double voronoi[4];  // the Voronoi pieces of t at each vertex
};

// p: the four vertices, 3 doubles each, positively oriented. Without `voronoi` the
// Voronoi pieces are left 0 (they are most of the cost).
TetContribution tet_contribution(const double* const p[4], bool voronoi = true);

// V(t) alone, the same bits as tet_contribution(p).volume (the same operations in the
// same order): `field --neighbours` alone needs only the volume (for `hull_volume`).
double tet_volume(const double* const p[4]);

// The hull terms of the tet with labels q[0..3] (positively oriented), one a vertex:
// a point is interior exactly when its terms sum to 0 mod 2^64 (see above).
void tet_hull_terms(const std::uint64_t q[4], std::uint64_t out[4]);

// Exact point location with a symbolic perturbation: whether g lies inside the
// positively oriented tet (a, b, c, d), where a point on a face is moved off it by an
// infinitesimal displacement g + e x + e^2 y + e^3 z (the same one for every tet), so
// each point of the hull's interior, faces and edges included, lies in exactly one
// tet, and two tets sharing a face decide it the same way (the exact orient3d of
// core/predicates.hpp, antisymmetric in the face's vertices).
bool tet_contains(const double* a, const double* b, const double* c, const double* d, const double* g);

// tet_contains for many points of one tet: the four face planes in floating point
// decide the points clearly inside or outside (the rounding of a plane's value is below
// 48 u |u|max |v|max |w|max, the orient3d filter's bound; the margin is 20 times that),
// and only points too close to a face to call go to tet_contains's exact test. The
// answers are tet_contains's.
class TetLocator {
 public:
  TetLocator(const double* a, const double* b, const double* c, const double* d);
  bool contains(const double* g) const;

 private:
  const double* p_[4];
  double base_[4][3];    // a point of each face
  double normal_[4][3];  // oriented so that inside is positive
  double scale_[4];      // |u|max |v|max of each face, for the margin
};

// The linear interpolant at g of the values f[0..3] at the vertices: barycentric
// coordinates from the sub-volumes, in floating point.
double tet_interpolate(const double* const p[4], const double* f, const double* g);

}  // namespace tetstream::pipeline
