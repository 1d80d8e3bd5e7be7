"""tetstream.field() (docs/python.md) against `tetstream field` (the CLI), with pytest.

Usage: PYTHONPATH=BUILD/python TETSTREAM_BINARY=BUILD/tools/tetstream python3 -m pytest
tests/python/test_field_module.py   (CTest: py_test_field_module, label `python`).

Over a container, field() runs the CLI's own code: every array equals the CLI's .npy
file bit for bit, and the neighbour matrix its CSR arrays. Over an in-memory
Triangulation of the same points the sums are the same per-tet terms added in another
order: equal to rounding (1e-12 relative), the neighbour sets exactly.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

try:
    import tetstream
except ImportError:  # not installed and no PYTHONPATH: the module of the default build tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "build", "python"))
    import tetstream

sparse = pytest.importorskip("scipy.sparse")
BINARY = os.environ.get("TETSTREAM_BINARY") or os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                                             "build", "tools", "tetstream")


def clustered(n, seed):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0.2, 0.8, (6, 3))
    sigma = np.exp(rng.uniform(np.log(0.01), np.log(0.1), 6))
    which = rng.integers(0, 6, n)
    return centres[which] + rng.normal(size=(n, 3)) * sigma[which, None]


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    d = tmp_path_factory.mktemp("field")
    pts = clustered(20000, 3)
    pts.tofile(d / "c.f64")
    subprocess.run([BINARY, "-q", "run", str(d / "c.f64"), "-o", str(d / "c.tets"), "--no-checkpoint"], check=True)
    mass = np.random.default_rng(4).uniform(0.5, 2.0, len(pts))
    np.save(d / "m.npy", mass)
    for hull in ("nan", "open"):
        subprocess.run([BINARY, "-q", "field", str(d / "c.tets"), "-o", str(d / hull), "--density", "dtfe",
                        "--voronoi-volume", "--neighbours", "--grid", "12,10,8", "--hull", hull,
                        "--mass", str(d / "m.npy")], check=True, stdout=subprocess.DEVNULL)
    return d, pts, mass


@pytest.mark.parametrize("hull", ["nan", "open"])
def test_container_equals_cli(job, hull):
    d, pts, mass = job
    r = tetstream.field(str(d / "c.tets"), density=True, voronoi_volume=True, neighbours=True, grid=(12, 10, 8),
                        hull=hull, mass=mass, memory="256M")
    for key, name in (("density", "density"), ("voronoi_volume", "voronoi"), ("grid", "grid")):
        cli = np.load(d / f"{hull}.{name}.npy")
        assert r[key].dtype == cli.dtype and r[key].shape == cli.shape
        assert np.array_equal(r[key], cli, equal_nan=True), key
    nb = r["neighbours"]
    assert isinstance(nb, sparse.csr_matrix) and nb.shape == (len(pts), len(pts))
    assert np.array_equal(nb.indptr, np.load(d / f"{hull}.neighbours.offsets.npy"))
    assert np.array_equal(nb.indices, np.load(d / f"{hull}.neighbours.indices.npy"))
    assert (nb != nb.T).nnz == 0
    assert np.array_equal(r["original_ids"], np.arange(len(pts)))
    s = r["summary"]
    assert s["points"] == len(pts) and s["tets"] > 6 * len(pts) and s["grid_points"] == 960
    # a mass file by its path gives the same
    r2 = tetstream.field(str(d / "c.tets"), hull=hull, mass=str(d / "m.npy"))
    assert np.array_equal(r2["density"], r["density"], equal_nan=True) and set(r2) == {"density", "original_ids",
                                                                                       "summary"}


@pytest.mark.parametrize("hull", ["nan", "open"])
def test_memory_equals_container(job, hull):
    d, pts, mass = job
    tri = tetstream.delaunay(pts)
    m = tetstream.field(tri, voronoi_volume=True, neighbours=True, grid=(12, 10, 8), hull=hull, mass=mass)
    for key, name in (("density", "density"), ("voronoi_volume", "voronoi"), ("grid", "grid")):
        cli = np.load(d / f"{hull}.{name}.npy")
        assert np.array_equal(np.isnan(m[key]), np.isnan(cli)), key
        assert np.array_equal(np.isinf(m[key]), np.isinf(cli)), key
        ok = np.isfinite(cli)
        assert np.allclose(m[key][ok], cli[ok], rtol=1e-10, atol=0), key
    cli_nb = sparse.csr_matrix((np.ones(len(np.load(d / f"{hull}.neighbours.indices.npy")), dtype=np.int8),
                                np.load(d / f"{hull}.neighbours.indices.npy"),
                                np.load(d / f"{hull}.neighbours.offsets.npy")), shape=(len(pts), len(pts)))
    assert (m["neighbours"] != cli_nb).nnz == 0
    assert m["summary"]["hull_points"] == int(np.isinf(m["voronoi_volume"]).sum())


def test_memory_duplicates_and_float32():
    p = clustered(3000, 5)
    q = np.vstack([p, p[:10]])
    tri = tetstream.delaunay(q)
    r = tetstream.field(tri, voronoi_volume=True, neighbours=True, dtype=np.float32, hull="open")
    assert r["density"].dtype == np.float32 and r["density"].shape == (len(q),)
    assert np.isnan(r["density"][3000:]).all() and np.isfinite(r["density"][:3000]).all()
    assert r["neighbours"][3000:].nnz == 0
    # DTFE conserves mass under --hull open: the linear field integrates to the total mass
    d = r["density"].astype(np.float64)[:3000]
    vol = tri.volumes()
    integral = (vol * d[tri.simplices].mean(axis=1)).sum()
    assert abs(integral - 3000) < 1e-6 * 3000


def test_errors(job):
    d, pts, _ = job
    with pytest.raises(tetstream.UsageError):
        tetstream.field(str(d / "c.tets"), density=False)
    with pytest.raises(tetstream.UsageError):
        tetstream.field(str(d / "c.tets"), hull="closed")
    with pytest.raises(tetstream.UsageError):
        tetstream.field(str(d / "c.tets"), grid=(4, 0, 4))
    with pytest.raises(tetstream.IoError):
        tetstream.field(str(d / "missing.tets"))
    with pytest.raises(tetstream.InputError):
        tetstream.field(tetstream.delaunay(pts[:100]), mass=np.ones(99))


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-p", "no:cacheprovider"]))
