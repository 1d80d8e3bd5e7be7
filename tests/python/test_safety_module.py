"""The Python package keeps the promises of the command line (issue #35, docs/safety.md).

- TetFile.points, .original_ids and frames(original_ids=True) check the points
  section's CRC: a damaged section raises, as `cat --original-ids` refuses;
- run(array, ...) never removes an OUT.input.f64.partial it did not make, and after
  bad input (a NaN) removes its own spill, so the corrected call is not refused;
- an HDF5 file of a list that lacks the dataset's group says so (it gives 0 points).

Usage: python3 -m pytest tests/python/test_safety_module.py (PYTHONPATH=BUILD/python);
CTest runs it so (tests/CMakeLists.txt, label `python`).
"""
import fcntl
import os
import sys

import numpy as np
import pytest

try:
    import tetstream
except ImportError:  # the module of the default build tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "build", "python"))
    import tetstream


@pytest.fixture
def container(tmp_path):
    pts = np.random.default_rng(3).random((20000, 3))
    out = str(tmp_path / "c.tets")
    tetstream.run(pts, out, memory="64M", progress=False, checkpoint=False)
    return out


def flip(path, at):
    with open(path, "r+b") as f:
        f.seek(at)
        b = f.read(1)[0]
        f.seek(at)
        f.write(bytes([b ^ 1]))


def test_damaged_points_are_refused_by_every_reader_of_them(container):
    with tetstream.open(container) as f:
        good_ids = f.original_ids.copy()
        good_frames = [fr.copy() for fr in f.frames(original_ids=True)]
    flip(container, 300000)  # inside the points section (20000 records of 28 bytes after the header)
    with tetstream.open(container) as f:
        with pytest.raises(ValueError, match="checksum"):
            f.original_ids
        with pytest.raises(ValueError, match="checksum"):
            list(f.frames(original_ids=True))
        with pytest.raises(ValueError, match="checksum"):
            f.points
        with pytest.raises(ValueError, match="checksum"):
            f.tets(0, 10, original_ids=True)
        # Labels alone do not depend on the points: still served.
        assert len(list(f.frames())) == len(good_frames)
    flip(container, 300000)
    with tetstream.open(container) as f:
        assert np.array_equal(f.original_ids, good_ids)


def test_run_array_keeps_a_partial_spill_it_did_not_make(tmp_path):
    pts = np.random.default_rng(4).random((2000, 3))
    out = str(tmp_path / "o.tets")
    partial = out + ".input.f64.partial"
    with open(partial, "w") as f:
        f.write("another job's spill")
    # Held by another process's writer (its lock), and merely left there: both refused.
    with open(partial, "r+") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        with pytest.raises(ValueError):
            tetstream.run(pts, out, memory="64M", progress=False)
    with pytest.raises(ValueError, match="partial"):
        tetstream.run(pts, out, memory="64M", progress=False)
    assert open(partial).read() == "another job's spill"
    assert not os.path.exists(out)


def test_run_array_with_a_nan_removes_its_spill(tmp_path):
    pts = np.random.default_rng(5).random((2000, 3))
    out = str(tmp_path / "o.tets")
    bad = pts.copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError):
        tetstream.run(bad, out, memory="64M", progress=False)
    assert not os.path.exists(out + ".input.f64"), "the spill of bad input is kept"
    s = tetstream.run(pts, out, memory="64M", progress=False)  # the corrected call
    assert s["points"] == len(pts)
    assert tetstream.verify(out)["valid"]


def test_a_file_of_a_list_without_the_dataset_says_so(tmp_path):
    h5py = pytest.importorskip("h5py")
    binary = os.environ.get("TETSTREAM_BINARY") or os.path.join(
        os.path.dirname(os.path.abspath(tetstream.__file__)), "..", "..", "tools", "tetstream")
    if not os.path.exists(binary):
        pytest.skip("no tetstream binary beside the module")
    rng = np.random.default_rng(6)
    with h5py.File(tmp_path / "snap.0.hdf5", "w") as f:
        f.create_dataset("/PartType0/Coordinates", data=rng.random((50, 3)))
    with h5py.File(tmp_path / "snap.1.hdf5", "w") as f:
        f.create_dataset("/PartType1/Coordinates", data=rng.random((50, 3)))
    import subprocess
    r = subprocess.run([binary, "info", str(tmp_path / "snap.*.hdf5"), "--dataset", "/PartType0/Coordinates"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "snap.1.hdf5: no /PartType0/Coordinates in this file" in r.stderr, r.stderr


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q", "-p", "no:cacheprovider"]))
