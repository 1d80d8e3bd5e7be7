#pragma once
// The points on the convex hull's boundary. The certificate searches them to decide
// whether a window's hull facet is a facet of the global hull (pipeline/window/
// certificate.hpp, docs/certificate.md); a window too flat to triangulate on its own
// takes them in.

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

}  // namespace tetstream::pipeline
