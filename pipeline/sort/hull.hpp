#pragma once
// The points on the convex hull's boundary. The certificate searches them to decide
// whether a window's hull facet is a facet of the global hull (pipeline/window/
// certificate.hpp, docs/certificate.md); a window too flat to triangulate on its own
// takes them in.

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

// Indices of every point on the boundary of conv(points): the hull's vertices and
// the points on its faces and edges (the pipeline relies on having all of them).
// Cheap filters first (points strictly inside the hull of the 26 directional
// extremes, then, when over 4 * sample_points remain, those strictly inside a tet of
// a sample of them: both are strictly inside conv(points)), then the kernel's
// triangulation of the survivors, whose infinite tets touch exactly the points on
// the boundary. Fewer than 4 affinely independent survivors: all of them are returned.
//
// Applied to pieces and then to the union of the pieces' results, it still finds
// every boundary point of the whole: a point on the boundary of conv(all) is on the
// boundary of conv(piece) for the piece that holds it.
inline constexpr std::size_t kHullSamplePoints = 16384;
std::vector<std::uint32_t> hull_vertex_candidates(const double* xyz, std::size_t n,
                                                  std::size_t sample_points = kHullSamplePoints);

// The facets of the convex hull of n distinct points (their labels, each triple in
// increasing order, the triples sorted), as the kernel's symbolic perturbation
// defines them: a flat face of the hull with many points on it is cut into the
// perturbed 2D Delaunay triangles that infinite_conflict_sos describes, the same ones
// every window's kernel finds. Given the hull's boundary points (hull_vertex_candidates),
// these are the facets of the hull of the whole input: a point strictly inside the hull
// is strictly below every facet's plane. Empty when the points have fewer than 4
// affinely independent ones (no 3D hull).
using LabelTriple = std::array<std::uint64_t, 3>;
std::vector<LabelTriple> hull_facet_labels(const double* xyz, const std::uint64_t* labels, std::size_t n);

}  // namespace tetstream::pipeline
