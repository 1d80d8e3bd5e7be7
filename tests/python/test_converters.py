"""`tetstream convert` output, read back by independent readers.

Usage: python3 test_converters.py /path/to/tetstream

For each golden container in tests/data (a lattice of cubes, 6 tets per cube; see
tests/unit/container_test.cpp), the truth comes from `tetstream cat` (tets, in stored
order) and `cat --points`, and is itself checked with numpy: every tet positively
oriented, the volumes adding up to the lattice's box. Then each converter's output is
read with meshio (.vtu raw and zlib-compressed, .vtk ASCII and binary, .mesh, .msh ASCII
and binary, .node/.ele, .xdmf + .h5 with h5py) and must give exactly the same points
(bit for bit), cells (same order) and original ids (the point field "original_id", or
the .node's attribute), and gmsh must open both .msh and check them. A larger container
(several zlib blocks an array) checks the compressed .vtu against the raw one.
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile

try:
    import meshio
    import numpy as np
except ImportError:
    # CMake may have found a Python without Debian's python3-meshio; use the system one.
    if os.path.exists("/usr/bin/python3") and os.path.realpath(sys.executable) != os.path.realpath("/usr/bin/python3"):
        os.execv("/usr/bin/python3", ["/usr/bin/python3"] + sys.argv)
    raise

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "data")
FAILURES = []


def check(cond, what):
    if not cond:
        FAILURES.append(what)
        print("FAIL:", what)


def run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


def truth(tool, container):
    info = json.loads(run([tool, "-q", "--json", "info", container], check=True).stdout)
    tets = np.loadtxt(run([tool, "-q", "cat", container], check=True).stdout.splitlines(), dtype=np.int64, ndmin=2)
    pts = np.loadtxt(run([tool, "-q", "cat", container, "--points"], check=True).stdout.splitlines(), ndmin=2)
    return info, tets, pts[:, :3], pts[:, 3].astype(np.int64)


def volumes(points, cells):
    a, b, c, d = (points[cells[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def check_truth(name, info, tets, points, ids):
    check(len(tets) == info["tets"], f"{name}: cat gives {len(tets)} tets, info says {info['tets']}")
    check(len(points) == info["points"], f"{name}: cat --points gives {len(points)} points")
    vol = volumes(points, tets)
    check(np.all(vol > 0), f"{name}: {np.sum(vol <= 0)} tets not positively oriented")
    lo, hi = np.array(info["bbox"]["min"]), np.array(info["bbox"]["max"])
    check(np.isclose(vol.sum(), np.prod(hi - lo)), f"{name}: volume {vol.sum()} != box {np.prod(hi - lo)}")
    check(len({tuple(sorted(t)) for t in tets.tolist()}) == len(tets), f"{name}: repeated tets")
    check(sorted(ids.tolist()) == sorted(set(ids.tolist())), f"{name}: original ids not distinct")


def cells_of(mesh):
    blocks = [c.data for c in mesh.cells if c.type == "tetra"]
    check(len(blocks) == 1 and len(mesh.cells) == 1, "one block of tetra cells")
    return np.asarray(blocks[0], dtype=np.int64)


# (extension, convert options, name of the original-id point field or None)
VARIANTS = [
    ("vtu", [], "original_id"),
    ("vtu", ["--compress"], "original_id"),
    ("vtu", ["--compress=1"], "original_id"),
    ("vtk", [], "original_id"),
    ("vtk", ["--binary"], "original_id"),
    ("mesh", [], None),
    ("msh", [], "original_id"),
    ("msh", ["--binary"], "original_id"),
    ("node", [], "tetgen:attr1"),
    ("xdmf", [], "original_id"),
]


def hdf5_built(tool, container, tmp):
    """Whether this tetstream writes .xdmf; without HDF5 the refusal must be clear."""
    out = os.path.join(tmp, "probe.xdmf")
    r = run([tool, "-q", "convert", container, out])
    if r.returncode == 0:
        for f in ("probe.xdmf", "probe.h5"):
            os.remove(os.path.join(tmp, f))
        return True
    check(r.returncode == 2 and "built without HDF5" in r.stderr and r.stderr.count("\n") == 1
          and r.stderr.startswith("tetstream: error:"), f".xdmf without HDF5: exit {r.returncode}, {r.stderr}")
    check(not os.listdir(tmp) or not [f for f in os.listdir(tmp) if f.startswith("probe")], ".xdmf refusal left files")
    return False


def test_container(tool, golden, tmp):
    name = os.path.basename(golden)
    container = os.path.join(tmp, name.replace(".golden", ".tets"))
    shutil.copy(golden, container)
    info, tets, points, ids = truth(tool, container)
    check_truth(name, info, tets, points, ids)
    with_hdf5 = hdf5_built(tool, container, tmp)

    for ext, options, id_field in VARIANTS:
        if ext == "xdmf" and not with_hdf5:
            continue
        what = f"{name}: .{ext} {' '.join(options)}"
        out = os.path.join(tmp, f"mesh.{ext}")
        r = run([tool, "-q", "convert", container, out] + options)
        check(r.returncode == 0, f"{what}: convert failed: {r.stderr}")
        if r.returncode:
            continue
        check(not [f for f in os.listdir(tmp) if f.endswith(".partial")], f"{what}: .partial left")
        mesh = meshio.read(out)
        check(mesh.points.shape == points.shape and np.array_equal(mesh.points.astype(np.float64), points),
              f"{what}: points differ")
        cells = cells_of(mesh)
        check(np.array_equal(cells, tets), f"{what}: cells differ from `cat`")
        if id_field:
            field = np.asarray(mesh.point_data.get(id_field, []), dtype=np.int64).ravel()
            check(np.array_equal(field, ids), f"{what}: {id_field} differs from `cat --points`")
        with open(out, "rb") as f:
            head = f.read(2048)
        if "--binary" in options:
            check(b"BINARY" in head or b"4.1 1 8" in head, f"{what}: not binary")
        if "--compress" in " ".join(options):
            check(b'compressor="vtkZLibDataCompressor"' in head, f"{what}: not compressed")
        if ext == "xdmf":
            check(os.path.exists(os.path.join(tmp, "mesh.h5")), f"{what}: no .h5 beside the .xdmf")
        if ext == "node":
            check(os.path.exists(os.path.join(tmp, "mesh.ele")), f"{name}: no .ele beside the .node")
        if ext == "msh":
            g = run(["gmsh", "-check", out])
            log = g.stdout + g.stderr
            check(g.returncode == 0, f"{name}: gmsh -check exit {g.returncode}: {log[-500:]}")
            check(f"{len(points)} nodes" in log and f"{len(tets)} elements" in log,
                  f"{name}: gmsh did not read {len(points)} nodes and {len(tets)} elements: {log[-500:]}")
            check("Error" not in log, f"{name}: gmsh reports an error: {log[-500:]}")


def test_failures(tool, golden, tmp):
    container = os.path.join(tmp, "cut.tets")
    with open(golden, "rb") as f:
        data = f.read()
    with open(container, "wb") as f:
        f.write(data[: len(data) // 2])
    out = os.path.join(tmp, "cut.vtu")
    r = run([tool, "-q", "convert", container, out])
    check(r.returncode == 1 and "truncated" in r.stderr, f"truncated input: exit {r.returncode}, {r.stderr}")
    check(not os.path.exists(out) and not os.path.exists(out + ".partial"), "output left after a failure")
    r = run([tool, "-q", "convert", golden, os.path.join(tmp, "mesh.stl")])
    check(r.returncode == 2 and "unknown mesh format" in r.stderr, f"unknown extension: exit {r.returncode}")
    for ext, options, words in (("mesh", ["--binary"], "--binary is for .msh and .vtk"),
                                ("msh", ["--compress"], "--compress is for .vtu"),
                                ("vtu", ["--compress=12"], "use 1 to 9")):
        out = os.path.join(tmp, f"bad.{ext}")
        r = run([tool, "-q", "convert", golden, out] + options)
        check(r.returncode == 2 and words in r.stderr and r.stderr.startswith("tetstream: error:"),
              f"convert .{ext} {options}: exit {r.returncode}, {r.stderr}")
        check(not os.path.exists(out) and not os.path.exists(out + ".partial"), f"bad .{ext}: output left")


def test_compressed_blocks(tool, tmp):
    """A mesh whose arrays span several 1 MiB zlib blocks, the last one partial."""
    pts, container = os.path.join(tmp, "big.f64"), os.path.join(tmp, "big.tets")
    run([tool, "-q", "gen", "--n", "2e4", "--seed", "5", "-o", pts], check=True)
    run([tool, "-q", "run", pts, "-o", container, "--memory", "64M"], check=True)
    raw, packed = os.path.join(tmp, "raw.vtu"), os.path.join(tmp, "packed.vtu")
    run([tool, "-q", "convert", container, raw], check=True)
    run([tool, "-q", "convert", container, packed, "--compress=9"], check=True)
    a, b = meshio.read(raw), meshio.read(packed)
    check(len(b.cells[0].data) * 32 > 3 << 20, "the compressed test spans several blocks")
    check(np.array_equal(a.points, b.points) and np.array_equal(a.cells[0].data, b.cells[0].data)
          and np.array_equal(a.point_data["original_id"], b.point_data["original_id"]),
          "compressed .vtu differs from the raw one")
    check(os.path.getsize(packed) < os.path.getsize(raw) / 2, "compression halves the .vtu at least")


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: test_converters.py /path/to/tetstream")
    tool = sys.argv[1]
    goldens = sorted(os.path.join(DATA, f) for f in os.listdir(DATA) if f.startswith("golden_v"))
    check(len(goldens) >= 3, "golden containers present")
    if shutil.which("gmsh") is None:
        FAILURES.append("gmsh is not installed (scripts/setup.sh installs it)")
    with tempfile.TemporaryDirectory(prefix="tetstream_convert_") as tmp:
        for g in goldens:
            sub = os.path.join(tmp, os.path.basename(g))
            os.mkdir(sub)
            test_container(tool, g, sub)
        test_failures(tool, goldens[0], tmp)
        test_compressed_blocks(tool, tmp)
    if FAILURES:
        print(f"{len(FAILURES)} failure(s)")
        sys.exit(1)
    print(f"ok: {len(goldens)} containers x {len(VARIANTS)} format variants read back by meshio, "
          ".msh checked by gmsh, compressed .vtu in several blocks")


if __name__ == "__main__":
    main()
