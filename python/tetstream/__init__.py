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

Errors: bad input or options raise :class:`InputError` / :class:`UsageError` (both
``ValueError``), I/O failures :class:`IoError` (an ``OSError``), and Ctrl-C during
:func:`run` or :func:`verify` stops the job and raises ``KeyboardInterrupt`` (a
checkpointed run keeps its checkpoint: call ``run(..., resume=True)``).
"""
from __future__ import annotations

import builtins
import json
import os
from typing import Any, Dict, Iterator, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

from . import _core
from ._core import InputError, IoError, UsageError

__all__ = [
    "delaunay",
    "Triangulation",
    "run",
    "open",
    "TetFile",
    "verify",
    "InputError",
    "UsageError",
    "IoError",
    "VerificationError",
]
__version__ = "0.1.0"

PathLike = Union[str, "os.PathLike[str]"]
ArrayLike = npt.ArrayLike  # anything np.asarray turns into an (N, 3) array


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
        ``i`` was merged into point ``j`` (a vertex). Every input point is either a vertex
        of some simplex or the first column of one row. Sorted by ``i``.

    The triangulation is exact: every predicate is evaluated exactly, and degenerate
    inputs (cospherical or coplanar points, grids) are resolved by one symbolic
    perturbation keyed by the input index, so the result is a valid triangulation of the
    convex hull whatever the input. (The out-of-core :func:`run` keys it by the sorted
    order instead; on degenerate inputs the two may choose different, equally Delaunay,
    tetrahedra.)
    """

    __slots__ = ("points", "simplices", "neighbors", "convex_hull", "duplicates")

    def __init__(self, points: np.ndarray, simplices: np.ndarray, neighbors: np.ndarray,
                 convex_hull: np.ndarray, duplicates: np.ndarray):
        self.points = points
        self.simplices = simplices
        self.neighbors = neighbors
        self.convex_hull = convex_hull
        self.duplicates = duplicates

    @property
    def npoints(self) -> int:
        """Number of input points (vertices and duplicates)."""
        return int(self.points.shape[0])

    @property
    def nsimplex(self) -> int:
        """Number of tetrahedra."""
        return int(self.simplices.shape[0])

    def volumes(self) -> np.ndarray:
        """The (positive) volume of each simplex, in floating point."""
        p = self.points[self.simplices]
        a, b, c = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
        return np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0

    def __len__(self) -> int:
        return self.nsimplex

    def __repr__(self) -> str:
        return (f"<tetstream.Triangulation: {self.npoints} points, {self.nsimplex} simplices, "
                f"{len(self.convex_hull)} hull facets, {len(self.duplicates)} duplicates>")


