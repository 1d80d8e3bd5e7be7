"""Triangulation's scipy.spatial.Delaunay API against SciPy itself (docs/python.md), with pytest.

Usage: PYTHONPATH=BUILD/python python3 -m pytest tests/python/test_scipy_parity.py
(CTest: py_test_scipy_parity, label `python`).

On uniform and clustered points (general position: both triangulations are the same
simplex set) every query is compared with SciPy's answer: find_simplex (the simplex's
vertex set; -1 together), transform (barycentric weights by vertex), vertex_neighbor_vertices,
vertex_to_simplex, plane_distance's signs, the bounds. On a grid (degenerate: the two
pick different, equally valid simplices) each answer is checked for what it claims:
the simplex found holds the point, -1 exactly when SciPy says outside.
"""
import os
import sys

import numpy as np
import pytest

try:
    import tetstream
except ImportError:  # not installed and no PYTHONPATH: the module of the default build tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "build", "python"))
    import tetstream

spatial = pytest.importorskip("scipy.spatial")


def uniform(n, seed):
    return np.random.default_rng(seed).random((n, 3))


def clustered(n, seed):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0.1, 0.9, (8, 3))
    sigma = np.exp(rng.uniform(np.log(0.003), np.log(0.08), 8))
    which = rng.integers(0, 8, n)
    return centres[which] + rng.normal(size=(n, 3)) * sigma[which, None]


def grid(k):
    i = np.arange(k) / k
    return np.stack(np.meshgrid(i, i, i, indexing="ij"), axis=-1).reshape(-1, 3)


def keys(simplices):
    """Each simplex as a hashable sorted vertex tuple."""
    return [tuple(r) for r in np.sort(np.asarray(simplices, dtype=np.int64), axis=1)]


def queries(points, n, seed):
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = 0.1 * (hi - lo)
    return np.random.default_rng(seed).uniform(lo - pad, hi + pad, (n, 3))


def barycentric(transform, s, x):
    t = transform[s]
    c = np.einsum("ijk,ik->ij", t[:, :3, :], x - t[:, 3, :])
    return np.concatenate([c, 1 - c.sum(axis=1, keepdims=True)], axis=1)


@pytest.fixture(scope="module", params=["uniform", "clustered"])
def general(request):
    pts = uniform(3000, 1) if request.param == "uniform" else clustered(3000, 2)
    ours, theirs = tetstream.delaunay(pts), spatial.Delaunay(pts)
    assert sorted(keys(ours.simplices)) == sorted(keys(theirs.simplices)), "not the same triangulation"
    return pts, ours, theirs


def test_attributes(general):
    pts, ours, theirs = general
    assert ours.ndim == theirs.ndim == 3
    assert ours.npoints == theirs.npoints and ours.nsimplex == theirs.nsimplex
    assert np.array_equal(ours.min_bound, theirs.min_bound) and np.array_equal(ours.max_bound, theirs.max_bound)
    assert np.array_equal(ours.points, theirs.points)
    assert ours.coplanar.shape == theirs.coplanar.shape == (0, 3)


def test_find_simplex(general):
    pts, ours, theirs = general
    xi = np.vstack([queries(pts, 20000, 3), pts[:500] * 0.5 + pts[500:1000] * 0.5])
    a, b = ours.find_simplex(xi), theirs.find_simplex(xi)
    assert a.dtype == b.dtype and a.shape == b.shape
    assert np.array_equal(a < 0, b < 0), f"{(np.sign(a) != np.sign(b)).sum()} disagree on inside/outside"
    inside = a >= 0
    assert inside.sum() > 1000 and (~inside).sum() > 1000
    ka, kb = np.sort(ours.simplices[a[inside]], axis=1), np.sort(theirs.simplices[b[inside]], axis=1)
    # The same simplex, but for a query on a facet or edge the two share (a midpoint of a
    # Delaunay edge): then both simplices hold it
    differ = np.nonzero((ka != kb).any(axis=1))[0]
    assert len(differ) <= 10
    x = xi[inside][differ]
    assert (barycentric(ours.transform, a[inside][differ], x) >= -1e-12).all()
    assert (barycentric(theirs.transform, b[inside][differ], x) >= -1e-12).all()
    assert (np.abs(barycentric(ours.transform, a[inside][differ], x)).min(axis=1) < 1e-12).all()
    # shapes: xi (..., 3) -> (...)
    assert ours.find_simplex(xi[:35].reshape(5, 7, 3)).shape == (5, 7)
    assert ours.find_simplex(xi[0]).shape == ()
    assert ours.find_simplex(xi, bruteforce=True, tol=1e-12).tolist() == a.tolist()
    # a vertex lies in a simplex that has it; a non-finite query is outside
    v = ours.find_simplex(pts)
    assert (v >= 0).all()
    assert np.array_equal(ours.find_simplex(np.array([[np.nan, 0, 0], [0.5, np.inf, 0.5]])), [-1, -1])


