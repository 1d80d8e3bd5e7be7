"""`tetstream field` against SciPy (Qhull), an independent implementation.

Usage: python3 test_field_scipy.py /path/to/tetstream

On 20000 clustered points (gen --dist clusters, run): every interior point's Voronoi
volume against the convex hull of its scipy.spatial.Voronoi region (relative 1e-9;
measured 4.7e-11), the neighbours against scipy.spatial.Delaunay's (identical sets),
the DTFE density against 4 / (sum of the volumes of scipy's tets at the point)
(relative 1e-12), and the hull points (NaN / inf) against Qhull's unbounded regions.
"""
import os
import subprocess
import sys
import tempfile

try:
    import numpy as np
    from scipy.spatial import ConvexHull, Delaunay, Voronoi
except ImportError:
    # CMake may have found a Python without Debian's numpy/scipy; use the system one.
    if os.path.exists("/usr/bin/python3") and os.path.realpath(sys.executable) != os.path.realpath("/usr/bin/python3"):
        os.execv("/usr/bin/python3", ["/usr/bin/python3"] + sys.argv)
    raise


def main(tetstream):
    with tempfile.TemporaryDirectory() as d:
        def run(*args):
            subprocess.run([tetstream, "-q", *args], check=True, cwd=d, stdout=subprocess.DEVNULL)
        run("gen", "--dist", "clusters", "--n", "20000", "--seed", "9", "-o", "p.f64")
        run("run", "p.f64", "-o", "p.tets", "--no-checkpoint")
        run("field", "p.tets", "-o", "f", "--density", "dtfe", "--voronoi-volume", "--neighbours")
        p = np.fromfile(os.path.join(d, "p.f64")).reshape(-1, 3)
        load = lambda name: np.load(os.path.join(d, "f." + name + ".npy"))
        vol, rho = load("voronoi"), load("density")
        off, idx = load("neighbours.offsets"), load("neighbours.indices")

    vor = Voronoi(p)
    worst, compared = 0.0, 0
    for i in range(len(p)):
        region = vor.regions[vor.point_region[i]]
        unbounded = -1 in region or not region
        if not np.isfinite(vol[i]):
            continue  # a hull point; Qhull's region of it is unbounded (checked below)
        assert not unbounded, f"point {i}: finite volume {vol[i]} but Qhull's cell is unbounded"
        v = ConvexHull(vor.vertices[region]).volume
        worst = max(worst, abs(v - vol[i]) / v)
        compared += 1
    hull = int((~np.isfinite(vol)).sum())
    assert compared > 19000 and worst < 1e-9, (compared, worst)
    assert np.array_equal(np.isnan(rho), ~np.isfinite(vol)), "density and Voronoi disagree on the hull points"

    dt = Delaunay(p)
    ip, ind = dt.vertex_neighbor_vertices
    for i in range(len(p)):
        assert set(ind[ip[i]:ip[i + 1]]) == set(idx[off[i]:off[i + 1]]), f"neighbours of point {i}"
        assert list(idx[off[i]:off[i + 1]]) == sorted(idx[off[i]:off[i + 1]]), f"row {i} not sorted"
    star = np.zeros(len(p))
    for t in dt.simplices:
        a, b, c, e = p[t]
        star[t] += abs(np.linalg.det(np.array([b - a, c - a, e - a]))) / 6
    interior = np.isfinite(rho)
    rel = np.max(np.abs(rho[interior] - 4 / star[interior]) / rho[interior])
    assert rel < 1e-12, rel
    print(f"field vs scipy: {compared} interior Voronoi cells (worst relative {worst:.2g}), {hull} hull points, "
          f"neighbours identical, DTFE worst relative {rel:.2g}")


if __name__ == "__main__":
    main(os.path.abspath(sys.argv[1]))
