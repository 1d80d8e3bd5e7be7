#include "pipeline/field/geometry.hpp"

#include "core/predicates.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>

namespace tetstream::pipeline {
namespace {

struct V3 {
  double x, y, z;
};
inline V3 sub(const V3& a, const V3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline V3 add(const V3& a, const V3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline V3 scale(const V3& a, double s) { return {a.x * s, a.y * s, a.z * s}; }
inline double dot(const V3& a, const V3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline V3 cross(const V3& a, const V3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double det3(const V3& a, const V3& b, const V3& c) { return dot(a, cross(b, c)); }

// Circumcentre of the triangle (0, u, v), relative to its first vertex.
V3 face_circumcentre(const V3& u, const V3& v) {
  const V3 n = cross(u, v);
  const V3 w = sub(scale(v, dot(u, u)), scale(u, dot(v, v)));
  return scale(cross(w, n), 0.5 / dot(n, n));
}

}  // namespace

namespace {

// The faces through each edge: for vertex i and its edge to j, the two other vertices.
// Even permutations of (0,1,2,3) keep the positive orientation: sigma of (i, j, k, l)
// is its parity, +1 for even.
constexpr int parity(int i, int j, int k, int l) {
  const int p[4] = {i, j, k, l};
  int inv = 0;
  for (int x = 0; x < 4; ++x)
    for (int y = x + 1; y < 4; ++y) inv += p[x] > p[y];
  return inv % 2 == 0 ? 1 : -1;
}

// Face index by the vertex it omits: face f holds the three vertices other than f.
constexpr int face_without(int i, int j, int k) { return 6 - i - j - k; }

// splitmix64's finaliser: a bijection of 64-bit words that mixes every input bit into
// every output bit (the faces' hashes of the hull test).
inline std::uint64_t mix(std::uint64_t x) {
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

}  // namespace

void tet_hull_terms(const std::uint64_t q[4], std::uint64_t out[4]) {
  // Face f holds the vertices other than f, in index order (the boundary operator:
  // d[q0 q1 q2 q3] = sum_f (-1)^f [the others]); sorting its labels flips the sign once
  // a swap. Its signed hash goes to its three vertices, that is to all but vertex f:
  // out[i] = total - (signed hash of face i).
  // A face's hash is mix(m_a + 3 m_b + 5 m_c) over its labels a < b < c, with m = mix
  // of a label (four a tet, not twelve): two faces' sums before the last mix coincide
  // only by chance, 1 in 2^63 (the odd weights keep the order of the labels).
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  const std::uint64_t m[4] = {mix(q[0]), mix(q[1]), mix(q[2]), mix(q[3])};
  std::uint64_t face[4], total = 0;
  for (int f = 0; f < 4; ++f) {
    int a = kFace[f][0], b = kFace[f][1], c = kFace[f][2];
    bool odd = f & 1;
    if (q[a] > q[b]) std::swap(a, b), odd = !odd;
    if (q[b] > q[c]) std::swap(b, c), odd = !odd;
    if (q[a] > q[b]) std::swap(a, b), odd = !odd;
    const std::uint64_t h = mix(m[a] + 3 * m[b] + 5 * m[c]);
    face[f] = odd ? std::uint64_t(0) - h : h;
    total += face[f];
  }
  for (int i = 0; i < 4; ++i) out[i] = total - face[i];
}

double tet_volume(const double* const p[4]) {
  V3 v[4];
  for (int i = 1; i < 4; ++i) v[i] = {p[i][0] - p[0][0], p[i][1] - p[0][1], p[i][2] - p[0][2]};
  return det3(v[1], v[2], v[3]) / 6.0;
}

TetContribution tet_contribution(const double* const p[4], bool voronoi) {
  // Everything relative to vertex 0, so the arithmetic sees the tet's own scale.
  V3 v[4];
  for (int i = 0; i < 4; ++i) v[i] = {p[i][0] - p[0][0], p[i][1] - p[0][1], p[i][2] - p[0][2]};
  TetContribution out;
  const double d6 = det3(v[1], v[2], v[3]);
  out.volume = d6 / 6.0;
  if (!voronoi) {
    out.voronoi[0] = out.voronoi[1] = out.voronoi[2] = out.voronoi[3] = 0.0;
    return out;
  }
  V3 e[4][4];
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) {
      e[i][j] = sub(v[j], v[i]);
      e[j][i] = scale(e[i][j], -1.0);
    }
  // Tet circumcentre: (|u|^2 (v x w) + |v|^2 (w x u) + |w|^2 (u x v)) / (2 det).
  const V3 cc = scale(add(add(scale(cross(v[2], v[3]), dot(v[1], v[1])), scale(cross(v[3], v[1]), dot(v[2], v[2]))),
                          scale(cross(v[1], v[2]), dot(v[3], v[3]))),
                      0.5 / d6);
  // Face circumcentres, face f opposite vertex f.
  V3 fc[4];
  for (int f = 0; f < 4; ++f) {
    const int a = f == 0 ? 1 : 0, b = f <= 1 ? 2 : 1, c = f <= 2 ? 3 : 2;
    fc[f] = add(v[a], face_circumcentre(e[a][b], e[a][c]));
  }
  // For vertex i and edge ij the two faces ijk, ijl (k < l) have opposite signs
  // (sigma(i,j,l,k) = -sigma(i,j,k,l)), so their pieces combine into one determinant:
  //   sigma (det[M-p, F_ijk-p, C-p] - det[M-p, F_ijl-p, C-p]) = sigma (F_ijk - F_ijl) . ((C-p) x (M-p))
  // (p cancels in the difference): 12 cross products and dots a tet instead of 24
  // determinants, the Voronoi volume's cost halved.
  for (int i = 0; i < 4; ++i) {
    double vor = 0.0;
    const V3 c_rel = sub(cc, v[i]);
    for (int j = 0; j < 4; ++j) {
      if (j == i) continue;
      const int k = (i != 0 && j != 0) ? 0 : (i != 1 && j != 1) ? 1 : 2;  // the smaller other vertex
      const int l = 6 - i - j - k;
      const V3 g = cross(c_rel, scale(e[i][j], 0.5));
      vor += parity(i, j, k, l) * dot(sub(fc[face_without(i, j, k)], fc[face_without(i, j, l)]), g);
    }
    out.voronoi[i] = vor / 6.0;
  }
  return out;
}

namespace {

// The sign of n_x, n_y or n_z for the normal n = (b-a) x (c-a), exactly: a 2D
// orientation in the plane of the other two axes, written as orient3d of the points
// projected there (coordinates copied exactly) against an apex above the plane.
int normal_sign(const double* a, const double* b, const double* c, int axis) {
  const int u = (axis + 1) % 3, w = (axis + 2) % 3;
  const double pa[3] = {a[u], a[w], 0.0}, pb[3] = {b[u], b[w], 0.0}, pc[3] = {c[u], c[w], 0.0};
  const double apex[3] = {0.0, 0.0, 1.0};
  return core::orient3d(pa, pb, pc, apex);
}

// Sign of orient3d(a, b, c, g + e x + e^2 y + e^3 z) as e -> 0+: the exact sign when
// nonzero, else the first nonzero component of the normal in the order x, y, z.
int perturbed_orient(const double* a, const double* b, const double* c, const double* g) {
  const int s = core::orient3d(a, b, c, g);
  if (s != 0) return s;
  for (int axis = 0; axis < 3; ++axis)
    if (const int n = normal_sign(a, b, c, axis); n != 0) return n;
  return 0;  // a flat face: not in a valid container
}

}  // namespace

bool tet_contains(const double* a, const double* b, const double* c, const double* d, const double* g) {
  // g replaces each vertex in turn; each determinant is rewritten with g last by an
  // odd permutation (hence the "< 0") except the first.
  return perturbed_orient(a, b, c, g) > 0 && perturbed_orient(a, b, d, g) < 0 && perturbed_orient(a, d, c, g) < 0 &&
         perturbed_orient(d, b, c, g) < 0;
}

TetLocator::TetLocator(const double* a, const double* b, const double* c, const double* d) : p_{a, b, c, d} {
  // The four tests of tet_contains, as (face p, q, r; required sign).
  const double* faces[4][3] = {{a, b, c}, {a, b, d}, {a, d, c}, {d, b, c}};
  const double sign[4] = {1, -1, -1, -1};
  for (int f = 0; f < 4; ++f) {
    const double* p = faces[f][0];
    double u[3], v[3];
    for (int k = 0; k < 3; ++k) u[k] = faces[f][1][k] - p[k], v[k] = faces[f][2][k] - p[k], base_[f][k] = p[k];
    normal_[f][0] = sign[f] * (u[1] * v[2] - u[2] * v[1]);
    normal_[f][1] = sign[f] * (u[2] * v[0] - u[0] * v[2]);
    normal_[f][2] = sign[f] * (u[0] * v[1] - u[1] * v[0]);
    const double mu = std::max({std::fabs(u[0]), std::fabs(u[1]), std::fabs(u[2])});
    const double mv = std::max({std::fabs(v[0]), std::fabs(v[1]), std::fabs(v[2])});
    scale_[f] = mu * mv;
  }
}

bool TetLocator::contains(const double* g) const {
  bool sure = true;
  for (int f = 0; f < 4; ++f) {
    const double w[3] = {g[0] - base_[f][0], g[1] - base_[f][1], g[2] - base_[f][2]};
    const double value = normal_[f][0] * w[0] + normal_[f][1] * w[1] + normal_[f][2] * w[2];
    const double margin = 1e-13 * scale_[f] * std::max({std::fabs(w[0]), std::fabs(w[1]), std::fabs(w[2])});
    if (value < -margin) return false;  // clearly on the outer side of a face
    if (value <= margin) sure = false;
  }
  return sure || tet_contains(p_[0], p_[1], p_[2], p_[3], g);
}

double tet_interpolate(const double* const p[4], const double* f, const double* g) {
  V3 v[4];
  for (int i = 0; i < 4; ++i) v[i] = {p[i][0] - g[0], p[i][1] - g[1], p[i][2] - g[2]};
  // lambda_i = det with g in place of vertex i / det of the tet; with everything
  // relative to g, g is the origin.
  const double l0 = det3(sub(v[1], v[0]), sub(v[2], v[0]), sub(v[3], v[0]));
  const double w0 = det3(v[1], v[2], v[3]);
  const double w1 = -det3(v[0], v[2], v[3]);
  const double w2 = det3(v[0], v[1], v[3]);
  const double w3 = -det3(v[0], v[1], v[2]);
  return (w0 * f[0] + w1 * f[1] + w2 * f[2] + w3 * f[3]) / l0;
}

}  // namespace tetstream::pipeline
