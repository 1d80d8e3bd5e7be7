#pragma once
// The points on the convex hull's boundary, for the windows of the pipeline: with
// them in every window, the window's hull is the global hull and every point that
// could lie on the plane of a hull facet is present, so no tetrahedron near the hull
// goes missing and the hull facets need no check (DESIGN.md section 3).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

// Indices of every point on the boundary of conv(points): the hull's vertices and
// the points on its faces and edges (the pipeline relies on having all of them).
// Cheap filter first (points strictly inside the hull of the 26 directional
// extremes are strictly inside conv(points)), then the kernel's triangulation of the
// survivors, whose infinite tets touch exactly the points on the boundary.
// Fewer than 4 affinely independent survivors: all of them are returned.
//
// Applied to pieces and then to the union of the pieces' results, it still finds
// every boundary point of the whole: a point on the boundary of conv(all) is on the
// boundary of conv(piece) for the piece that holds it.
std::vector<std::uint32_t> hull_vertex_candidates(const double* xyz, std::size_t n);

}  // namespace tetstream::pipeline
