"""tetstream: exact 3D Delaunay triangulations, in memory or out of core.

Four entry points (docs/python.md has a tour and an example):

* :func:`delaunay` -- triangulate an ``(N, 3)`` array in memory (like
  ``scipy.spatial.Delaunay``, with exact predicates), returning a :class:`Triangulation`.
* :func:`run` -- the out-of-core job of ``tetstream run``: a point file (or an array,
  spilled to disk) to a ``.tets`` container, within a memory budget; returns the summary
  that ``tetstream run --json`` prints.
* :func:`open` -- read a ``.tets`` container: points, original ids, tets frame by
  frame or by position (:class:`TetFile`).
* :func:`verify` -- the independent certificate of ``tetstream verify``.
* :func:`field` -- per-point fields (DTFE density, Voronoi volumes, neighbours, a density
  grid) of a container, as ``tetstream field`` computes them, or of a
  :class:`Triangulation` in memory.

Progress and the jobs' messages go through Python's :mod:`logging` (the logger
``"tetstream"``), so notebooks and ``contextlib.redirect_stderr`` see them.

Errors: bad input or options raise :class:`InputError` / :class:`UsageError` (both
``ValueError``), I/O failures :class:`IoError` (an ``OSError``), and Ctrl-C during
:func:`delaunay`, :func:`run`, :func:`verify` or :func:`field` stops the work and raises
``KeyboardInterrupt`` (a checkpointed run keeps its checkpoint: call
``run(..., resume=True)``).
"""
from __future__ import annotations

import builtins
import json
import logging
import operator
import os
import sys
import tempfile
from typing import Any, Callable, Dict, Iterator, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

from . import _core
from ._core import InputError, IoError, UsageError

__all__ = [
    "delaunay",
    "Triangulation",
    "PeriodicTriangulation",
    "run",
    "open",
    "TetFile",
    "verify",
    "field",
    "InputError",
    "UsageError",
    "IoError",
    "VerificationError",
]
__version__ = "0.1.0"

PathLike = Union[str, "os.PathLike[str]"]
ArrayLike = npt.ArrayLike  # anything np.asarray turns into an (N, 3) array
Progress = Union[bool, Callable[[str], Any]]

# ---------------------------------------------------------------------------------------
# Messages: the C++ side hands each log line of a job to _emit (on the calling thread,
# with the GIL), which passes it to the logger "tetstream". Without any logging
# configuration, a handler of our own writes them to sys.stderr as looked up at each
# message (so redirect_stderr and notebooks capture them); once the application
# configures logging (a handler on the root logger), the records go there instead.

_log = logging.getLogger("tetstream")
_PY_LEVELS = {0: 5, 1: logging.DEBUG, 2: logging.INFO, 3: logging.WARNING, 4: logging.ERROR, 5: logging.CRITICAL}


