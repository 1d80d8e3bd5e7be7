#include "core/delaunay_check.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <utility>

namespace tetstream::core {
namespace {

// Collects violations: every one is counted, the first few are described.
class Violations {
 public:
  Violations(CheckReport& report, std::size_t max_messages) : report_(report), max_(max_messages) {}

  // `describe` builds the message lazily: most checks on a broken kernel fail
  // millions of times and only the first few strings are kept.
  template <class Describe>
  void add(std::uint64_t& counter, Describe&& describe) {
    ++counter;
    if (report_.messages.size() < max_) report_.messages.push_back(describe());
  }

 private:
  CheckReport& report_;
  std::size_t max_;
};

std::string vertex_name(VertexId v) { return v == kInfiniteVertex ? std::string("inf") : std::to_string(v); }

std::string tet_name(const Delaunay& dt, TetId t) {
  std::string s = "tet " + std::to_string(t) + " (";
  for (int i = 0; i < 4; ++i) {
    if (i) s += ' ';
    s += vertex_name(dt.vertex(t, i));
  }
  return s + ")";
}

std::string facet_name(const Delaunay& dt, TetId t, int f) { return tet_name(dt, t) + " facet " + std::to_string(f); }

int infinite_index(const Delaunay& dt, TetId t) {
  for (int i = 0; i < 4; ++i)
    if (dt.vertex(t, i) == kInfiniteVertex) return i;
  return -1;
}

std::array<VertexId, 3> sorted_facet(const Delaunay& dt, TetId t, int f) {
  std::array<VertexId, 3> k = {dt.vertex(t, kFacetVertex[f][0]), dt.vertex(t, kFacetVertex[f][1]),
                               dt.vertex(t, kFacetVertex[f][2])};
  std::sort(k.begin(), k.end());
  return k;
}

std::uint64_t edge_key(VertexId a, VertexId b) {
  if (a > b) std::swap(a, b);
  return (std::uint64_t(a) << 32) | b;
}

// det[b-a, c-a, d-a] in floating point (6 times the signed volume).
double det3(const double* a, const double* b, const double* c, const double* d) {
  const double bx = b[0] - a[0], by = b[1] - a[1], bz = b[2] - a[2];
  const double cx = c[0] - a[0], cy = c[1] - a[1], cz = c[2] - a[2];
  const double dx = d[0] - a[0], dy = d[1] - a[1], dz = d[2] - a[2];
  return bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx);
}

// Counts the distinct keys of a vector (sorts it in place).
template <class T>
std::uint64_t count_distinct(std::vector<T>& keys) {
  std::sort(keys.begin(), keys.end());
  return std::uint64_t(std::unique(keys.begin(), keys.end()) - keys.begin());
}

// Counts distinct (bucket, value) pairs: `emit(sink)` calls sink(bucket, value) for
// every pair, and is run twice (count, then fill). Bucketing by a vertex first
// leaves many small sorts instead of one huge one: several times faster than a
// global sort, and the values need fewer bytes than whole keys.
template <class Value, class Emit>
std::uint64_t count_distinct_bucketed(std::size_t buckets, Emit&& emit) {
  std::vector<std::uint64_t> offset(buckets + 1, 0);
  emit([&](VertexId b, Value) { ++offset[b + 1]; });
  for (std::size_t i = 0; i < buckets; ++i) offset[i + 1] += offset[i];
  std::vector<Value> values(offset[buckets]);
  {
    std::vector<std::uint64_t> next(offset.begin(), offset.end() - 1);
    emit([&](VertexId b, Value v) { values[next[b]++] = v; });
  }
  std::uint64_t distinct = 0;
#pragma omp parallel for schedule(dynamic, 4096) reduction(+ : distinct) if (buckets > (1u << 16))
  for (std::int64_t b = 0; b < std::int64_t(buckets); ++b) {
    Value* first = values.data() + offset[b];
    Value* last = values.data() + offset[b + 1];
    std::sort(first, last);
    distinct += std::uint64_t(std::unique(first, last) - first);
  }
  return distinct;
}

}  // namespace

