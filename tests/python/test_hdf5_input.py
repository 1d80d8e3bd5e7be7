#!/usr/bin/env python3
"""HDF5 input, on files written by h5py as Gadget/SWIFT snapshots are laid out.

A snapshot of 11 files (natural order: snap.10 last, not after snap.1), float32 and
float64 datasets, two particle types with one type's group missing from a file; `info`
lists the (N, 3) datasets; `run` over the files gives a valid triangulation whose
original ids are the positions across the files and datasets in order (checked point by
point with `cat --points`); a large dataset is read in bounded memory; bad datasets and
files are one-line errors. Without h5py this test FAILS (CI installs python3-h5py).

Usage: test_hdf5_input.py /path/to/tetstream
"""
import os
import shutil
import subprocess
import sys
import tempfile

try:
    import h5py
    import numpy as np
except ImportError:
    # Debian's python3-h5py lives in the system interpreter; ctest may have found another.
    if os.path.exists("/usr/bin/python3") and os.path.realpath(sys.executable) != os.path.realpath("/usr/bin/python3"):
        os.execv("/usr/bin/python3", ["/usr/bin/python3"] + sys.argv)
    print("FAIL: h5py is not installed (apt-get install python3-h5py; scripts/setup.sh does)", file=sys.stderr)
    sys.exit(1)

T = os.path.realpath(sys.argv[1])


def fail(msg):
    print("FAIL: " + msg, file=sys.stderr)
    sys.exit(1)


def run(*args, code=0):
    p = subprocess.run([T, "-q", *args], capture_output=True, text=True)
    if p.returncode != code:
        fail(f"{' '.join(args)}: exit {p.returncode}, expected {code}: {p.stderr}")
    if code != 0 and len(p.stderr.strip().splitlines()) != 1:
        fail(f"{' '.join(args)}: expected a one-line error, got: {p.stderr}")
    return p


def write_snapshot(rng):
    """11 files; PartType1 in all (float64, file 3 float32), PartType0 missing from file 5."""
    expected = []  # points in the order tetstream must read them: file-major, then dataset
    for i in range(11):
        with h5py.File(f"snap.{i}.hdf5", "w") as f:
            f.create_group("Header").attrs["NumFilesPerSnapshot"] = 11
            parts = {}
            if i != 5:
                parts["PartType0"] = rng.random((30 + i, 3))
            p1 = rng.random((40 + i, 3))
            parts["PartType1"] = p1.astype(np.float32) if i == 3 else p1
            for name, xyz in parts.items():
                g = f.create_group(name)
                g.create_dataset("Coordinates", data=xyz, chunks=(16, 3), compression="gzip")
                g.create_dataset("Velocities", data=rng.random((len(xyz), 3)).astype(np.float32))
                g.create_dataset("ParticleIDs", data=np.arange(len(xyz), dtype=np.uint64))
                g.create_dataset("Masses4", data=rng.random((len(xyz), 4)))
            for name in ("PartType0", "PartType1"):
                if name in parts:
                    expected.append(parts[name].astype(np.float64))
    return np.concatenate(expected)


