#!/usr/bin/env python3
"""Triangulate 10^6 clustered points with tetstream and draw a slice through the mesh.

    PYTHONPATH=build/python python3 docs/python_example.py [OUT.png] [--n N]

Each tetrahedron that the plane z = 0.5 cuts leaves a triangle or a quadrilateral in the
plane; they are drawn coloured by the tetrahedron's volume (small where the points
cluster), which shows the density field the triangulation resolves (the DTFE idea).
The same mesh is then written out of core with tetstream.run() and read back frame by
frame, to show the other half of the package.
"""
import argparse
import os
import tempfile
import time

import numpy as np
import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt
from matplotlib.collections import PolyCollection

import tetstream

WINDOW = ((0.15, 0.5), (0.3, 0.65))  # the part of the slice drawn: a cluster and its surroundings
EDGES = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)])


def clustered_points(n, seed=7):
    """A uniform background plus a few Gaussian clusters, in the unit cube."""
    rng = np.random.default_rng(seed)
    k = n // 2
    centres = rng.random((12, 3)) * 0.8 + 0.1
    which = rng.integers(0, len(centres), n - k)
    clusters = centres[which] + rng.normal(scale=0.04, size=(n - k, 3))
    pts = np.concatenate([rng.random((k, 3)), clusters])
    return pts[((pts >= 0) & (pts <= 1)).all(axis=1)]


def slice_polygons(points, simplices, z0):
    """The cross-sections of the tets cut by the plane z = z0: (polygons, tet indices)."""
    z = points[simplices, 2]
    above = z > z0
    count = above.sum(axis=1)
    cut = np.nonzero((count > 0) & (count < 4))[0]
    tets = simplices[cut]
    a, b = tets[:, EDGES[:, 0]], tets[:, EDGES[:, 1]]  # (K, 6) edge end points
    za, zb = points[a, 2], points[b, 2]
    crosses = (za > z0) != (zb > z0)
    t = np.where(crosses, (z0 - za) / np.where(crosses, zb - za, 1.0), np.nan)
    xy = points[a, :2] + t[..., None] * (points[b, :2] - points[a, :2])  # (K, 6, 2), NaN off the plane
    centre = np.nanmean(xy, axis=1)
    angle = np.arctan2(xy[..., 1] - centre[:, None, 1], xy[..., 0] - centre[:, None, 0])
    order = np.argsort(np.where(crosses, angle, np.inf), axis=1)  # the crossing edges first, by angle
    xy = np.take_along_axis(xy, order[..., None], axis=1)
    quads = count[cut] == 2  # two vertices on each side: four edges cross
    polygons = [p[:4] if q else p[:3] for p, q in zip(xy, quads)]
    return polygons, cut


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out", nargs="?", default="python_slice.png")
    ap.add_argument("--n", type=int, default=1_000_000)
    a = ap.parse_args()

    pts = clustered_points(a.n)
    t = time.perf_counter()
    tri = tetstream.delaunay(pts)
    print(f"delaunay: {tri} in {time.perf_counter() - t:.2f} s")
    volume = tri.volumes()
    print(f"total volume {volume.sum():.12f}, smallest tet {volume.min():.3g}")

    polygons, cut = slice_polygons(tri.points, tri.simplices, 0.5)
    (x0, x1), (y0, y1) = WINDOW
    window = [(p[:, 0].min() > x0) & (p[:, 0].max() < x1) & (p[:, 1].min() > y0) & (p[:, 1].max() < y1)
              for p in polygons]
    shown = [p for p, w in zip(polygons, window) if w]
    fig, ax = plt.subplots(figsize=(5.5, 5), dpi=80)
    pc = PolyCollection(shown, array=np.log10(volume[cut][window]), cmap="viridis", edgecolors="face",
                        linewidths=0.1)
    ax.add_collection(pc)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_title(f"z = 0.5 through the Delaunay tetrahedra of {len(pts):,} points")
    fig.colorbar(pc, ax=ax, shrink=0.8, label="log10 tetrahedron volume")
    fig.savefig(a.out, bbox_inches="tight")
    print(f"{len(polygons)} tets cut by z = 0.5 ({len(shown)} drawn) -> {a.out}")

    # The same points out of core: a container on disk, read back frame by frame.
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "points.tets")
        summary = tetstream.run(pts, out, memory="256M", progress=False)
        print(f"run: {summary['tets']} tets in {summary['segments']} segments, {summary['output_bytes']} bytes, "
              f"{summary['seconds']['total']:.2f} s")
        with tetstream.open(out) as f:
            n = sum(len(frame) for frame in f.frames(original_ids=True))
            print(f"read back {n} tets in {f.n_frames} frames; verify: {tetstream.verify(out)['valid']}")


if __name__ == "__main__":
    main()