class _StderrHandler(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        if logging.getLogger().handlers:
            return  # the application's logging configuration shows it (propagation)
        try:
            sys.stderr.write(self.format(record) + "\n")
            sys.stderr.flush()
        except Exception:  # pragma: no cover - a closed stream
            self.handleError(record)


if not any(isinstance(h, _StderrHandler) for h in _log.handlers):
    _handler = _StderrHandler()
    _handler.setFormatter(logging.Formatter("[%(asctime)s.%(msecs)03d] [%(levelname)s] %(message)s", "%H:%M:%S"))
    _log.addHandler(_handler)
if _log.level == logging.NOTSET:
    _log.setLevel(logging.INFO)  # the jobs' progress is INFO; progress=False filters it in C++


def _emitter(progress: Progress) -> Callable[[int, str], None]:
    """The sink of a job's log lines: the logger, and ``progress`` when it is callable."""
    callback = progress if callable(progress) else None

    def emit(level: int, message: str) -> None:
        _log.log(_PY_LEVELS.get(level, logging.INFO), message)
        if callback is not None and level <= 2:
            callback(message)

    return emit


class VerificationError(ValueError):
    """:func:`verify` found violations. ``report`` holds the whole report (a dict)."""

    def __init__(self, message: str, report: Dict[str, Any]):
        super().__init__(message)
        self.report = report


def _threads(threads: Optional[int]) -> int:
    if threads is None:
        return 0
    if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or not 1 <= int(threads) <= 1024:
        raise UsageError(f"threads must be an int in [1, 1024] or None (all cores), got {threads!r}")
    return int(threads)


# ---------------------------------------------------------------------------------------
# In memory


class Triangulation:
    """The Delaunay triangulation of a point set, as returned by :func:`delaunay`.

    Attributes (NumPy arrays, indices of ``dtype`` int64 or int32):

    points : (N, 3) float64
        The points that were triangulated: the caller's array itself when it was a
        C-contiguous float64 array (no copy is made), else a float64 copy.
    simplices : (M, 4)
        The tetrahedra, as indices into ``points`` (the input's order), each positively
        oriented: ``det[p1 - p0, p2 - p0, p3 - p0] > 0``.
    neighbors : (M, 4)
        ``neighbors[i, j]`` is the simplex opposite vertex ``j`` of simplex ``i`` (across
        the facet without it), or -1 when that facet is on the convex hull (SciPy's
        convention).
    convex_hull : (H, 3)
        The hull's triangles, as point indices, counter-clockwise seen from outside
        (their normals point outwards).
    duplicates : (D, 2)
        Points that are exact duplicates of others: each row ``[i, j]`` says input point
        ``i`` was merged into point ``j`` (a vertex), the first of its copies in the
        input (``j < i``, as ``run`` keeps the first). Every input point is either a
        vertex of some simplex or the first column of one row. Sorted by ``i``.

    The attributes and methods of ``scipy.spatial.Delaunay`` that make sense for 3-D
    points are here with SciPy's names, shapes and conventions: :meth:`find_simplex`,
    :attr:`transform`, :attr:`vertex_to_simplex`, :attr:`vertex_neighbor_vertices`,
    :attr:`coplanar`, :attr:`equations`, :meth:`plane_distance`, :meth:`lift_points`,
    :attr:`ndim`, :attr:`npoints`, :attr:`nsimplex`, :attr:`min_bound`,
    :attr:`max_bound` (computed on first use, then cached).

    The triangulation is exact: every predicate is evaluated exactly, and degenerate
    inputs (cospherical or coplanar points, grids) are resolved by one symbolic
    perturbation keyed by the input index, so the result is a valid triangulation of the
    convex hull whatever the input. (The out-of-core :func:`run` keys it by the sorted
    order instead; on degenerate inputs the two may choose different, equally Delaunay,
    tetrahedra.)
    """

    __slots__ = ("points", "simplices", "neighbors", "convex_hull", "duplicates", "_cache")

    #: SciPy's lifting of the points onto the paraboloid is ``z = scale * |x|^2 + shift``;
    #: Qhull picks its own values, tetstream uses 1 and 0 (see :attr:`equations`).
    paraboloid_scale = 1.0
    paraboloid_shift = 0.0
    #: Always False: the Delaunay triangulation, not the furthest-site one.
    furthest_site = False

    def __init__(self, points: np.ndarray, simplices: np.ndarray, neighbors: np.ndarray,
                 convex_hull: np.ndarray, duplicates: np.ndarray):
        self.points = points
        self.simplices = simplices
        self.neighbors = neighbors
        self.convex_hull = convex_hull
        self.duplicates = duplicates
        self._cache: Dict[str, Any] = {}

    @property
    def ndim(self) -> int:
        """Dimension of the points: 3."""
        return 3

    @property
    def npoints(self) -> int:
        """Number of input points (vertices and duplicates)."""
        return int(self.points.shape[0])

    @property
    def nsimplex(self) -> int:
        """Number of tetrahedra."""
        return int(self.simplices.shape[0])

    @property
    def min_bound(self) -> np.ndarray:
        """(3,) the smallest coordinate of the input points on each axis."""
        return self.points.min(axis=0)

    @property
    def max_bound(self) -> np.ndarray:
        """(3,) the largest coordinate of the input points on each axis."""
        return self.points.max(axis=0)

    def volumes(self) -> np.ndarray:
        """The (positive) volume of each simplex, in floating point."""
        p = self.points[self.simplices]
        a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
        return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0

    def _vertex_to_simplex(self) -> np.ndarray:
        # In the dtype of simplices, as find_simplex's walk wants it.
        if "v2s" not in self._cache:
            self._cache["v2s"] = _core.vertex_to_simplex(self.simplices, self.npoints)
        return self._cache["v2s"]

    @property
    def vertex_to_simplex(self) -> np.ndarray:
        """(npoints,) intc: one simplex that has each point as a vertex; -1 for a merged duplicate."""
        return self._vertex_to_simplex().astype(np.intc, copy=False)

    @property
    def vertex_neighbor_vertices(self):
        """``(indptr, indices)``: the Delaunay neighbours of vertex ``k`` are
        ``indices[indptr[k]:indptr[k + 1]]`` (sorted; none for a merged duplicate).

        SciPy's layout (a CSR matrix's index arrays), intc while the counts fit.
        """
        if "vnv" not in self._cache:
            self._cache["vnv"] = _core.vertex_neighbor_vertices(self.simplices, self.npoints, 0)
        return self._cache["vnv"]

    @property
    def coplanar(self) -> np.ndarray:
        """(D, 3) intc rows ``[i, s, j]`` for the input points that are not vertices.

        In SciPy these are the points Qhull left out (coplanar or too close to another),
        with the simplex ``s`` nearest to each and its nearest vertex ``j``. Here the
        only points left out are exact duplicates: ``j`` is the vertex point ``i`` was
        merged into (the second column of :attr:`duplicates`) and ``s`` a simplex of it.
        """
        d = self.duplicates
        out = np.empty((len(d), 3), dtype=np.intc)
        out[:, 0] = d[:, 0]
        out[:, 1] = self._vertex_to_simplex()[d[:, 1]] if len(d) else 0
        out[:, 2] = d[:, 1]
        return out

    def find_simplex(self, xi: ArrayLike, bruteforce: bool = False, tol: Optional[float] = None) -> np.ndarray:
        """The simplex holding each point of ``xi``; -1 outside the convex hull.

        Parameters
        ----------
        xi : array_like, shape (..., 3)
            Query points.
        bruteforce, tol
            SciPy's arguments, accepted for compatibility: the location is exact (every
            test is an exact ``orient3d``), so there is no tolerance to set and no
            search that can miss. A point on a shared facet, edge or vertex belongs to
            one of the simplices around it; a point on the hull is inside.

        Returns
        -------
        ndarray of intc, shape ``xi.shape[:-1]``

        Notes
        -----
        The queries are sorted along a Hilbert curve and each one is found by a walk
        across facets from the simplex of the one before (C++, GIL released, all cores).
        """
        x = np.asarray(xi, dtype=np.float64)
        if x.shape[-1:] != (3,):
            raise ValueError(f"wrong dimensionality in xi: expected (..., 3), got {x.shape}")
        flat = np.ascontiguousarray(x.reshape(-1, 3))
        found = _core.find_simplex(self.points, self.simplices, self.neighbors, self._vertex_to_simplex(), flat, 0)
        return found.reshape(x.shape[:-1])

    @property
    def transform(self) -> np.ndarray:
        """(nsimplex, 4, 3) affine maps to barycentric coordinates (SciPy's layout).

        For simplex ``i`` with ``T = transform[i, :3]`` and ``r = transform[i, 3]``, the
        barycentric coordinates of ``x`` are ``c = T @ (x - r)`` followed by
        ``1 - c.sum()`` (``r`` is the simplex's last vertex). Floating point.
        """
        if "transform" not in self._cache:
            p = self.points[self.simplices]
            r = p[:, 3, :]
            t = np.transpose(p[:, :3, :] - r[:, None, :], (0, 2, 1))  # columns v_k - v_3
            out = np.empty((self.nsimplex, 4, 3))
            try:
                out[:, :3, :] = np.linalg.inv(t)
            except np.linalg.LinAlgError:  # a simplex too flat for floating point
                for i in range(self.nsimplex):
                    try:
                        out[i, :3, :] = np.linalg.inv(t[i])
                    except np.linalg.LinAlgError:
                        out[i, :3, :] = np.nan
            out[:, 3, :] = r
            self._cache["transform"] = out
        return self._cache["transform"]

    def lift_points(self, x: ArrayLike) -> np.ndarray:
        """Points lifted onto the paraboloid: ``(x, paraboloid_scale * |x|^2 + paraboloid_shift)``."""
        x = np.asarray(x, dtype=np.float64)
        z = np.empty(x.shape[:-1] + (4,))
        z[..., :3] = x
        z[..., 3] = self.paraboloid_scale * (x ** 2).sum(axis=-1) + self.paraboloid_shift
        return z

    @property
    def equations(self) -> np.ndarray:
        """(nsimplex, 5): the lifted hyperplane of each simplex, ``[n, offset]``.

        The hyperplane through the simplex's vertices lifted by :meth:`lift_points`, as
        a unit normal ``n`` (4 components, pointing down: ``n[3] < 0``, the lower hull's
        outward side) and an offset, so that ``n . lift(x) + offset`` is positive exactly
        when ``x`` lies inside the simplex's circumsphere (in exact arithmetic; this is
        floating point). SciPy's convention, with the paraboloid unscaled (Qhull scales
        and shifts it, so SciPy's values differ by a positive factor per simplex and its
        offsets by the shift; the signs agree).
        """
        if "equations" not in self._cache:
            lifted = self.lift_points(self.points[self.simplices])  # (M, 4, 4)
            d = lifted[:, :3, :] - lifted[:, 3:4, :]               # (M, 3, 4)
            n = np.empty((self.nsimplex, 4))
            for k in range(4):  # the generalised cross product: cofactors of the 3x4 rows
                cols = [c for c in range(4) if c != k]
                n[:, k] = (-1) ** k * np.linalg.det(d[:, :, cols])
            n /= np.linalg.norm(n, axis=1)[:, None]
            n[n[:, 3] > 0] *= -1
            eq = np.empty((self.nsimplex, 5))
            eq[:, :4] = n
            eq[:, 4] = -np.einsum("ij,ij->i", n, lifted[:, 3, :])
            self._cache["equations"] = eq
        return self._cache["equations"]

    def plane_distance(self, xi: ArrayLike) -> np.ndarray:
        """(nsimplex,) distances of the lifted point ``xi`` (shape (3,)) to the simplices'
        lifted hyperplanes (:attr:`equations`): positive where ``xi`` lies inside the
        simplex's circumsphere."""
        x = np.asarray(xi, dtype=np.float64)
        if x.shape != (3,):
            raise ValueError(f"xi must have shape (3,), got {x.shape}")
        eq = self.equations
        return eq[:, :4] @ self.lift_points(x) + eq[:, 4]

    def __len__(self) -> int:
        return self.nsimplex

    def __repr__(self) -> str:
        return (f"<tetstream.Triangulation: {self.npoints} points, {self.nsimplex} simplices, "
                f"{len(self.convex_hull)} hull facets, {len(self.duplicates)} duplicates>")


class PeriodicTriangulation:
    """The Delaunay triangulation of points on the flat 3-torus (docs/periodic.md).

    ``points`` (N, 3) as given; ``simplices`` (M, 4) indices into them; ``offsets``
    (M, 4, 3) int8: vertex j of simplex i stands at
    ``points[simplices[i, j]] + offsets[i, j] * period``; ``period`` (3,). Every simplex is
    positively oriented so placed; each appears once.
    """

    def __init__(self, points: np.ndarray, simplices: np.ndarray, offsets: np.ndarray, period: np.ndarray):
        self.points, self.simplices, self.offsets, self.period = points, simplices, offsets, period

    def vertices(self) -> np.ndarray:
        """(M, 4, 3) coordinates of every simplex's vertices, unwrapped."""
        return self.points[self.simplices] + self.offsets * self.period

    def volumes(self) -> np.ndarray:
        """(M,) volumes; they sum to the box's volume."""
        v = self.vertices()
        return np.linalg.det(v[:, 1:] - v[:, :1]) / 6


def _periodic_delaunay(points: ArrayLike, periodic: Any, threads: Optional[int]) -> PeriodicTriangulation:
    arr = np.ascontiguousarray(np.asarray(points, dtype=np.float64))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise UsageError(f"points must be an (N, 3) array, got shape {arr.shape}")
    with tempfile.TemporaryDirectory(prefix="tetstream-periodic-") as work:
        out = os.path.join(work, "p.tets")
        run(arr, out, memory="1G", threads=threads, progress=False, checkpoint=False, periodic=periodic)
        d = _core.periodic_tets(out)
    return PeriodicTriangulation(arr, d["simplices"], d["offsets"], np.asarray(d["period"], dtype=np.float64))


def delaunay(points: ArrayLike, threads: Optional[int] = None, dtype: npt.DTypeLike = np.int64,
             periodic: Any = None) -> Union[Triangulation, PeriodicTriangulation]:
    """Delaunay triangulation of 3D points, computed in memory with exact predicates.

    With ``periodic=L`` (or ``(Lx, Ly, Lz)``) it is the triangulation of the flat torus
    ``[0, L)^3`` (docs/periodic.md), computed by the out-of-core job in a temporary
    directory, returned as a :class:`PeriodicTriangulation`.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        The coordinates, float64 or float32 (other real types are converted). A
        C-contiguous float64 array is used in place, without a copy; every coordinate
        must be finite.
    threads : int or None
        Threads that turn the kernel's tetrahedra into the returned arrays (``None``: all
        cores). The insertion itself runs on one thread (the in-memory kernel is
        sequential); for parallel triangulation of large inputs use :func:`run`.
    dtype : numpy integer type, np.int64 (default) or np.int32
        The type of the index arrays (``simplices``, ``neighbors``, ``convex_hull``,
        ``duplicates``). np.int32 halves their memory.

    Returns
    -------
    Triangulation
        ``simplices`` (M, 4) in the input's point order, positively oriented;
        ``neighbors`` (SciPy's convention: ``neighbors[i, j]`` is opposite vertex ``j``,
        -1 on the hull); ``convex_hull`` (H, 3); ``duplicates`` (D, 2) rows
        ``[merged input index, kept index]``; ``points``. The arrays own their memory
        (no copy is made on the way from C++).

    Raises
    ------
    InputError (a ValueError)
        Non-finite coordinates, or fewer than 4 affinely independent distinct points.
    UsageError (a ValueError)
        A wrong shape, dtype or ``threads``, or more points than the in-memory kernel
        holds (about 1.5e8; use :func:`run`).

    Notes
    -----
    The computation releases the GIL and runs on a thread of its own while the calling
    thread handles signals: Ctrl-C stops it within a few thousand insertions and raises
    ``KeyboardInterrupt``. Of several exact copies of a point, the first in the input
    is the vertex and the others are listed in ``duplicates`` (as :func:`run` keeps
    the first). It is the kernel the out-of-core pipeline runs on
    each of its windows (Bowyer-Watson with a biased randomized insertion order along a
    Hilbert curve). Peak memory is about 250 bytes per point plus the returned arrays
    (4 x 8 bytes per simplex each for ``simplices`` and ``neighbors`` in int64, about
    6.5 simplices per point on uniform data).

    Examples
    --------
    >>> import numpy as np, tetstream
    >>> pts = np.random.default_rng(1).random((1000, 3))
    >>> tri = tetstream.delaunay(pts)
    >>> tri.simplices.shape[1], bool((tri.volumes() > 0).all())
    (4, True)
    """
    if periodic is not None:
        return _periodic_delaunay(points, periodic, threads)
    arr = np.asarray(points)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise UsageError(f"points must be an (N, 3) array, got shape {arr.shape}")
    if arr.dtype.kind not in "fiu":
        raise UsageError(f"points must be real numbers, got dtype {arr.dtype}")
    pts = np.ascontiguousarray(arr, dtype=np.float64)
    index_dtype = np.dtype(dtype)
    if index_dtype not in (np.dtype(np.int64), np.dtype(np.int32)):
        raise UsageError(f"dtype must be np.int64 or np.int32, got {index_dtype}")
    d = _core.delaunay(pts, index_dtype.name, _threads(threads))
    return Triangulation(pts, d["simplices"], d["neighbors"], d["convex_hull"], d["duplicates"])


# ---------------------------------------------------------------------------------------
# Out of core


_MESH_EXTENSIONS = (".vtu", ".vtk", ".mesh", ".msh", ".node", ".xdmf")


def _spill_matches(path: str, arr: np.ndarray) -> bool:
    """Whether the file at path holds exactly arr's bytes (compared in pieces)."""
    if os.path.getsize(path) != arr.nbytes:
        return False
    on_disk = np.memmap(path, dtype=arr.dtype, mode="r", shape=arr.shape)
    step = max(1, (64 << 20) // max(1, arr.itemsize * 3))
    return all(np.array_equal(on_disk[i:i + step], arr[i:i + step]) for i in range(0, len(arr), step))


def run(source: Union[PathLike, Sequence[PathLike], ArrayLike], output: PathLike, memory: Union[str, int] = "4G",
        threads: Optional[int] = None, progress: Progress = True, resume: bool = False, **options: Any) -> Dict[str, Any]:
    """Triangulate out of core into a ``.tets`` container (``tetstream run``).

    Parameters
    ----------
    source : path, list of paths, or array_like (N, 3)
        A point file (raw ``.f64``/``.f32``, PLY, ``.npy``, text, LAS, HDF5; see
        docs/inputs.md), several files read in order as one input, or an array. A path
        that is no file and holds ``*``, ``?`` or ``[`` is a glob, expanded as the CLI
        does (its matches in natural order: ``snap.2`` before ``snap.10``). An array
        is written to a raw file first (float32 stays float32, anything else becomes
        float64): with checkpoints on (the default) to ``OUTPUT.input.f64`` (or
        ``.f32``) beside the output (in ``tmpdir`` when given), kept when the job fails
        so that ``resume=True`` with the same array continues it (another array is
        refused), and removed when it succeeds; with ``checkpoint=False`` to a private
        temporary file, always removed.
    output : path
        The container to write (``.tets``). Written as ``OUTPUT.partial`` and renamed
        at the end: nothing incomplete is ever left under this name. A mesh name
        (``.vtu``, ``.vtk``, ``.mesh``, ``.msh``, ``.node``, ``.xdmf``) gets that format:
        the job writes ``OUTPUT.tets`` beside it, converts it, and removes it.
    memory : str or int
        The memory budget, e.g. ``"512M"``, ``"4G"``, or bytes; at least 64M.
    threads : int or None
        Worker threads; ``None``: all cores.
    progress : bool or callable
        Log the job's progress and summary (True, the default) through the logger
        ``"tetstream"`` of :mod:`logging` (shown on ``sys.stderr`` when logging is not
        configured); False: warnings only. A callable is also called with each progress
        line (a str).
    resume : bool
        Continue the job checkpointed for this output (after a crash, kill, Ctrl-C or a
        full disk); the result has the same bytes as an uninterrupted run.
    **options
        The CLI's other ``run`` options, ``-`` spelled ``_``: ``tmpdir``, ``buffer``,
        ``zone_points``, ``zones``, ``checkpoint`` (True, False or a directory),
        ``force``, ``labels`` (``"bricks"``, the default, or ``"sorted"``: the
        container's label order, docs/format.md §3.4), and the point-input options ``format``, ``type``, ``stride``,
        ``offset``, ``byte_order``, ``columns`` (1-based, a list), ``properties``,
        ``datasets``; ``periodic`` (L, (Lx, Ly, Lz) or ``"auto"``: the triangulation of
        the flat torus, docs/periodic.md) and ``periodic_outside`` (``"wrap"`` or
        ``"refuse"``). An unknown name raises TypeError.

    Returns
    -------
    dict
        The summary ``tetstream run --json`` prints: ``points``, ``duplicates``,
        ``tets``, ``segments``, ``zones``, ``output_bytes``, ``seconds`` (a dict), ...
        (for an array, ``input`` names the file it was written to).

    Raises
    ------
    InputError, UsageError (ValueError)
        Bad input data; bad options; a checkpoint exists for this output (pass
        ``resume=True`` or ``force=True``) or belongs to another input.
    IoError (OSError)
        Unreadable input, full disk, ...; the checkpoint is kept: fix the cause and
        resume.
    KeyboardInterrupt
        Ctrl-C: the job stops within a batch; the checkpoint is kept.

    The job runs with the GIL released, on a thread of its own; the calling thread
    waits for it and handles Ctrl-C. One job at a time per process.
    """
    opts = dict(options)
    output = os.fspath(output)
    mesh = None
    if os.path.splitext(output)[1].lower() in _MESH_EXTENSIONS:
        mesh, output = output, output + ".tets"
        # That container is the job's own, removed after the conversion: a file already
        # there is somebody else's, never replaced or removed.
        if os.path.lexists(output):
            raise UsageError(f"{output} exists: run() to {mesh} writes its container there and removes it "
                             f"after the conversion (move it away, or write {output} and convert it)")
    spill: Optional[str] = None
    remove_spill_always = False
    wrote_spill = False
    if isinstance(source, (str, bytes, os.PathLike)):
        inputs = _core.expand_inputs([os.fsdecode(source)])
    elif isinstance(source, (list, tuple)) and source and all(isinstance(s, (str, os.PathLike)) for s in source):
        inputs = _core.expand_inputs([os.fspath(s) for s in source])
    else:
        arr = np.asarray(source)
        if arr.ndim != 2 or arr.shape[1] != 3 or arr.dtype.kind not in "fiu":
            raise UsageError(f"source must be a path, a list of paths or an (N, 3) array; got {type(source).__name__}"
                             f" of shape {getattr(arr, 'shape', None)}")
        arr = np.ascontiguousarray(arr, dtype=np.float32 if arr.dtype == np.float32 else np.float64)
        ext = ".f32" if arr.dtype == np.float32 else ".f64"
        directory = os.fspath(opts.get("tmpdir") or os.path.dirname(os.path.abspath(output)))
        checkpointed = opts.get("checkpoint", True) is not False
        if checkpointed:
            spill = os.path.join(directory, os.path.basename(output) + ".input" + ext)
            if os.path.lexists(spill):
                # The input of an earlier job on this output, kept for its resumption. It
                # is never rewritten for resume=True (its fingerprint, modification time
                # included, identifies the checkpointed job's input).
                if resume:
                    if not _spill_matches(spill, arr):
                        raise UsageError(f"{spill} holds other points than `source`: the checkpointed job was "
                                         f"started with other points (force=True starts over)")
                elif opts.get("force"):
                    os.remove(spill)
                else:
                    raise UsageError(f"{spill} exists (the input of an earlier job on this output): resume=True "
                                     f"continues that job, force=True starts over")
            if not os.path.lexists(spill):
                _core.spill(spill, arr)  # SPILL.partial, renamed when complete; refused if there
                wrote_spill = True
        else:
            import secrets
            spill = os.path.join(directory, f".tetstream-input-{os.getpid()}-{secrets.token_hex(8)}{ext}")
            _core.spill(spill, arr)
            remove_spill_always = True
        inputs = [spill]
    try:
        text = _core.run(inputs[0], inputs[1:], output, _core.parse_memory(memory), _threads(threads), bool(progress),
                         bool(resume), opts, _emitter(progress))
    except BaseException as e:
        # Bad input or options leave nothing to resume: the spill this call wrote goes
        # too, so that the corrected call is not refused.
        if spill and (remove_spill_always or (wrote_spill and isinstance(e, (InputError, UsageError)))):
            os.remove(spill)
        raise
    if spill:
        os.remove(spill)
    summary = json.loads(text)
    if mesh is not None:
        _core.convert(output, mesh)
        os.remove(output)
        summary["mesh"] = mesh
    return summary


# ---------------------------------------------------------------------------------------
# Reading a container


class TetFile:
    """A ``.tets`` container opened for reading (see :func:`open`).

    The file is memory-mapped read-only; arrays are decoded on demand and owned by the
    caller (no copy beyond the decode). Labels (the default in tets) index
    :attr:`points`, which are in the container's order (sorted along the longest axis,
    duplicates merged); ``original_ids=True`` gives indices into the job's input instead
    (:attr:`original_ids` maps one to the other).

    A periodic container (``run(..., periodic=L)``, docs/periodic.md) reads the same
    way, and its tets need their vertex offsets too: :attr:`periodic` is its period,
    :meth:`frame_offsets` each frame's offsets (vertex j of a tet stands at
    ``points[label] + offsets[j] * period``).
    """

    def __init__(self, path: PathLike):
        self._reader = _core.Reader(os.fspath(path))
        self._header = self._reader.header()
        self._points: Optional[np.ndarray] = None
        self._ids: Optional[np.ndarray] = None

    @property
    def path(self) -> str:
        return self._header["path"]

    @property
    def n_points(self) -> int:
        """Number of points (distinct: duplicates of the input were merged)."""
        return int(self._header["points"])

    @property
    def n_tets(self) -> int:
        """Number of tetrahedra."""
        return int(self._header["tets"])

    @property
    def n_frames(self) -> int:
        """Number of frames (the container's compressed blocks of tets)."""
        return int(self._header["frames"])

    @property
    def periodic(self) -> Optional[Tuple[float, float, float]]:
        """The period (Lx, Ly, Lz) of a periodic container; None for a plain one."""
        p = self._header["periodic"]
        return None if p is None else tuple(p)

    def frame_offsets(self, k: int) -> np.ndarray:
        """A periodic container's frame ``k``: each tet's vertex offsets in periods,
        relative to its first vertex, as a (t, 4, 3) int8 array matching :meth:`frame`."""
        return self._reader.frame_offsets(k)

    @property
    def header(self) -> Dict[str, Any]:
        """The container's header: counts, bounding box, coordinate type, tool, options."""
        return dict(self._header)

    @property
    def points(self) -> np.ndarray:
        """(n_points, 3) float64 coordinates, indexed by label (read once, then cached)."""
        if self._points is None:
            self._points = self._reader.points(0, self.n_points, True, False)[0]
        return self._points

    @property
    def original_ids(self) -> np.ndarray:
        """(n_points,) int64: each label's index in the job's input (read once, cached)."""
        if self._ids is None:
            self._ids = self._reader.points(0, self.n_points, False, True)[1]
        return self._ids

    def frame_index(self) -> Dict[str, np.ndarray]:
        """Per frame: ``first_tet``, ``tet_count``, ``min_label``, ``max_label`` (int64 arrays)."""
        return self._reader.frame_index()

    def frame(self, k: int, original_ids: bool = False, dtype: npt.DTypeLike = np.int64) -> np.ndarray:
        """Frame ``k``'s tets as a (t, 4) array (labels, or original ids)."""
        return self._reader.frame(k, original_ids, _narrow(dtype), False)

    def frames(self, original_ids: bool = False, dtype: npt.DTypeLike = np.int64) -> Iterator[np.ndarray]:
        """Iterate over the tets frame by frame, as (k, 4) arrays in stored order.

        ``original_ids``: indices into the job's input instead of labels. ``dtype``:
        np.int64 (default) or np.uint32 (the container's 32-bit labels as they are, half
        the memory). The pages of each frame are handed back after it is decoded, so a
        pass over a file larger than memory keeps a small resident set.
        """
        narrow = _narrow(dtype)
        for k in range(self.n_frames):
            yield self._reader.frame(k, original_ids, narrow, True)

    def tets(self, start: int = 0, stop: Optional[int] = None, original_ids: bool = False) -> np.ndarray:
        """Tets with ordinals ``start`` to ``stop - 1`` (stored order) as an (n, 4) int64 array.

        Random access: the frame index finds the frames that hold them and only those
        are decoded. Negative positions count from the end, as in a slice.
        """
        start, stop, _ = slice(start, stop).indices(self.n_tets)
        return self._reader.tets(start, max(start, stop), original_ids)

    def __getitem__(self, index: Union[int, slice]) -> np.ndarray:
        """``f[k]``: tet ``k`` (stored order; negative counts from the end) as a (4,) array
        of labels; ``f[a:b]``: tets ``a`` to ``b - 1`` as an (n, 4) array."""
        if isinstance(index, slice):
            if index.step not in (None, 1):
                raise TypeError("a TetFile's slices take no step: f[1000:2000]")
            return self.tets(index.start or 0, index.stop)
        try:
            k = operator.index(index)
        except TypeError:
            raise TypeError(f"a TetFile is indexed by an int or a slice of tets, not {type(index).__name__}") from None
        n = self.n_tets
        if not -n <= k < n:
            raise IndexError(f"tet index {k} out of range for {n} tets")
        k %= n
        return self.tets(k, k + 1)[0]

    def __len__(self) -> int:
        return self.n_tets

    def to_meshio(self, original_ids: bool = False, points: Optional[ArrayLike] = None,
                  point_data: Optional[Dict[str, ArrayLike]] = None):
        """The whole triangulation as a ``meshio.Mesh`` (points and one "tetra" block).

        Requires meshio. The mesh carries the point data ``"original_id"`` (each point's
        index in the job's input) and the arrays of ``point_data`` (name -> array with
        one row per mesh point).

        With ``original_ids``, the mesh's points are the input's, in its order, and the
        tets index them: the exact duplicates that ``run`` merged are points of their
        own (used by no tet) at their real coordinates. Those coordinates are not in
        the container: they come from ``points`` (the input as an (input_count, 3)
        array, checked against the container's points) or, without it, from the input
        file the container names, read again; ``UsageError`` when neither is at hand
        (the input was an array: pass it). With no duplicates nothing is read.
        """
        try:
            import meshio
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("to_meshio() needs meshio (pip install meshio, or apt install python3-meshio)") from e
        tets = self.tets(0, self.n_tets, original_ids)
        ids = self.original_ids
        data: Dict[str, np.ndarray] = {}
        if not original_ids:
            xyz = self.points
            data["original_id"] = ids
        else:
            total = max(int(self.header.get("input_points") or 0), int(ids.max()) + 1 if len(ids) else 0)
            if points is not None:
                xyz = np.ascontiguousarray(np.asarray(points, dtype=np.float64))
                if xyz.shape != (total, 3):
                    raise UsageError(f"points: expected the job's input, shape ({total}, 3), got {xyz.shape}")
                if not np.array_equal(xyz[ids], self.points):
                    raise UsageError("points: not the input of this container (its points differ)")
            elif total == len(ids):
                xyz = np.empty((total, 3))
                xyz[ids] = self.points
            else:
                xyz = self._input_points(total)
            data["original_id"] = np.arange(len(xyz), dtype=np.int64)
        for name, values in (point_data or {}).items():
            arr = np.asarray(values)
            if len(arr) != len(xyz):
                raise UsageError(f"point_data[{name!r}]: {len(arr)} rows for {len(xyz)} points")
            data[name] = arr
        return meshio.Mesh(xyz, [("tetra", tets)], point_data=data)

    def _input_points(self, total: int) -> np.ndarray:
        """The job's input points, read again from the file the header names."""
        try:
            source = json.loads(self.header.get("options") or "{}").get("input")
        except ValueError:
            source = None
        if not source or source == "-" or not os.path.exists(source):
            raise UsageError(f"{self.path}: {total - self.n_points} merged duplicate(s) have no coordinates in the "
                             f"container and its input ({source or 'unknown'}) cannot be read: pass points=")
        xyz = _core.read_points(source)
        if len(xyz) != total or not np.array_equal(xyz[self.original_ids], self.points):
            raise UsageError(f"{self.path}: {source} is no longer this container's input: pass points=")
        return xyz

    def close(self) -> None:
        """Unmap the file (arrays already returned stay valid)."""
        self._reader.close()

    def __enter__(self) -> "TetFile":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<tetstream.TetFile {self.path!r}: {self.n_points} points, {self.n_tets} tets, {self.n_frames} frames>"


def _narrow(dtype: Any) -> bool:
    d = np.dtype(dtype)
    if d == np.dtype(np.int64):
        return False
    if d == np.dtype(np.uint32):
        return True
    raise UsageError(f"dtype must be np.int64 or np.uint32, got {d}")


def open(path: PathLike) -> TetFile:  # noqa: A001 - the module's verb, like gzip.open
    """Open a ``.tets`` container for reading; see :class:`TetFile`.

    Raises InputError (a ValueError) when the file is not a container or is damaged
    (the footer, index and header are checked here; each frame's checksum when it is
    read), IoError (an OSError) when it cannot be read.
    """
    return TetFile(path)


def verify(path: PathLike, memory: Union[str, int] = "1G", sample: float = 1.0, seed: int = 1,
           tmpdir: Optional[PathLike] = None, volume_tolerance: float = 1e-9, max_listed: int = 10,
           progress: Progress = False, check: bool = True, threads: Optional[int] = None) -> Dict[str, Any]:
    """Check that a container holds the Delaunay triangulation of its points (``tetstream verify``).

    Exact orientation, facet pairing, local Delaunay on every interior facet, a closed
    convex hull, coverage of every point, Euler characteristic and volume (docs/verify.md).
    ``sample`` < 1 checks a seeded fraction (a quick look). Out of core within ``memory``;
    spills go to ``tmpdir``; ``threads``: None for all cores.

    Returns the report ``tetstream verify --json`` prints (``valid``, ``violations``,
    ``violation_counts``, ``listed``, ...). With ``check`` (the default) a failed
    verification raises :class:`VerificationError` (a ValueError) carrying the report as
    ``.report``; with ``check=False`` the report is returned either way.
    """
    p = os.fspath(path)
    text = _core.verify(p, memory, float(sample), int(seed), os.fspath(tmpdir) if tmpdir else "",
                        float(volume_tolerance), int(max_listed), bool(progress), _threads(threads),
                        _emitter(progress))
    report = json.loads(text)
    if check and not report["valid"]:
        raise VerificationError(f"{p}: verification failed: {report['violations']} violation(s)", report)
    return report


# ---------------------------------------------------------------------------------------
# Fields


def _grid_shape(grid: Union[None, int, Sequence[int]]) -> tuple:
    if grid is None:
        return (0, 0, 0)
    if isinstance(grid, (int, np.integer)):
        grid = (int(grid),) * 3
    g = tuple(int(k) for k in grid)
    if len(g) != 3 or min(g) < 1:
        raise UsageError(f"grid must be N or (NX, NY, NZ) with positive counts, got {grid!r}")
    return g


def field(source: Union[PathLike, Triangulation], density: bool = True, voronoi_volume: bool = False,
          neighbours: bool = False, grid: Union[None, int, Sequence[int]] = None,
          box: Optional[Sequence[float]] = None, hull: str = "nan", mass: Union[None, PathLike, ArrayLike] = None,
          dtype: npt.DTypeLike = np.float64, index_dtype: str = "auto", memory: Union[str, int] = "1G",
          tmpdir: Optional[PathLike] = None, threads: Optional[int] = None, progress: Progress = False,
          neighbors: Optional[bool] = None) -> Dict[str, Any]:
    """Per-point fields of a triangulation: ``tetstream field`` from Python.

    Parameters
    ----------
    source : path or Triangulation
        A ``.tets`` container (computed out of core within ``memory``, exactly as the
        CLI does, through temporary files removed before returning), or the result of
        :func:`delaunay` (computed in memory with the same per-tet geometry).
    density : bool
        The DTFE density ``rho_i = 4 m_i / (sum of the volumes of the tets at i)``.
    voronoi_volume : bool
        The volume of each point's Voronoi cell; +inf on the hull.
    neighbours : bool
        The Delaunay neighbours as a ``scipy.sparse.csr_matrix`` of int8 ones: row i
        holds point i's neighbours (``neighbors=`` is the same).
    grid : int or (NX, NY, NZ)
        The DTFE density at the cell centres of a grid over ``box`` (default: the
        points' bounding box), shape (NX, NY, NZ); NaN outside the hull.
    box : (xmin, ymin, zmin, xmax, ymax, zmax)
    hull : "nan" or "open"
        Density at hull points: NaN (default), or the same formula over their open star.
    mass : path or array_like
        Per-point masses in the input's order (one per input point, duplicates
        included); default 1.
    dtype : np.float64 or np.float32
        The density, Voronoi and grid arrays.
    index_dtype, memory, tmpdir, threads
        As the CLI's ``--index-dtype``, ``--memory``, ``--tmpdir``, ``--threads`` (a
        container only; ``threads`` also for a Triangulation).
    progress : bool or callable
        As for :func:`run` (through :mod:`logging`).

    Returns
    -------
    dict
        ``"density"``, ``"voronoi_volume"``, ``"neighbours"``, ``"grid"`` (those asked
        for) and ``"summary"`` (the counts and totals of ``tetstream --json field``).
        For a container, entry i belongs to the point with the i-th smallest original
        index (the input's order, less the exact duplicates ``run`` merged;
        ``"original_ids"`` lists them) and the neighbour matrix's columns are original
        indices. For a Triangulation, entries are in the input's order, one per input
        point: a merged duplicate gets NaN and no neighbours.

    Raises
    ------
    InputError, UsageError, IoError, KeyboardInterrupt
        As :func:`run`.
    """
    if neighbors is not None:
        neighbours = neighbours or bool(neighbors)
    shape = _grid_shape(grid)
    if hull not in ("nan", "open"):
        raise UsageError(f"hull must be 'nan' or 'open', not {hull!r}")
    out_dtype = np.dtype(dtype)
    if out_dtype not in (np.dtype(np.float64), np.dtype(np.float32)):
        raise UsageError(f"dtype must be np.float64 or np.float32, got {out_dtype}")
    if index_dtype not in ("auto", "int64"):
        raise UsageError(f"index_dtype must be 'auto' or 'int64', not {index_dtype!r}")
    if box is not None:
        box = tuple(float(v) for v in box)
        if len(box) != 6:
            raise UsageError(f"box must be (xmin, ymin, zmin, xmax, ymax, zmax), got {box!r}")
    if not (density or voronoi_volume or neighbours or shape[0]):
        raise UsageError("field: nothing to compute (density, voronoi_volume, neighbours or grid)")
    if isinstance(source, Triangulation):
        return _field_in_memory(source, density, voronoi_volume, neighbours, shape, box, hull, mass, out_dtype,
                                _threads(threads))
    path = os.fspath(source)
    import scipy.sparse

    with tempfile.TemporaryDirectory(prefix="tetstream-field-", dir=os.fspath(tmpdir) if tmpdir else None) as work:
        mass_path = ""
        if mass is not None:
            if isinstance(mass, (str, bytes, os.PathLike)):
                mass_path = os.fsdecode(mass)
            else:
                # Raw float64 (the mass file may be raw or .npy), written the one way the
                # package writes a file: claimed, to a partial name, renamed when complete.
                mass_path = os.path.join(work, "mass.f64")
                _core.spill(mass_path, np.ascontiguousarray(np.asarray(mass, dtype="<f8")))
        summary = _core.field(path, os.path.join(work, "f"), bool(density), bool(voronoi_volume), bool(neighbours),
                              shape, box, hull, out_dtype.name, index_dtype == "int64", mass_path, memory,
                              os.fspath(tmpdir) if tmpdir else "", _progress_flag(progress), _threads(threads),
                              _emitter(progress))
        files = summary.pop("files")
        result: Dict[str, Any] = {}
        if "density" in files:
            result["density"] = np.load(files["density"])
        if "voronoi" in files:
            result["voronoi_volume"] = np.load(files["voronoi"])
        if "grid" in files:
            result["grid"] = np.load(files["grid"])
        if "neighbours.offsets" in files:
            indptr = np.load(files["neighbours.offsets"])
            indices = np.load(files["neighbours.indices"])
            with open(path) as f:
                ids = np.sort(f.original_ids)
                columns = max(int(f.header.get("input_points") or 0), int(ids[-1]) + 1 if len(ids) else 0)
            result["neighbours"] = scipy.sparse.csr_matrix((np.ones(len(indices), dtype=np.int8), indices, indptr),
                                                           shape=(len(indptr) - 1, columns))
            result["original_ids"] = ids
    if "original_ids" not in result:
        with open(path) as f:
            result["original_ids"] = np.sort(f.original_ids)
    result["summary"] = summary
    return result


def _progress_flag(progress: Progress) -> bool:
    return bool(progress) or callable(progress)


def _field_in_memory(tri: Triangulation, density: bool, voronoi_volume: bool, neighbours: bool, shape: tuple,
                     box: Optional[tuple], hull: str, mass: Any, out_dtype: np.dtype, threads: int) -> Dict[str, Any]:
    n = tri.npoints
    m = np.ones(n) if mass is None else np.asarray(np.load(os.fspath(mass)) if isinstance(mass, (str, os.PathLike))
                                                      else mass, dtype=np.float64).reshape(-1)
    if len(m) != n or not np.isfinite(m).all():
        raise InputError(f"mass: expected {n} finite values, one per input point, got {len(m)}")
    want_rho = density or shape[0] > 0
    star, cell, on_hull = _core.field_sums(tri.points, tri.simplices, tri.neighbors, bool(voronoi_volume), threads)
    vertex = star > 0
    result: Dict[str, Any] = {}
    summary: Dict[str, Any] = {"points": int(vertex.sum()), "hull_points": int(on_hull.sum()),
                               "tets": tri.nsimplex, "hull_volume": float(tri.volumes().sum()),
                               "total_mass": float(m[vertex].sum())}
    rho = None
    if want_rho:
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = np.where(vertex, 4.0 * m / np.where(vertex, star, 1.0), np.nan)
        if hull == "nan":
            rho[on_hull] = np.nan
        if density:
            result["density"] = rho.astype(out_dtype, copy=False)
    if voronoi_volume:
        vol = np.where(vertex, cell, np.nan)
        summary["interior_voronoi_volume"] = float(vol[vertex & ~on_hull].sum())
        vol[on_hull] = np.inf
        result["voronoi_volume"] = vol.astype(out_dtype, copy=False)
    if neighbours:
        import scipy.sparse
        indptr, indices = tri.vertex_neighbor_vertices
        result["neighbours"] = scipy.sparse.csr_matrix((np.ones(len(indices), dtype=np.int8), indices, indptr),
                                                       shape=(n, n))
        summary["neighbour_entries"] = int(len(indices))
    if shape[0]:
        lo = np.array(box[:3]) if box else tri.min_bound
        hi = np.array(box[3:]) if box else tri.max_bound
        if not (np.isfinite(lo).all() and np.isfinite(hi).all() and (lo < hi).all()):
            raise UsageError(f"grid: the box {tuple(lo)}..{tuple(hi)} is flat or not finite: give box=")
        axes = [lo[k] + (np.arange(shape[k]) + 0.5) * (hi[k] - lo[k]) / shape[k] for k in range(3)]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        where = tri.find_simplex(centres)
        inside = where >= 0
        values = np.full(len(centres), np.nan)
        s = where[inside]
        t = tri.transform[s]
        c = np.einsum("ijk,ik->ij", t[:, :3, :], centres[inside] - t[:, 3, :])
        bary = np.concatenate([c, 1.0 - c.sum(axis=1, keepdims=True)], axis=1)
        values[inside] = np.einsum("ij,ij->i", bary, rho[tri.simplices[s]])
        result["grid"] = values.reshape(shape).astype(out_dtype, copy=False)
        summary["grid_points"] = int(len(centres))
        summary["grid_inside"] = int(inside.sum())
    result["summary"] = summary
    return result
