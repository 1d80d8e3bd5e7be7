"""The Python package `tetstream` (python/, docs/python.md), with pytest.

Usage: python3 -m pytest tests/python/test_tetstream_module.py   (with the module importable:
       PYTHONPATH=BUILD/python), or python3 test_tetstream_module.py [/path/to/tetstream].
CTest runs it so (tests/CMakeLists.txt, label `python`).

delaunay() against scipy.spatial.Delaunay (Qhull, an independent implementation) on points
in general position: the same simplex set, the same hull; on degenerate inputs (a grid,
duplicates), a valid triangulation of the hull (positive volumes, every point a vertex or
a reported duplicate, total volume = ConvexHull's volume). run() + open() on 10^5 points in
several segments against delaunay(); verify(); the exceptions; no copies on the way out.
"""
import os
import signal
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest

try:
    import tetstream
except ImportError:  # not installed and no PYTHONPATH: the module of the default build tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "build", "python"))
    import tetstream

scipy_spatial = pytest.importorskip("scipy.spatial")


# ---- helpers -----------------------------------------------------------------------------

def simplex_set(simplices):
    """The simplices as a sorted array of rows with sorted vertices (a canonical set)."""
    s = np.sort(np.asarray(simplices, dtype=np.int64), axis=1)
    return s[np.lexsort(s.T[::-1])]


def signed_volumes(points, simplices):
    p = points[simplices]
    a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0


def check_valid(points, tri):
    """Positive volumes, coverage, volume = hull volume, neighbours and hull consistent."""
    n = len(points)
    s = tri.simplices
    vol = signed_volumes(points, s)
    assert (vol > 0).all(), f"{(vol <= 0).sum()} simplices not positively oriented"
    vertices = np.zeros(n, bool)
    vertices[s.ravel()] = True
    dup = tri.duplicates
    assert not vertices[dup[:, 0]].any(), "a reported duplicate is also a vertex"
    assert vertices[dup[:, 1]].all(), "a duplicate merged into a point that is not a vertex"
    assert (points[dup[:, 0]] == points[dup[:, 1]]).all(), "a duplicate with other coordinates"
    covered = vertices.copy()
    covered[dup[:, 0]] = True
    assert covered.all(), f"{(~covered).sum()} input points are neither vertices nor duplicates"
    hull_volume = scipy_spatial.ConvexHull(points).volume
    assert abs(vol.sum() - hull_volume) <= 1e-9 * hull_volume
    # neighbors[i, j]: the simplex across the facet opposite vertex j, which shares it
    nb = tri.neighbors
    i, j = np.nonzero(nb >= 0)
    facet = facet_without(s[i], j)
    other = s[nb[i, j]]
    shares = (facet[:, :, None] == other[:, None, :]).any(axis=2).all(axis=1)
    assert shares.all()
    # hull facets: one per -1, outward (their points' centroid side is away from the tet)
    assert len(tri.convex_hull) == (nb == -1).sum()
    h = points[tri.convex_hull]
    normal = np.cross(h[:, 1] - h[:, 0], h[:, 2] - h[:, 0])
    centre = points.mean(axis=0)
    assert (np.einsum("ij,ij->i", normal, h[:, 0] - centre) > 0).all()


def facet_without(s, j):
    keep = np.ones(s.shape, bool)
    keep[np.arange(len(s)), j] = False
    return s[keep].reshape(len(s), 3)


def uniform(n, seed):
    return np.random.default_rng(seed).random((n, 3))


# ---- in memory -----------------------------------------------------------------------

def test_same_simplices_as_scipy():
    pts = uniform(3000, 1)
    tri = tetstream.delaunay(pts)
    ref = scipy_spatial.Delaunay(pts)
    assert np.array_equal(simplex_set(tri.simplices), simplex_set(ref.simplices))
    hull = np.sort(tri.convex_hull, axis=1)
    ref_hull = np.sort(ref.convex_hull, axis=1)
    assert np.array_equal(hull[np.lexsort(hull.T[::-1])], ref_hull[np.lexsort(ref_hull.T[::-1])])
    check_valid(pts, tri)
    assert len(tri.duplicates) == 0 and tri.duplicates.shape == (0, 2)


