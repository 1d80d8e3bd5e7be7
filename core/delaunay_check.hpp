#pragma once
// A validity certificate for an in-memory triangulation (core/delaunay.hpp), built
// only from the kernel's public accessors and the exact predicates, so it checks the
// kernel rather than trusting it. Used by the tests and by the pipeline's self-checks.
//
// What "valid" means here (docs/verify.md):
//   storage      every alive tet has 4 distinct vertices, at most one of them the
//                infinite vertex, all of them points of the kernel's array;
//   orientation  every finite tet is positively oriented (exact orient3d > 0);
//   adjacency    neighbor(neighbor(h)) == h, and both sides of a facet name the same
//                3 vertices; the infinite tets close the hull into a surface with
//                V - E + F = 2;
//   Delaunay     for every facet, the vertex of the neighbouring tet opposite it is
//                not in conflict with the tet (insphere_sos for a finite tet,
//                infinite_conflict_sos for an infinite one, with the points' labels).
//                Across the hull facets this is "the hull is locally convex", and with
//                the adjacency checks it makes the triangulation globally Delaunay;
//   topology     V - E + F - T = 1 for the finite complex, with edges and triangles
//                counted by sorting, independently of the neighbour arrays;
//   coverage     every input point is a vertex or maps through duplicate_of() to a
//                vertex with the same coordinates, and no two vertices coincide;
//   volume       the summed (unsigned) volume of the finite tets equals the volume
//                the hull facets enclose (divergence theorem), to a relative
//                tolerance: the tets cover the hull exactly once.
//
// No I/O: problems come back as strings in the report.
#include "core/delaunay.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace tetstream::core {

struct CheckOptions {
  // Test the local Delaunay condition from both sides of every facet between two
  // finite tets (twice the predicate calls; also catches an inconsistent predicate).
  bool both_sides = false;
  bool check_delaunay = true;  // the insphere tests, the most expensive part
  bool check_euler = true;     // sorts every edge and triangle: ~20 bytes per facet
  bool check_coverage = true;
  bool check_volume = true;
  double volume_rel_tolerance = 1e-9;
  std::size_t max_messages = 8;  // violations described in full; all are counted
};

struct CheckReport {
  bool ok = false;

  // What was found.
  std::uint64_t points = 0;      // num_points() of the kernel
  std::uint64_t vertices = 0;    // distinct vertices of finite tets
  std::uint64_t duplicates = 0;  // points p with duplicate_of(p) != p
  std::uint64_t finite_tets = 0;
  std::uint64_t infinite_tets = 0;  // = hull facets
  std::uint64_t edges = 0;          // of the finite complex
  std::uint64_t triangles = 0;      // of the finite complex
  std::int64_t euler = 0;           // V - E + F - T, 1 when valid
  std::uint64_t hull_vertices = 0;
  std::uint64_t hull_edges = 0;
  std::uint64_t facets_tested = 0;  // conflict tests made
  double tet_volume = 0;            // sum of finite tet volumes (unsigned)
  double hull_volume = 0;           // volume enclosed by the hull facets
  double volume_rel_error = 0;

  // Violations of each kind (0 when valid).
  std::uint64_t bad_storage = 0;  // bad vertex ids, repeated vertices, freed neighbours
  std::uint64_t bad_orientation = 0;
  std::uint64_t bad_adjacency = 0;
  std::uint64_t bad_delaunay = 0;  // a finite tet's circumsphere holds a neighbour's vertex
  std::uint64_t bad_hull = 0;      // hull not locally convex, or not a closed surface
  std::uint64_t bad_topology = 0;  // Euler characteristic, counts disagreeing with the kernel
  std::uint64_t bad_coverage = 0;  // a point neither a vertex nor a duplicate of one
  std::uint64_t bad_volume = 0;

  // The first max_messages violations, e.g. "orientation: tet 17 (3 9 12 40): orient3d = -1".
  std::vector<std::string> messages;

  std::uint64_t violations() const {
    return bad_storage + bad_orientation + bad_adjacency + bad_delaunay + bad_hull + bad_topology + bad_coverage +
           bad_volume;
  }
  // One line of counts, then the messages, one a line.
  std::string summary() const;
};

CheckReport check_delaunay(const Delaunay& dt, const CheckOptions& options = {});

}  // namespace tetstream::core
