// tetstream._core, continued: the queries scipy.spatial.Delaunay answers on a
// triangulation it holds (python/tetstream/__init__.py's Triangulation calls them):
//
//   find_simplex(points, simplices, neighbors, vertex_to_simplex, xi, threads)
//       the simplex that holds each query point, -1 outside the hull: exact
//       (core/point_location.hpp: walks across facets, the queries in Hilbert order)
//   vertex_to_simplex(simplices, npoints)      one simplex of each vertex, -1 for none
//   vertex_neighbor_vertices(simplices, npoints, threads)   CSR (indptr, indices)
//
// Index arrays come as int32 or int64 (Triangulation's dtype); the answers are int32
// (numpy.intc, scipy's type) while every value fits, else int64.
#include "python/tetstream/_geometry.hpp"

#include "core/error.hpp"
#include "core/point_location.hpp"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

namespace py = pybind11;

namespace tetstream::python {
namespace {

template <class T>
py::array_t<T> owned_array(std::vector<T>&& v, std::vector<py::ssize_t> shape) {
  auto* owned = new std::vector<T>(std::move(v));
  py::capsule owner(owned, [](void* q) { delete static_cast<std::vector<T>*>(q); });
  return py::array_t<T>(shape, owned->empty() ? nullptr : owned->data(), owner);
}

template <class T>
const T* checked_rows(const py::array& a, std::size_t cols, const char* name, std::size_t& rows) {
  if (a.ndim() != 2 || std::size_t(a.shape(1)) != cols || !(a.flags() & py::array::c_style))
    throw UsageError(std::string(name) + ": expected a C-contiguous (n, " + std::to_string(cols) + ") array");
  rows = std::size_t(a.shape(0));
  return static_cast<const T*>(a.data());
}

template <class I, class R>
void find_simplex_into(const double* points, std::size_t npoints, const py::array& simplices,
                       const py::array& neighbors, const py::array& v2s, const double* xi, std::size_t nq, R* out,
                       int threads) {
  core::locate_detail::Table<I> s, nb;
  s.data = checked_rows<I>(simplices, 4, "simplices", s.rows);
  nb.data = checked_rows<I>(neighbors, 4, "neighbors", nb.rows);
  if (nb.rows != s.rows) throw UsageError("neighbors and simplices differ in length");
  if (v2s.ndim() != 1 || std::size_t(v2s.shape(0)) != npoints) throw UsageError("vertex_to_simplex: wrong shape");
  const I* vertex_tet = static_cast<const I*>(v2s.data());
  py::gil_scoped_release release;
  core::locate_points<I, R>(points, s.data, nb.data, s.rows, vertex_tet, npoints, xi, nq, out, threads);
}

bool is_int32(const py::array& a) { return a.dtype().is(py::dtype::of<std::int32_t>()); }
bool is_int64(const py::array& a) { return a.dtype().is(py::dtype::of<std::int64_t>()); }

py::array find_simplex(py::array_t<double, py::array::c_style> points, py::array simplices, py::array neighbors,
                       py::array vertex_to_simplex, py::array_t<double, py::array::c_style> xi, int threads) {
  if (points.ndim() != 2 || points.shape(1) != 3) throw UsageError("points: expected an (N, 3) array");
  if (xi.ndim() != 2 || xi.shape(1) != 3) throw UsageError("xi: expected a (Q, 3) array");
  if (std::size_t(xi.shape(0)) >= (std::size_t(1) << 32)) throw UsageError("xi: at most 2^32 - 1 query points a call");
  const std::size_t nq = std::size_t(xi.shape(0));
  py::array_t<std::int32_t> out{py::ssize_t(nq)};
  if (std::size_t(simplices.shape(0)) > std::size_t(std::numeric_limits<std::int32_t>::max()))
    throw UsageError("find_simplex: more simplices than int32 holds");
  if (is_int32(simplices) && is_int32(neighbors) && is_int32(vertex_to_simplex))
    find_simplex_into<std::int32_t>(points.data(), std::size_t(points.shape(0)), simplices, neighbors,
                                    vertex_to_simplex, xi.data(), nq, out.mutable_data(), threads);
  else if (is_int64(simplices) && is_int64(neighbors) && is_int64(vertex_to_simplex))
    find_simplex_into<std::int64_t>(points.data(), std::size_t(points.shape(0)), simplices, neighbors,
                                    vertex_to_simplex, xi.data(), nq, out.mutable_data(), threads);
  else
    throw UsageError("simplices, neighbors and vertex_to_simplex must all be int32 or all int64");
  return out;
}

template <class I>
py::array vertex_to_simplex_t(const py::array& simplices, std::size_t npoints) {
  std::size_t m = 0;
  const I* s = checked_rows<I>(simplices, 4, "simplices", m);
  std::vector<I> out(npoints, I(-1));
  {
    py::gil_scoped_release release;
    for (std::size_t t = 0; t < m; ++t)
      for (int j = 0; j < 4; ++j) {
        const I v = s[4 * t + j];
        if (v < 0 || std::size_t(v) >= npoints) throw UsageError("simplices: an index out of range");
        out[std::size_t(v)] = I(t);
      }
  }
  return owned_array(std::move(out), {py::ssize_t(npoints)});
}

py::array vertex_to_simplex(py::array simplices, std::size_t npoints) {
  if (is_int32(simplices)) return vertex_to_simplex_t<std::int32_t>(simplices, npoints);
  if (is_int64(simplices)) return vertex_to_simplex_t<std::int64_t>(simplices, npoints);
  throw UsageError("simplices must be int32 or int64");
}

// The Delaunay edges as a CSR matrix: for vertex k, its neighbours sorted ascending in
// indices[indptr[k]:indptr[k+1]]. From each vertex's tets (a CSR of its own, built by
// counting), their vertices gathered, sorted and made unique, in parallel over vertices.
template <class I, class O>
py::tuple vertex_neighbors_t(const I* s, std::size_t m, std::size_t npoints, int threads) {
  std::vector<O> indptr(npoints + 1, 0);
  std::vector<O> indices;
  {
    py::gil_scoped_release release;
    std::vector<std::uint64_t> tet_start(npoints + 1, 0);
    for (std::size_t i = 0; i < 4 * m; ++i) ++tet_start[std::size_t(s[i]) + 1];
    for (std::size_t v = 0; v < npoints; ++v) tet_start[v + 1] += tet_start[v];
    std::vector<std::uint32_t> tets(4 * m);
    {
      std::vector<std::uint64_t> fill(tet_start.begin(), tet_start.end() - 1);
      for (std::size_t i = 0; i < 4 * m; ++i) tets[fill[std::size_t(s[i])]++] = std::uint32_t(i / 4);
    }
    const int team = threads > 0 ? threads : omp_get_max_threads();
    std::vector<std::uint32_t> degree(npoints, 0);
    // Two passes (count, then fill) over the same per-vertex gathering.
    auto gather = [&](std::size_t v, std::vector<I>& nbrs) {
      nbrs.clear();
      for (std::uint64_t k = tet_start[v]; k < tet_start[v + 1]; ++k) {
        const I* row = s + 4 * std::size_t(tets[k]);
        for (int j = 0; j < 4; ++j)
          if (std::size_t(row[j]) != v) nbrs.push_back(row[j]);
      }
      std::sort(nbrs.begin(), nbrs.end());
      nbrs.erase(std::unique(nbrs.begin(), nbrs.end()), nbrs.end());
    };
#pragma omp parallel num_threads(team)
    {
      std::vector<I> nbrs;
#pragma omp for schedule(dynamic, 4096)
      for (std::size_t v = 0; v < npoints; ++v) {
        gather(v, nbrs);
        degree[v] = std::uint32_t(nbrs.size());
      }
    }
    for (std::size_t v = 0; v < npoints; ++v) indptr[v + 1] = indptr[v] + O(degree[v]);
    indices.resize(std::size_t(indptr[npoints]));
#pragma omp parallel num_threads(team)
    {
      std::vector<I> nbrs;
#pragma omp for schedule(dynamic, 4096)
      for (std::size_t v = 0; v < npoints; ++v) {
        gather(v, nbrs);
        std::copy(nbrs.begin(), nbrs.end(), indices.begin() + std::ptrdiff_t(indptr[v]));
      }
    }
  }
  const py::ssize_t nnz = py::ssize_t(indices.size());
  return py::make_tuple(owned_array(std::move(indptr), {py::ssize_t(npoints + 1)}),
                        owned_array(std::move(indices), {nnz}));
}

template <class I>
py::tuple vertex_neighbors_i(const py::array& simplices, std::size_t npoints, int threads) {
  std::size_t m = 0;
  const I* s = checked_rows<I>(simplices, 4, "simplices", m);
  for (std::size_t i = 0; i < 4 * m; ++i)
    if (s[i] < 0 || std::size_t(s[i]) >= npoints) throw UsageError("simplices: an index out of range");
  // Each tet gives each of its vertices 3 neighbours: 12 m bounds the entries.
  if (12 * m < std::size_t(std::numeric_limits<std::int32_t>::max()) &&
      npoints < std::size_t(std::numeric_limits<std::int32_t>::max()))
    return vertex_neighbors_t<I, std::int32_t>(s, m, npoints, threads);
  return vertex_neighbors_t<I, std::int64_t>(s, m, npoints, threads);
}

py::tuple vertex_neighbor_vertices(py::array simplices, std::size_t npoints, int threads) {
  if (is_int32(simplices)) return vertex_neighbors_i<std::int32_t>(simplices, npoints, threads);
  if (is_int64(simplices)) return vertex_neighbors_i<std::int64_t>(simplices, npoints, threads);
  throw UsageError("simplices must be int32 or int64");
}

}  // namespace

void register_geometry(py::module_& m) {
  m.def("find_simplex", &find_simplex, py::arg("points"), py::arg("simplices"), py::arg("neighbors"),
        py::arg("vertex_to_simplex"), py::arg("xi"), py::arg("threads") = 0,
        "The simplex holding each row of xi (-1 outside the hull), exactly; int32.");
  m.def("vertex_to_simplex", &vertex_to_simplex, py::arg("simplices"), py::arg("npoints"),
        "One simplex of each point, -1 for a point that is no vertex.");
  m.def("vertex_neighbor_vertices", &vertex_neighbor_vertices, py::arg("simplices"), py::arg("npoints"),
        py::arg("threads") = 0, "(indptr, indices): each vertex's Delaunay neighbours, sorted.");
}

}  // namespace tetstream::python