def test_float32_and_int32():
    pts = uniform(2000, 2).astype(np.float32)
    tri = tetstream.delaunay(pts, dtype=np.int32)
    assert tri.simplices.dtype == np.int32 and tri.neighbors.dtype == np.int32
    assert tri.points.dtype == np.float64 and np.array_equal(tri.points, pts.astype(np.float64))
    ref = scipy_spatial.Delaunay(pts.astype(np.float64))
    assert np.array_equal(simplex_set(tri.simplices), simplex_set(ref.simplices))


def test_grid_is_valid():
    g = np.arange(20, dtype=np.float64)
    pts = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    tri = tetstream.delaunay(pts)
    check_valid(pts, tri)
    assert len(tri.duplicates) == 0


def test_duplicates_are_reported():
    rng = np.random.default_rng(3)
    base = rng.random((3000, 3))
    pts = np.concatenate([base, base[rng.integers(0, 3000, 700)], base[:5], base[:5]])
    order = rng.permutation(len(pts))
    pts = pts[order]
    tri = tetstream.delaunay(pts)
    check_valid(pts, tri)
    assert len(tri.duplicates) == len(pts) - len(np.unique(pts, axis=0))
    assert np.all(np.diff(tri.duplicates[:, 0]) > 0)


def test_zero_copy():
    pts = uniform(1000, 4)
    tri = tetstream.delaunay(pts)
    assert tri.points is pts or np.shares_memory(tri.points, pts)
    for a in (tri.simplices, tri.neighbors, tri.convex_hull, tri.duplicates):
        assert not a.flags.owndata and type(a.base).__name__ == "PyCapsule"
        assert a.flags.c_contiguous
    assert not np.shares_memory(tri.simplices, tri.neighbors)


def test_delaunay_errors():
    with pytest.raises(ValueError):
        tetstream.delaunay(np.zeros((10, 2)))
    with pytest.raises(ValueError):
        tetstream.delaunay(uniform(3, 5))  # too few points
    with pytest.raises(ValueError):
        tetstream.delaunay(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 2, 0.0]]))  # coplanar
    bad = uniform(100, 6)
    bad[17, 1] = np.nan
    with pytest.raises(tetstream.InputError, match="row 17"):
        tetstream.delaunay(bad)
    with pytest.raises(ValueError):
        tetstream.delaunay(uniform(100, 6), dtype=np.float32)
    with pytest.raises(ValueError):
        tetstream.delaunay(uniform(100, 6), threads=0)


def test_help_reads_well():
    doc = tetstream.delaunay.__doc__
    for word in ("Parameters", "Returns", "Raises", "neighbors", "positively oriented"):
        assert word in doc
    assert "Triangulation" in repr(tetstream.delaunay.__annotations__.get("return"))


# ---- out of core -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def big_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("run")
    pts = uniform(100_000, 7)
    out = str(d / "p.tets")
    # 110M: a little above the least budget run() accepts for 10^5 points (106M), which
    # plans several segments (7 on 2 threads)
    summary = tetstream.run(pts, out, memory="110M", threads=2, progress=False)
    return pts, out, summary


def test_run_summary(big_run):
    pts, out, s = big_run
    assert s["command"] == "run" and s["points"] == len(pts) and s["input_points"] == len(pts)
    assert s["segments"] > 1
    assert s["tets"] > 6 * len(pts)
    assert os.path.exists(out)
    assert not os.path.exists(out + ".input.f64"), "the spilled array is removed after a successful job"


def test_run_matches_delaunay(big_run):
    pts, out, s = big_run
    tri = tetstream.delaunay(pts)
    with tetstream.open(out) as f:
        assert f.n_points == len(pts) and f.n_tets == s["tets"] == len(tri.simplices)
        tets = f.tets(0, f.n_tets, original_ids=True)
        assert np.array_equal(simplex_set(tets), simplex_set(tri.simplices))
        # labels index f.points; original_ids maps them to the input
        assert np.array_equal(f.points, pts[f.original_ids])
        labels = np.concatenate(list(f.frames()))
        assert np.array_equal(f.original_ids[labels], tets)
        assert (signed_volumes(f.points, labels) > 0).all()
        # random access through the frame index, across frame boundaries
        index = f.frame_index()
        assert len(index["first_tet"]) == f.n_frames > 1
        for a, b in [(0, 10), (int(index["first_tet"][1]) - 3, int(index["first_tet"][1]) + 5),
                     (f.n_tets - 7, f.n_tets), (12345, 54321)]:
            assert np.array_equal(f.tets(a, b), labels[a:b])
        assert np.array_equal(f[-5:], labels[-5:])
        narrow = np.concatenate(list(f.frames(dtype=np.uint32)))
        assert narrow.dtype == np.uint32 and np.array_equal(narrow, labels)
        frame = f.frame(0)
        assert not frame.flags.owndata and type(frame.base).__name__ == "PyCapsule"


