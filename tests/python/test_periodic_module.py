"""tetstream.delaunay(points, periodic=L) and run(..., periodic=L) (docs/periodic.md), with pytest.

Usage: PYTHONPATH=BUILD/python python3 -m pytest tests/python/test_periodic_module.py
(CTest: py_test_periodic_module, label `python`).

The periodic triangulation of the unit box: its volumes sum to the box's, every point
is a vertex, every simplex positively oriented as placed by its offsets, and run() to a
container gives the same simplices.
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


def dyadic(n, seed):
    rng = np.random.default_rng(seed)
    return np.floor(rng.random((n, 3)) * 2.0**30) / 2.0**30


def test_delaunay_periodic_tiles_the_box():
    pts = dyadic(3000, 1)
    tri = tetstream.delaunay(pts, periodic=1.0)
    assert isinstance(tri, tetstream.PeriodicTriangulation)
    vol = tri.volumes()
    assert (vol > 0).all()
    assert abs(vol.sum() - 1.0) < 1e-12
    assert np.array_equal(np.unique(tri.simplices), np.arange(3000))
    assert tri.offsets.dtype == np.int8 and set(np.unique(tri.offsets)) <= {-1, 0, 1}


def test_run_periodic_same_as_delaunay(tmp_path):
    pts = dyadic(2000, 2)
    out = str(tmp_path / "p.tets")
    s = tetstream.run(pts, out, memory="256M", progress=False, checkpoint=False, periodic=(1.0, 1.0, 1.0))
    assert s["periodic"]["points"] == 2000
    a = tetstream._core.periodic_tets(out)
    b = tetstream.delaunay(pts, periodic=1.0)
    assert np.array_equal(a["simplices"], b.simplices) and np.array_equal(a["offsets"], b.offsets)


def test_points_outside_refused_on_request(tmp_path):
    pts = dyadic(2000, 3)
    pts[0, 0] = 1.5
    with pytest.raises(tetstream.InputError, match="outside"):
        tetstream.run(pts, str(tmp_path / "r.tets"), progress=False, checkpoint=False, periodic=1.0,
                      periodic_outside="refuse")


def test_periodic_auto_reads_the_snapshots_box(tmp_path):
    # A Gadget-like snapshot: float32 coordinates in [0, 50), Header/BoxSize = 50.
    h5py = pytest.importorskip("h5py")
    rng = np.random.default_rng(4)
    pts = (rng.random((3000, 3)) * 50).astype(np.float32)
    snap = str(tmp_path / "snap.hdf5")
    with h5py.File(snap, "w") as f:
        f.create_group("Header").attrs["BoxSize"] = 50.0
        f.create_dataset("PartType1/Coordinates", data=pts)
    out = str(tmp_path / "snap.tets")
    s = tetstream.run(snap, out, progress=False, checkpoint=False, periodic="auto",
                      datasets=["/PartType1/Coordinates"])
    assert s["periodic"]["period"] == [50.0, 50.0, 50.0]
    d = tetstream._core.periodic_tets(out)
    v = pts.astype(np.float64)[d["simplices"]] + d["offsets"] * 50.0
    assert abs(np.linalg.det(v[:, 1:] - v[:, :1]).sum() / 6 - 50.0**3) < 1e-6 * 50.0**3


def test_tetfile_reads_a_periodic_container(tmp_path):
    # TetFile's frames and frame_offsets give the tets run() wrote, each whole when
    # its vertices stand at points + offsets * period: positive volumes summing to the box.
    pts = dyadic(2000, 3)
    out = str(tmp_path / "p.tets")
    tetstream.run(pts, out, memory="256M", progress=False, checkpoint=False, periodic=1.0)
    plain = str(tmp_path / "plain.tets")
    tetstream.run(pts, plain, memory="256M", progress=False, checkpoint=False)
    with tetstream.open(plain) as f:
        assert f.periodic is None
        with pytest.raises(Exception, match="not a periodic container"):
            f.frame_offsets(0)
    with tetstream.open(out) as f:
        assert f.periodic == (1.0, 1.0, 1.0)
        tets = np.concatenate(list(f.frames()))
        offsets = np.concatenate([f.frame_offsets(k) for k in range(f.n_frames)])
        assert tets.shape == (f.n_tets, 4) and offsets.shape == (f.n_tets, 4, 3)
        assert not offsets[:, 0].any() and offsets[:, 1:].any()
        x = f.points[tets] + offsets * 1.0
        vol = np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0])) / 6
        assert (vol > 0).all() and abs(vol.sum() - 1.0) < 1e-12
        a = tetstream._core.periodic_tets(out)
        ids = f.original_ids
        assert np.array_equal(ids[tets], a["simplices"]) and np.array_equal(offsets, a["offsets"])