std::string CheckReport::summary() const {
  std::string s = ok ? "valid" : "INVALID";
  s += ": points " + std::to_string(points) + ", vertices " + std::to_string(vertices) + ", duplicates " +
       std::to_string(duplicates) + ", finite tets " + std::to_string(finite_tets) + ", hull facets " +
       std::to_string(infinite_tets) + ", V-E+F-T " + std::to_string(euler) + ", volume error " +
       std::to_string(volume_rel_error) + "; violations: storage " + std::to_string(bad_storage) + ", orientation " +
       std::to_string(bad_orientation) + ", adjacency " + std::to_string(bad_adjacency) + ", delaunay " +
       std::to_string(bad_delaunay) + ", hull " + std::to_string(bad_hull) + ", topology " +
       std::to_string(bad_topology) + ", coverage " + std::to_string(bad_coverage) + ", volume " +
       std::to_string(bad_volume);
  for (const std::string& m : messages) s += "\n  " + m;
  return s;
}

CheckReport check_delaunay(const Delaunay& dt, const CheckOptions& options) {
  CheckReport r;
  Violations bad(r, options.max_messages);
  const std::size_t n = dt.num_points();
  const std::size_t slots = dt.num_tet_slots();
  r.points = n;

  // 1. Storage: vertex ids in range and distinct, at most one infinite vertex.
  //    A tet that fails here takes no part in the geometric checks.
  std::vector<std::uint8_t> broken(slots, 0);
  std::vector<std::uint8_t> is_vertex(n, 0);
  for (TetId t = 0; t < slots; ++t) {
    if (!dt.is_alive(t)) continue;
    int infinite = 0;
    bool ok = true;
    for (int i = 0; i < 4; ++i) {
      const VertexId v = dt.vertex(t, i);
      if (v == kInfiniteVertex) {
        ++infinite;
      } else if (v >= n) {
        ok = false;
      }
      for (int j = 0; j < i; ++j)
        if (dt.vertex(t, j) == v) ok = false;
    }
    if (infinite > 1) ok = false;
    if (!ok) {
      broken[t] = 1;
      bad.add(r.bad_storage, [&] { return "storage: " + tet_name(dt, t) + ": bad or repeated vertex"; });
      continue;
    }
    if (infinite) {
      ++r.infinite_tets;
    } else {
      ++r.finite_tets;
      for (int i = 0; i < 4; ++i) is_vertex[dt.vertex(t, i)] = 1;
    }
  }
  if (r.finite_tets == 0) {
    bad.add(r.bad_topology, [] { return std::string("topology: no finite tetrahedra"); });
    return r;
  }

  // A point strictly inside the hull (the centroid of the vertices): the apex of the
  // cones over the hull facets, so every cone has positive volume (no cancellation).
  double origin[3];
  {
    long double sum[3] = {0, 0, 0};
    for (VertexId v = 0; v < n; ++v) {
      if (!is_vertex[v]) continue;
      ++r.vertices;
      for (int k = 0; k < 3; ++k) sum[k] += dt.point(v)[k];
    }
    for (int k = 0; k < 3; ++k) origin[k] = double(sum[k] / (long double)r.vertices);
  }

  // 2. Per tet: orientation and volume, then per facet: adjacency and conflict.
  long double tet_volume = 0, hull_volume = 0;
  std::vector<std::uint64_t> hull_edges;
  std::vector<VertexId> hull_vertices;
  hull_edges.reserve(3 * r.infinite_tets);
  hull_vertices.reserve(3 * r.infinite_tets);
  for (TetId t = 0; t < slots; ++t) {
    if (!dt.is_alive(t) || broken[t]) continue;
    const int inf = infinite_index(dt, t);
    const VertexId v[4] = {dt.vertex(t, 0), dt.vertex(t, 1), dt.vertex(t, 2), dt.vertex(t, 3)};
    if (inf < 0) {
      const int o = orient3d(dt.point(v[0]), dt.point(v[1]), dt.point(v[2]), dt.point(v[3]));
      if (o <= 0)
        bad.add(r.bad_orientation,
                [&] { return "orientation: " + tet_name(dt, t) + ": orient3d = " + std::to_string(o); });
      // Unsigned: inverted or overlapping tets then show up as excess volume.
      tet_volume += std::abs(det3(dt.point(v[0]), dt.point(v[1]), dt.point(v[2]), dt.point(v[3])));
    } else {
      const VertexId a = v[kFacetVertex[inf][0]], b = v[kFacetVertex[inf][1]], c = v[kFacetVertex[inf][2]];
      // Outward orientation: the interior is on the negative side of (a, b, c).
      hull_volume += det3(origin, dt.point(a), dt.point(b), dt.point(c));
      hull_edges.push_back(edge_key(a, b));
      hull_edges.push_back(edge_key(b, c));
      hull_edges.push_back(edge_key(c, a));
      hull_vertices.push_back(a);
      hull_vertices.push_back(b);
      hull_vertices.push_back(c);
    }

    for (int f = 0; f < 4; ++f) {
      const FacetHandle h = dt.neighbor(t, f);
      const TetId t2 = h >> 2;
      const int f2 = int(h & 3);
      if (t2 >= slots || !dt.is_alive(t2) || t2 == t) {
        bad.add(r.bad_adjacency, [&] {
          return "adjacency: " + facet_name(dt, t, f) + ": neighbour handle " + std::to_string(h) +
                 " is not an alive other tet";
        });
        continue;
      }
      if (dt.neighbor(t2, f2) != 4 * t + FacetHandle(f)) {
        bad.add(r.bad_adjacency, [&] {
          return "adjacency: " + facet_name(dt, t, f) + ": neighbour " + facet_name(dt, t2, f2) + " points back to " +
                 std::to_string(dt.neighbor(t2, f2));
        });
        continue;
      }
      if (broken[t2]) continue;
      if (sorted_facet(dt, t, f) != sorted_facet(dt, t2, f2)) {
        bad.add(r.bad_adjacency,
                [&] { return "adjacency: " + facet_name(dt, t, f) + " and " + facet_name(dt, t2, f2) + " differ"; });
        continue;
      }
      const VertexId w = dt.vertex(t2, f2);
      if (w == kInfiniteVertex) {
        // Two infinite tets glued along their finite facet: the hull is not closed.
        if (inf >= 0)
          bad.add(r.bad_hull, [&] { return "hull: infinite " + facet_name(dt, t, f) + " faces another infinite tet"; });
        continue;
      }
      if (!options.check_delaunay) continue;
      if (inf < 0) {
        if (!options.both_sides && 4 * t + FacetHandle(f) > h) continue;
        ++r.facets_tested;
        const int s = insphere_sos(dt.point(v[0]), dt.point(v[1]), dt.point(v[2]), dt.point(v[3]), dt.point(w),
                                   dt.label(v[0]), dt.label(v[1]), dt.label(v[2]), dt.label(v[3]), dt.label(w));
        if (s > 0)
          bad.add(r.bad_delaunay, [&] {
            return "delaunay: " + facet_name(dt, t, f) + ": opposite vertex " + std::to_string(w) + " of tet " +
                   std::to_string(t2) + " is inside the circumsphere";
          });
      } else {
        // The conflict region of an infinite tet is the open half-space beyond its
        // hull facet (plus, on the facet's plane, the perturbed circumdisc).
        // Across a facet through the infinite vertex, w is the third vertex of the
        // next hull facet: no conflict means the hull is locally convex there.
        ++r.facets_tested;
        const VertexId a = v[kFacetVertex[inf][0]], b = v[kFacetVertex[inf][1]], c = v[kFacetVertex[inf][2]];
        const int s = infinite_conflict_sos(dt.point(a), dt.point(b), dt.point(c), dt.point(w), dt.label(a),
                                            dt.label(b), dt.label(c), dt.label(w));
        if (s > 0) {
          if (f == inf) {
            bad.add(r.bad_delaunay, [&] {
              return "delaunay: hull " + facet_name(dt, t, f) + ": apex " + std::to_string(w) + " of tet " +
                     std::to_string(t2) + " is beyond the hull facet";
            });
          } else {
            bad.add(r.bad_hull, [&] {
              return "hull: not locally convex at " + facet_name(dt, t, f) + ": vertex " + std::to_string(w) +
                     " of the next hull facet is beyond it";
            });
          }
        }
      }
    }
  }

  // 3. The hull is a closed surface of genus 0: each hull edge on exactly two hull
  //    facets, and V - E + F = 2.
  {
    std::sort(hull_edges.begin(), hull_edges.end());
    std::uint64_t distinct = 0;
    for (std::size_t i = 0; i < hull_edges.size();) {
      std::size_t j = i;
      while (j < hull_edges.size() && hull_edges[j] == hull_edges[i]) ++j;
      if (j - i != 2) {
        const std::uint64_t e = hull_edges[i];
        const std::size_t times = j - i;
        bad.add(r.bad_hull, [&] {
          return "hull: edge (" + std::to_string(e >> 32) + " " + std::to_string(e & 0xFFFFFFFFu) + ") is on " +
                 std::to_string(times) + " hull facets, not 2";
        });
      }
      ++distinct;
      i = j;
    }
    r.hull_edges = distinct;
    r.hull_vertices = count_distinct(hull_vertices);
    const std::int64_t chi = std::int64_t(r.hull_vertices) - std::int64_t(r.hull_edges) + std::int64_t(r.infinite_tets);
    if (chi != 2)
      bad.add(r.bad_hull, [&] { return "hull: V - E + F = " + std::to_string(chi) + " for the hull surface, not 2"; });
    std::vector<std::uint64_t>().swap(hull_edges);
    std::vector<VertexId>().swap(hull_vertices);
  }

  // 4. Euler characteristic of the finite complex, edges and triangles counted by
  //    sorting (independent of the neighbour arrays).
  if (options.check_euler) {
    auto finite = [&](TetId t) { return dt.is_alive(t) && !broken[t] && infinite_index(dt, t) < 0; };
    r.edges = count_distinct_bucketed<VertexId>(n, [&](auto&& sink) {
      for (TetId t = 0; t < slots; ++t) {
        if (!finite(t)) continue;
        for (int i = 0; i < 4; ++i)
          for (int j = i + 1; j < 4; ++j) {
            const VertexId a = dt.vertex(t, i), b = dt.vertex(t, j);
            a < b ? sink(a, b) : sink(b, a);
          }
      }
    });
    r.triangles = count_distinct_bucketed<std::uint64_t>(n, [&](auto&& sink) {
      for (TetId t = 0; t < slots; ++t) {
        if (!finite(t)) continue;
        for (int f = 0; f < 4; ++f) {
          const std::array<VertexId, 3> k = sorted_facet(dt, t, f);
          sink(k[0], (std::uint64_t(k[1]) << 32) | k[2]);
        }
      }
    });
    r.euler =
        std::int64_t(r.vertices) - std::int64_t(r.edges) + std::int64_t(r.triangles) - std::int64_t(r.finite_tets);
    if (r.euler != 1)
      bad.add(r.bad_topology, [&] { return "topology: V - E + F - T = " + std::to_string(r.euler) + ", not 1"; });
  }
  if (dt.num_finite_tets() != r.finite_tets)
    bad.add(r.bad_topology, [&] {
      return "topology: num_finite_tets() = " + std::to_string(dt.num_finite_tets()) + " but " +
             std::to_string(r.finite_tets) + " finite tets are alive";
    });
  if (dt.num_infinite_tets() != r.infinite_tets)
    bad.add(r.bad_topology, [&] {
      return "topology: num_infinite_tets() = " + std::to_string(dt.num_infinite_tets()) + " but " +
             std::to_string(r.infinite_tets) + " infinite tets are alive";
    });
  if (dt.num_vertices() != r.vertices)
    bad.add(r.bad_topology, [&] {
      return "topology: num_vertices() = " + std::to_string(dt.num_vertices()) + " but " + std::to_string(r.vertices) +
             " points are vertices of finite tets";
    });

  // 5. Coverage: each point is a vertex, or a duplicate of a vertex with the same
  //    coordinates; no two vertices coincide; incident_tet() agrees.
  if (options.check_coverage) {
    for (VertexId p = 0; p < n; ++p) {
      const VertexId d = dt.duplicate_of(p);
      const TetId it = dt.incident_tet(p);
      if (d == p) {
        if (!is_vertex[p]) {
          bad.add(r.bad_coverage, [&] { return "coverage: point " + std::to_string(p) + " is not a vertex"; });
          continue;
        }
        bool found = it < slots && dt.is_alive(it);
        if (found) {
          found = false;
          for (int i = 0; i < 4; ++i) found = found || dt.vertex(it, i) == p;
        }
        if (!found)
          bad.add(r.bad_storage, [&] {
            return "storage: incident_tet(" + std::to_string(p) + ") = " + std::to_string(it) +
                   " is not an alive tet with that vertex";
          });
        continue;
      }
      ++r.duplicates;
      const double* a = dt.point(p);
      const double* b = d < n ? dt.point(d) : nullptr;
      if (d >= n || dt.duplicate_of(d) != d || !is_vertex[d] || is_vertex[p] || a[0] != b[0] || a[1] != b[1] ||
          a[2] != b[2]) {
        bad.add(r.bad_coverage, [&] {
          return "coverage: point " + std::to_string(p) + " has duplicate_of = " + std::to_string(d) +
                 ", which is not a vertex with the same coordinates (or the point is a vertex itself)";
        });
      } else if (it != kNoTet) {
        bad.add(r.bad_storage, [&] {
          return "storage: incident_tet(" + std::to_string(p) + ") = " + std::to_string(it) +
                 " for a duplicate point (expected kNoTet)";
        });
      }
    }
    std::vector<VertexId> order;
    order.reserve(r.vertices);
    for (VertexId v = 0; v < n; ++v)
      if (is_vertex[v]) order.push_back(v);
    auto less = [&](VertexId a, VertexId b) {
      const double *p = dt.point(a), *q = dt.point(b);
      return std::lexicographical_compare(p, p + 3, q, q + 3);
    };
    std::sort(order.begin(), order.end(), less);
    for (std::size_t i = 1; i < order.size(); ++i) {
      if (!less(order[i - 1], order[i])) {
        const VertexId a = order[i - 1], b = order[i];
        bad.add(r.bad_coverage, [&] {
          return "coverage: vertices " + std::to_string(a) + " and " + std::to_string(b) + " have the same coordinates";
        });
      }
    }
  }

  // 6. Volume: the tets fill the hull exactly once (6x volumes cancel in the ratio).
  r.tet_volume = double(tet_volume / 6);
  r.hull_volume = double(hull_volume / 6);
  if (options.check_volume) {
    const double scale = std::max(std::abs(r.hull_volume), std::abs(r.tet_volume));
    r.volume_rel_error = scale > 0 ? std::abs(r.tet_volume - r.hull_volume) / scale : 0.0;
    if (!(r.volume_rel_error <= options.volume_rel_tolerance))
      bad.add(r.bad_volume, [&] {
        return "volume: tets " + std::to_string(r.tet_volume) + " vs hull " + std::to_string(r.hull_volume) +
               " (relative error " + std::to_string(r.volume_rel_error) + ")";
      });
  }

  r.ok = r.violations() == 0;
  return r;
}

}  // namespace tetstream::core