def main():
    probe = subprocess.run([T, "-q", "info", "/nonexistent.hdf5", "--dataset", "/x"], capture_output=True, text=True)
    if "built without HDF5" in probe.stderr:
        if os.path.exists("/usr/include/hdf5"):
            fail("libhdf5-dev is installed but tetstream was built without HDF5 (-DTETSTREAM_HDF5=ON)")
        print("SKIPPED: this tetstream was built without HDF5 and libhdf5-dev is not installed")
        return
    rng = np.random.default_rng(23)
    expected = write_snapshot(rng)

    # info lists the (N, 3) datasets only (not ParticleIDs (N,), not Masses4 (N, 4)).
    out = run("info", "snap.0.hdf5").stdout
    for want in ("/PartType0/Coordinates  30 x 3 float64", "/PartType1/Velocities  40 x 3 float32"):
        if want not in out:
            fail(f"info does not list '{want}':\n{out}")
    if "ParticleIDs" in out or "Masses4" in out:
        fail(f"info lists a dataset that is not (N, 3):\n{out}")

    # Several datasets over a quoted glob: count and bounding box of all of them.
    ds = ["--dataset", "/PartType0/Coordinates", "--dataset", "PartType1/Coordinates"]
    out = run("info", "snap.*.hdf5", *ds).stdout
    if f"points:  {len(expected)}\n" not in out:
        fail(f"info over the snapshot: expected {len(expected)} points:\n{out}")

    # run + verify, then every point's original id is its position in file/dataset order.
    run("run", "snap.*.hdf5", *ds, "-o", "snap.tets", "--no-checkpoint")
    if "VALID" not in run("verify", "snap.tets").stdout:
        fail("verify did not say VALID")
    pts = np.loadtxt(run("cat", "snap.tets", "--points").stdout.splitlines(), ndmin=2)
    ids = pts[:, 3].astype(np.int64)
    if len(ids) != len(expected) or sorted(ids) != list(range(len(expected))):
        fail(f"original ids are not 0..{len(expected) - 1}")
    if not np.array_equal(pts[:, :3], expected[ids]):
        fail("a point's original id does not give its position across the files and datasets")
    # The files given one by one in another order: another order of ids.
    rev = [f"snap.{i}.hdf5" for i in reversed(range(11))]
    out = run("info", *rev, *ds).stdout
    if f"points:  {len(expected)}\n" not in out:
        fail(f"info over files given one by one:\n{out}")

    # Bounded memory: 4e6 points (96 MB of float64) read with a peak well below that.
    n = 4_000_000
    with h5py.File("big.hdf5", "w") as f:
        f.create_dataset("/PartType1/Coordinates", data=np.random.default_rng(1).random((n, 3)))
    p = subprocess.run(["/usr/bin/time", "-f", "%M", T, "-q", "info", "big.hdf5", "--dataset", "/PartType1/Coordinates"],
                       capture_output=True, text=True)
    if p.returncode != 0 or f"points:  {n}\n" not in p.stdout:
        fail(f"big.hdf5: exit {p.returncode}: {p.stdout} {p.stderr}")
    peak_kb = int(p.stderr.strip().splitlines()[-1])
    if peak_kb > 60 * 1024:
        fail(f"reading 96 MB of HDF5 peaked at {peak_kb} KB")
    print(f"big.hdf5: 96 MB dataset read with peak RSS {peak_kb} KB")

    # One-line errors: exit 1 for bad data, 2 for a missing choice.
    with h5py.File("bad.hdf5", "w") as f:
        f["four"] = np.zeros((5, 4))
        f["ints"] = np.zeros((5, 3), dtype=np.int32)
        f["nan"] = np.array([[0, 0, 0], [1, np.nan, 2]])
        f["a"] = np.zeros((5, 3))
        f["b"] = np.zeros((5, 3))
    checks = [
        (["--dataset", "/four"], 1, "shape (5, 4) is not (N, 3)"),
        (["--dataset", "/ints"], 1, "not float32 or float64"),
        (["--dataset", "/nan"], 1, "dataset /nan row 1: non-finite coordinate (y = nan)"),
        (["--dataset", "/nope"], 1, "dataset /nope not found (its (N, 3) datasets: /a"),
        (["--dataset", "/a", "--dataset", "/missing/group"], 1, "/missing/group not found"),
    ]
    for opts, code, want in checks:
        err = run("info", "bad.hdf5", *opts, code=code).stderr
        if want not in err:
            fail(f"bad.hdf5 {opts}: '{want}' not in: {err}")
    err = run("run", "bad.hdf5", "-o", "x.tets", code=2).stderr
    if "name the dataset to read with --dataset" not in err:
        fail(f"no --dataset with two candidates: {err}")
    shutil.copy("snap.0.hdf5", "trunc.hdf5")
    with open("trunc.hdf5", "r+b") as f:
        f.truncate(os.path.getsize("trunc.hdf5") // 2)
    err = run("info", "trunc.hdf5", "--dataset", "/PartType1/Coordinates", code=1).stderr
    if "trunc.hdf5" not in err:
        fail(f"truncated file: {err}")
    err = run("info", "snap.0.hdf5", "--dataset", "/PartType1/Coordinates", "--columns", "1,2,3", code=2).stderr
    if "--columns applies to text and npy" not in err:
        fail(f"--columns with HDF5: {err}")
    if os.path.exists("x.tets"):
        fail("output left after an error")
    print("hdf5 input: ok")


if __name__ == "__main__":
    d = tempfile.mkdtemp(prefix="tetstream_hdf5_")
    try:
        os.chdir(d)
        main()
    finally:
        shutil.rmtree(d)