def test_transform(general):
    pts, ours, theirs = general
    assert ours.transform.shape == theirs.transform.shape == (ours.nsimplex, 4, 3)
    xi = queries(pts, 5000, 4)
    a = ours.find_simplex(xi)
    inside = a >= 0
    x = xi[inside]
    wa = barycentric(ours.transform, a[inside], x)
    # the coordinates reproduce the point and are in [0, 1]
    back = np.einsum("ij,ijk->ik", wa, ours.points[ours.simplices[a[inside]]])
    assert np.allclose(back, x, atol=1e-12)
    assert (wa >= -1e-12).all()
    # SciPy's weights of the same simplex, vertex by vertex
    b = theirs.find_simplex(x)
    wb = barycentric(theirs.transform, b, x)
    for i in range(0, len(x), 97):
        da = dict(zip(ours.simplices[a[inside][i]].tolist(), wa[i]))
        db = dict(zip(theirs.simplices[b[i]].tolist(), wb[i]))
        assert da.keys() == db.keys()
        assert all(abs(da[k] - db[k]) < 1e-9 for k in da)


def test_vertex_neighbor_vertices_and_vertex_to_simplex(general):
    pts, ours, theirs = general
    ia, ja = ours.vertex_neighbor_vertices
    ib, jb = theirs.vertex_neighbor_vertices
    assert ia.dtype == ib.dtype and ja.dtype == jb.dtype
    assert np.array_equal(ia, ib)
    for k in range(ours.npoints):
        row = ja[ia[k]:ia[k + 1]]
        assert np.array_equal(row, np.sort(jb[ib[k]:ib[k + 1]]))
        assert (np.diff(row) > 0).all()
    v2s = ours.vertex_to_simplex
    assert v2s.dtype == theirs.vertex_to_simplex.dtype and v2s.shape == (ours.npoints,)
    assert (ours.simplices[v2s] == np.arange(ours.npoints)[:, None]).any(axis=1).all()


def test_equations_and_plane_distance(general):
    pts, ours, theirs = general
    assert ours.equations.shape == theirs.equations.shape == (ours.nsimplex, 5)
    assert np.allclose(np.linalg.norm(ours.equations[:, :4], axis=1), 1) and (ours.equations[:, 3] < 0).all()
    order = {k: i for i, k in enumerate(keys(theirs.simplices))}
    match = np.array([order[k] for k in keys(ours.simplices)])
    for x in queries(pts, 5, 5):
        da, db = ours.plane_distance(x), theirs.plane_distance(x)[match]
        clear = np.abs(db) > 1e-9
        assert np.array_equal(np.sign(da[clear]), np.sign(db[clear]))
        assert clear.sum() > 0.99 * len(clear)
    lifted = ours.lift_points(pts[:10])
    assert np.allclose(lifted[:, 3], (pts[:10] ** 2).sum(axis=1))


def test_duplicates_are_coplanar_rows():
    p = uniform(500, 6)
    q = np.vstack([p, p[:20]])
    ours, theirs = tetstream.delaunay(q), spatial.Delaunay(q)
    c = ours.coplanar
    assert c.dtype == theirs.coplanar.dtype and c.shape == theirs.coplanar.shape == (20, 3)
    assert np.array_equal(c[:, 0], np.arange(500, 520)) and np.array_equal(c[:, 2], np.arange(20))
    assert (ours.simplices[c[:, 1]] == c[:, 2:3]).any(axis=1).all()
    assert np.array_equal(ours.vertex_to_simplex[500:], [-1] * 20)
    ia, ja = ours.vertex_neighbor_vertices
    assert (np.diff(ia)[500:] == 0).all()


def test_degenerate_grid():
    pts = grid(9)
    ours, theirs = tetstream.delaunay(pts), spatial.Delaunay(pts)
    assert ours.nsimplex > 0 and abs(ours.volumes().sum() - (8 / 9) ** 3) < 1e-12
    # queries: random, the grid points, the midpoints of grid edges and faces (on facets)
    h = 1 / 9
    xi = np.vstack([queries(pts, 5000, 7), pts, pts[:300] + [h / 2, 0, 0], pts[:300] + [h / 2, h / 2, 0],
                    pts[:300] + [h / 2, h / 2, h / 2]])
    a, b = ours.find_simplex(xi), theirs.find_simplex(xi)
    assert np.array_equal(a < 0, b < 0)
    inside = a >= 0
    w = barycentric(ours.transform, a[inside], xi[inside])
    assert (w >= -1e-12).all(), "find_simplex returned a simplex that does not hold the point"
    ia, ja = ours.vertex_neighbor_vertices
    assert len(ia) == len(pts) + 1 and (np.diff(ia) >= 3).all()
    v2s = ours.vertex_to_simplex
    assert (ours.simplices[v2s] == np.arange(len(pts))[:, None]).any(axis=1).all()


def test_int32_triangulation():
    pts = uniform(2000, 8)
    a, b = tetstream.delaunay(pts, dtype=np.int32), tetstream.delaunay(pts)
    xi = queries(pts, 3000, 9)
    assert np.array_equal(a.find_simplex(xi), b.find_simplex(xi))
    assert np.array_equal(a.vertex_neighbor_vertices[1], b.vertex_neighbor_vertices[1])


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-p", "no:cacheprovider"]))