def test_verify(big_run):
    _, out, s = big_run
    report = tetstream.verify(out, threads=2)
    assert report["valid"] and report["tets"] == s["tets"] and report["violations"] == 0


def test_to_meshio(big_run):
    pytest.importorskip("meshio")
    _, out, s = big_run
    with tetstream.open(out) as f:
        mesh = f.to_meshio()
        assert mesh.points.shape == (f.n_points, 3)
        assert mesh.cells[0].type == "tetra" and len(mesh.cells[0].data) == s["tets"]


def test_run_from_file_and_options(tmp_path):
    pts = uniform(5000, 8).astype(np.float32)
    src = tmp_path / "in.f32"
    pts.tofile(src)
    s = tetstream.run(src, tmp_path / "a.tets", memory="128M", progress=False, checkpoint=False)
    assert s["points"] == 5000 and s["segments"] >= 1
    # float32 input keeps its precision in the container (coord_type 1), exactly.
    with tetstream.open(tmp_path / "a.tets") as f:
        assert f.header["coord_type"] == "float32"
        assert (f.points[np.argsort(f.original_ids)] == pts.astype(np.float64)).all()
    np.save(tmp_path / "in.npy", pts.astype(np.float64))
    s2 = tetstream.run(str(tmp_path / "in.npy"), str(tmp_path / "b.tets"), memory=256 << 20, progress=False,
                       format="npy")
    assert s2["tets"] == s["tets"]


def test_run_errors(tmp_path):
    pts = uniform(1000, 9)
    with pytest.raises(ValueError):  # UsageError: budget too small
        tetstream.run(pts, tmp_path / "x.tets", memory="1M", progress=False)
    with pytest.raises(TypeError):
        tetstream.run(pts, tmp_path / "y.tets", progress=False, no_such_option=3)
    with pytest.raises(OSError):  # IoError: no such file
        tetstream.run(tmp_path / "missing.f64", tmp_path / "z.tets", progress=False)
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2 3\n4 5 six\n")
    with pytest.raises(tetstream.InputError):
        tetstream.run(bad, tmp_path / "w.tets", progress=False, checkpoint=False)
    with pytest.raises(OSError):
        tetstream.open(tmp_path / "missing.tets")
    with pytest.raises(ValueError):
        tetstream.open(bad)
    assert issubclass(tetstream.IoError, OSError) and issubclass(tetstream.UsageError, ValueError)


