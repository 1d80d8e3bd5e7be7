#pragma once
// Convex-hull vertex candidates, for the windows of the pipeline: adding the global
// hull's vertices to every window makes the window's hull the global hull, so no
// tetrahedron near the hull goes missing (DESIGN.md section 3).
#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetstream::pipeline {

// Indices of a superset of the extreme vertices of conv(points): every vertex of the
// hull is returned; points on the hull's boundary may be returned too (harmless:
// they are real points). Cheap filter first (points strictly inside the hull of the
// 26 directional extremes cannot be vertices), then the kernel's hull of the
// survivors, whose hull vertices are exactly the points on the boundary.
// Fewer than 4 affinely independent points: all indices are returned.
std::vector<std::uint32_t> hull_vertex_candidates(const double* xyz, std::size_t n);

}  // namespace tetstream::pipeline