def delaunay(points: ArrayLike, threads: Optional[int] = None, dtype: npt.DTypeLike = np.int64) -> Triangulation:
    """Delaunay triangulation of 3D points, computed in memory with exact predicates.

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
    The computation releases the GIL. It is the kernel the out-of-core pipeline runs on
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


def _spill_matches(path: str, arr: np.ndarray) -> bool:
    """Whether the file at path holds exactly arr's bytes (compared in pieces)."""
    if os.path.getsize(path) != arr.nbytes:
        return False
    on_disk = np.memmap(path, dtype=arr.dtype, mode="r", shape=arr.shape)
    step = max(1, (64 << 20) // max(1, arr.itemsize * 3))
    return all(np.array_equal(on_disk[i:i + step], arr[i:i + step]) for i in range(0, len(arr), step))


def run(source: Union[PathLike, Sequence[PathLike], ArrayLike], output: PathLike, memory: Union[str, int] = "4G",
        threads: Optional[int] = None, progress: bool = True, resume: bool = False, **options: Any) -> Dict[str, Any]:
    """Triangulate out of core into a ``.tets`` container (``tetstream run``).

    Parameters
    ----------
    source : path, list of paths, or array_like (N, 3)
        A point file (raw ``.f64``/``.f32``, PLY, ``.npy``, text, LAS, HDF5; see
        docs/inputs.md), several files read in order as one input, or an array. An array
        is written to a raw file first (float32 stays float32, anything else becomes
        float64): with checkpoints on (the default) to ``OUTPUT.input.f64`` (or
        ``.f32``) beside the output (in ``tmpdir`` when given), kept when the job fails
        so that ``resume=True`` with the same array continues it (another array is
        refused), and removed when it succeeds; with ``checkpoint=False`` to a private
        temporary file, always removed.
    output : path
        The container to write (``.tets``). Written as ``OUTPUT.partial`` and renamed
        at the end: nothing incomplete is ever left under this name.
    memory : str or int
        The memory budget, e.g. ``"512M"``, ``"4G"``, or bytes; at least 64M.
    threads : int or None
        Worker threads; ``None``: all cores.
    progress : bool
        Log the job's progress and summary to stderr (as the CLI does); False: warnings
        only.
    resume : bool
        Continue the job checkpointed for this output (after a crash, kill, Ctrl-C or a
        full disk); the result has the same bytes as an uninterrupted run.
    **options
        The CLI's other ``run`` options, ``-`` spelled ``_``: ``tmpdir``, ``buffer``,
        ``zone_points``, ``zones``, ``checkpoint`` (True, False or a directory),
        ``force``, and the point-input options ``format``, ``type``, ``stride``,
        ``offset``, ``byte_order``, ``columns`` (1-based, a list), ``properties``,
        ``datasets``. An unknown name raises TypeError.

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
    spill: Optional[str] = None
    remove_spill_always = False
    wrote_spill = False
    if isinstance(source, (str, bytes, os.PathLike)):
        inputs = [os.fsdecode(source)]
    elif isinstance(source, (list, tuple)) and source and all(isinstance(s, (str, os.PathLike)) for s in source):
        inputs = [os.fspath(s) for s in source]
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
                         bool(resume), opts)
    except BaseException as e:
        # Bad input or options leave nothing to resume: the spill this call wrote goes
        # too, so that the corrected call is not refused.
        if spill and (remove_spill_always or (wrote_spill and isinstance(e, (InputError, UsageError)))):
            os.remove(spill)
        raise
    if spill:
        os.remove(spill)
    return json.loads(text)


# ---------------------------------------------------------------------------------------
# Reading a container


class TetFile:
    """A ``.tets`` container opened for reading (see :func:`open`).

    The file is memory-mapped read-only; arrays are decoded on demand and owned by the
    caller (no copy beyond the decode). Labels (the default in tets) index
    :attr:`points`, which are in the container's order (sorted along the longest axis,
    duplicates merged); ``original_ids=True`` gives indices into the job's input instead
    (:attr:`original_ids` maps one to the other).
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

    def __getitem__(self, index: slice) -> np.ndarray:
        if not isinstance(index, slice) or index.step not in (None, 1):
            raise TypeError("a TetFile is indexed by a slice of tets, e.g. f[1000:2000]")
        return self.tets(index.start or 0, index.stop)

    def __len__(self) -> int:
        return self.n_tets

    def to_meshio(self, original_ids: bool = False):
        """The whole triangulation as a ``meshio.Mesh`` (points and one "tetra" block).

        Requires meshio. With ``original_ids``, the points are put back in the input's
        order (duplicates of the input are absent, so an input index without a point
        gets NaN coordinates) and the tets index them.
        """
        try:
            import meshio
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("to_meshio() needs meshio (pip install meshio, or apt install python3-meshio)") from e
        tets = self.tets(0, self.n_tets, original_ids)
        if not original_ids:
            return meshio.Mesh(self.points, [("tetra", tets)])
        ids = self.original_ids
        pts = np.full((int(ids.max()) + 1 if len(ids) else 0, 3), np.nan)
        pts[ids] = self.points
        return meshio.Mesh(pts, [("tetra", tets)])

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
           progress: bool = False, check: bool = True, threads: Optional[int] = None) -> Dict[str, Any]:
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
                        float(volume_tolerance), int(max_listed), bool(progress), _threads(threads))
    report = json.loads(text)
    if check and not report["valid"]:
        raise VerificationError(f"{p}: verification failed: {report['violations']} violation(s)", report)
    return report