def test_damaged_container_fails_verification(big_run, tmp_path):
    _, out, _ = big_run
    data = bytearray(open(out, "rb").read())
    data[len(data) // 2] ^= 0x40  # inside a frame: its checksum fails
    damaged = tmp_path / "damaged.tets"
    damaged.write_bytes(bytes(data))
    with pytest.raises(ValueError):
        tetstream.verify(damaged)


def test_io_failure_then_resume(tmp_path):
    """A failing job (fault injection: IoError) raises OSError, keeps its checkpoint and
    the spilled array; resume=True with the same array finishes it."""
    pts = uniform(40_000, 10)
    np.save(tmp_path / "pts.npy", pts)
    out = str(tmp_path / "r.tets")
    script = textwrap.dedent(f"""
        import numpy as np, tetstream
        pts = np.load({str(tmp_path / 'pts.npy')!r})
        try:
            tetstream.run(pts, {out!r}, memory="64M", progress=False, zone_points=10000)
        except OSError as e:
            print("OSError:", type(e).__name__)
    """)
    package_dir = os.path.dirname(os.path.dirname(os.path.abspath(tetstream.__file__)))
    env = dict(os.environ, TETSTREAM_FAULT="write:1",
               PYTHONPATH=os.pathsep.join([package_dir] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    r = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert "OSError: IoError" in r.stdout, r.stdout + r.stderr
    assert os.path.exists(out + ".input.f64") and os.path.isdir(out + ".ckpt")
    assert not os.path.exists(out)
    with pytest.raises(ValueError, match="resume"):  # a checkpoint exists: refused without resume
        tetstream.run(pts, out, memory="64M", progress=False, zone_points=10000)
    other = pts.copy()
    other[123, 0] += 1e-6
    with pytest.raises(ValueError, match="other points"):  # another array cannot resume it
        tetstream.run(other, out, memory="64M", progress=False, zone_points=10000, resume=True)
    s = tetstream.run(pts, out, memory="64M", progress=False, zone_points=10000, resume=True)
    assert s["resumed"] and s["points"] == len(pts)
    assert not os.path.exists(out + ".input.f64") and not os.path.exists(out + ".ckpt")
    assert tetstream.verify(out)["valid"]


def test_ctrl_c_raises_keyboard_interrupt(tmp_path):
    """SIGINT during run(): KeyboardInterrupt once the job has stopped, no output under its
    final name, the checkpoint kept."""
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signals reach the main thread only")
    pts = uniform(300_000, 11)
    out = str(tmp_path / "i.tets")
    done = threading.Event()

    def interrupt():  # once the job has made its checkpoint, and a little later
        while not done.is_set() and not os.path.isdir(out + ".ckpt"):
            done.wait(0.01)
        if not done.wait(0.2):
            os.kill(os.getpid(), signal.SIGINT)

    sender = threading.Thread(target=interrupt)
    sender.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            tetstream.run(pts, out, memory="64M", progress=False, zone_points=20000)
    finally:
        done.set()
        sender.join()
    assert not os.path.exists(out)
    assert os.path.isdir(out + ".ckpt")


# ---- issue 41: what new users met -------------------------------------------------------

def test_duplicates_keep_the_first_copy(tmp_path):
    """Of several copies of a point, the first in the input is the vertex, as in run()."""
    p = uniform(300, 21)
    q = np.vstack([p, p[:60], p[:60]])  # points 0..59 three times each
    tri = tetstream.delaunay(q)
    expected = np.array([[300 + i, i] for i in range(60)] + [[360 + i, i] for i in range(60)])
    assert np.array_equal(tri.duplicates, expected)
    assert set(np.unique(tri.simplices)) == set(range(300))
    check_valid(q, tri)
    out = str(tmp_path / "d.tets")
    tetstream.run(q, out, memory="64M", progress=False)
    with tetstream.open(out) as f:
        assert np.array_equal(np.sort(f.original_ids), np.arange(300))
        assert np.array_equal(simplex_set(f.tets(0, f.n_tets, original_ids=True)), simplex_set(tri.simplices))


def test_run_expands_a_glob_like_the_cli(tmp_path):
    parts = [uniform(700, 30 + k) for k in range(3)]
    for name, part in zip(("snap.2.f64", "snap.10.f64", "snap.1.f64"), (parts[1], parts[2], parts[0])):
        part.tofile(tmp_path / name)
    s = tetstream.run(str(tmp_path / "snap.*.f64"), str(tmp_path / "g.tets"), memory="64M", progress=False)
    assert s["points"] == 2100
    with tetstream.open(tmp_path / "g.tets") as f:
        # natural order: snap.1, snap.2, snap.10 (input indices follow it)
        assert np.array_equal(f.points[np.argsort(f.original_ids)], np.vstack(parts))
    with pytest.raises(tetstream.IoError, match="no file matches"):
        tetstream.run(str(tmp_path / "none.*.f64"), str(tmp_path / "n.tets"), memory="64M", progress=False)


def test_tetfile_indexing_by_int(big_run):
    _, out, s = big_run
    with tetstream.open(out) as f:
        assert np.array_equal(f[5], f.tets(5, 6)[0]) and f[5].shape == (4,)
        assert np.array_equal(f[-1], f.tets(f.n_tets - 1, f.n_tets)[0])
        assert np.array_equal(f[np.int64(7)], f.tets(7, 8)[0])
        with pytest.raises(IndexError):
            f[f.n_tets]
        with pytest.raises(TypeError):
            f["a"]


def test_to_meshio_keeps_merged_duplicates_as_points(tmp_path):
    meshio = pytest.importorskip("meshio")
    p = uniform(400, 22)
    q = np.vstack([p[:100], p[:5], p[100:]])  # input rows 100..104 repeat rows 0..4
    src = tmp_path / "q.f64"
    q.tofile(src)
    out = str(tmp_path / "q.tets")
    tetstream.run(str(src), out, memory="64M", progress=False)
    with tetstream.open(out) as f:
        mesh = f.to_meshio(original_ids=True)  # the merged rows read back from q.f64
        assert mesh.points.shape == q.shape and np.isfinite(mesh.points).all()
        assert np.array_equal(mesh.points, q)
        assert np.array_equal(mesh.point_data["original_id"], np.arange(len(q)))
        tets = mesh.cells[0].data
        assert (signed_volumes(mesh.points, tets) > 0).all()
        assert not np.isin(np.arange(100, 105), tets).any()
        os.remove(src)  # the input gone: the array itself can be passed
        assert np.array_equal(f.to_meshio(original_ids=True, points=q).points, q)
        with pytest.raises(tetstream.UsageError, match="points="):
            f.to_meshio(original_ids=True)
        data = f.to_meshio(point_data={"x": f.points[:, 0]}).point_data
        assert np.array_equal(data["x"], f.points[:, 0]) and np.array_equal(data["original_id"], f.original_ids)
        mesh_path = str(tmp_path / "m.vtu")
        meshio.write(mesh_path, f.to_meshio(original_ids=True, points=q))
        assert np.isfinite(meshio.read(mesh_path).points).all()


def test_delaunay_stops_on_ctrl_c():
    """SIGINT during delaunay(): KeyboardInterrupt within a piece of the insertion, long
    before the triangulation would have finished."""
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signals reach the main thread only")
    import time
    pts = uniform(2_000_000, 23)
    sent = []

    def interrupt():
        time.sleep(0.5)
        sent.append(time.process_time())
        os.kill(os.getpid(), signal.SIGINT)

    sender = threading.Thread(target=interrupt)
    sender.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            tetstream.delaunay(pts)
    finally:
        sender.join()
    stopped = time.process_time()
    # 2e6 points take several CPU seconds; a piece (65536 insertions) a fraction of one.
    # Counted in the process's CPU time, not the wall clock's: on a loaded machine the
    # wall clock runs on while the process waits for a core.
    assert sent and stopped - sent[0] < 2.5, f"stopped after {stopped - sent[0]:.2f} CPU s from the signal"
    # and it still works afterwards
    assert tetstream.delaunay(uniform(1000, 24)).nsimplex > 0


def test_progress_goes_through_logging(tmp_path):
    """run(progress=True) logs through `logging` (and sys.stderr as Python sees it), not fd 2."""
    import contextlib
    import io
    import logging
    pts = uniform(3000, 25)
    captured = io.StringIO()
    # As in a script or a notebook, where logging is not configured (pytest puts its
    # own capturing handler on the root logger, which would take the records instead)
    root = logging.getLogger()
    saved = root.handlers[:]
    root.handlers.clear()
    try:
        with contextlib.redirect_stderr(captured):
            tetstream.run(pts, str(tmp_path / "a.tets"), memory="64M", progress=True)
    finally:
        root.handlers[:] = saved
    assert "sorted 3000 points" in captured.getvalue() and "triangulating" in captured.getvalue(), captured.getvalue()
    records = []

    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record)

    handler = Keep()
    logging.getLogger("tetstream").addHandler(handler)
    lines = []
    try:
        tetstream.run(pts, str(tmp_path / "b.tets"), memory="64M", progress=lines.append)
        tetstream.run(pts, str(tmp_path / "c.tets"), memory="64M", progress=False)
    finally:
        logging.getLogger("tetstream").removeHandler(handler)
    infos = [r for r in records if r.levelno == logging.INFO]
    assert infos and all(r.name == "tetstream" for r in records)
    assert any("triangulating" in r.getMessage() for r in infos)
    assert lines and len(lines) == len(infos)  # progress=False added no INFO record


def test_run_to_a_mesh_name(tmp_path):
    meshio = pytest.importorskip("meshio")
    pts = uniform(2000, 26)
    s = tetstream.run(pts, str(tmp_path / "m.vtu"), memory="64M", progress=False)
    mesh = meshio.read(str(tmp_path / "m.vtu"))
    assert len(mesh.cells_dict["tetra"]) == s["tets"] and s["mesh"].endswith("m.vtu")
    assert sorted(os.listdir(tmp_path)) == ["m.vtu"]


if __name__ == "__main__":
    # ctest's convention for tests/python: the binary's path as the argument (unused here)
    sys.exit(pytest.main([__file__, "-q", "-p", "no:cacheprovider"]))
