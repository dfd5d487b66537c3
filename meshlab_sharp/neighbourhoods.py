"""Neighbourhoods at every scale: k nearest neighbours for clouds, k-rings for meshes.

A neighbourhood is stored flat, as in CSR sparse matrices: the neighbours of point
``i`` are ``indices[indptr[i]:indptr[i + 1]]``, the point itself included. For clouds
one kNN query at the largest scale serves every scale (the smaller ones are prefixes);
for meshes each ring is grown from the previous one.

Two backends give the same neighbourhoods (``tests/test_equivalence.py``): "numpy",
the reference (cKDTree; rings listed one level at a time), and "compiled" (the default
when built, :mod:`meshlab_sharp._kernels`), which builds a balanced kd-tree and
searches it, or a mesh's rings, in C.
With the compiled backend the neighbourhoods are not stored:
:func:`meshlab_sharp.multiscale.run_scales` searches them and uses them at once, point by
point, and ``at()`` computes a scale's table only when asked for.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from . import _header, _kernels
from .errors import InputError

#: Rows per block of kNN queries (bounds the temporary memory).
QUERY_BLOCK = 131072
#: Rows per block when the numpy reference grows the rings (bounds the temporaries).
RING_BLOCK = 16384
#: Coordinates up to 2**UNIT_RANGE in absolute value, and at least 2**-UNIT_RANGE for
#: the largest, are used as they are; others are scaled (:func:`unit_scale`).
UNIT_RANGE = _header.integer("UNIT_RANGE")
#: A point further from a cloud's median than this many of its spreads is far (and
#: points up to this far are used as they are: the unit then stays within UNIT_RANGE
#: of the bulk's); the spread is measured on at most FAR_SAMPLE points
#: (:func:`far_points`).
FAR_SPREADS = _header.real("FAR_SPREADS")  # 2**40
FAR_SAMPLE = _header.integer("FAR_SAMPLE")


@dataclass(frozen=True)
class Neighbourhood:
    """The neighbourhoods of all points at one scale, in CSR layout.

    Attributes
    ----------
    indptr : (n + 1,) int64
        Row pointers.
    indices : (nnz,) int32 or int64
        Neighbour indices; row ``i`` includes ``i`` itself.
    """

    indptr: np.ndarray
    indices: np.ndarray

    @property
    def sizes(self) -> np.ndarray:
        """Number of neighbours of each point, shape (n,)."""
        return np.diff(self.indptr)


def squared_distances(points: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """``dx*dx + dy*dy + dz*dz`` in this order, as the plugin computes it.

    Parameters
    ----------
    points : (..., 3) float64
    centres : (..., 3) float64, broadcastable against ``points``
    """
    d = points - centres
    return d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]


def unit_scale(points: np.ndarray) -> tuple[np.ndarray, int]:
    """``points * 2**-e`` and ``e``: coordinates of O(1) whatever the unit.

    Multiplying by a power of two is exact in IEEE arithmetic (short of underflow), so
    every ratio of distances, every normal and every decision is the one the unscaled
    points give where those do not underflow or overflow; on the scaled points (the
    largest absolute coordinate in [0.5, 1)) no squared distance, area or covariance
    does, whatever the unit (1e-300 to 1e300). When the largest absolute coordinate
    already lies in [2**-100, 2**100) nothing in the detection can underflow or overflow
    either (squared distances stay above 2**-306, covariances far from LAPACK's
    rescaling bounds), so scaling would change no bit: the points are returned as they
    are (``e = 0``), which saves a copy. No translation: it would round.

    Parameters
    ----------
    points : (n, 3) float64
        Finite coordinates.

    Returns
    -------
    scaled : (n, 3) float64
        A new array, or ``points`` itself when ``e`` is 0.
    e : int
        ``np.ldexp(scaled, e)`` gives ``points`` back.
    """
    largest = max(float(points.max()), -float(points.min())) if points.size else 0.0
    e = unit_exponent(largest)
    return (np.ldexp(points, -e), e) if e else (points, 0)


def unit_exponent(largest: float) -> int:
    """The ``e`` of :func:`unit_scale` for points whose largest absolute coordinate is
    ``largest`` (finite, >= 0): 0 when it lies in [2**-UNIT_RANGE, 2**UNIT_RANGE) or is
    0, else the exponent that brings it into [0.5, 1)."""
    e = math.frexp(largest)[1]
    return 0 if largest == 0.0 or -UNIT_RANGE < e <= UNIT_RANGE else e


def far_points(points: np.ndarray) -> np.ndarray | None:
    """The points of a cloud that lie far from all the others, or None when none does.

    A point is far when one of its coordinates lies more than ``FAR_SPREADS`` times the
    bulk's spread from the bulk's median: the spread is the largest interquartile range
    of a coordinate, both taken over at most ``FAR_SAMPLE`` points evenly spread through
    the input (the same points whatever the machine). Such a point (a corrupted number
    in a file, 1e300 away) has no neighbourhood of its own, and kept it would set the
    coordinates' unit (:func:`unit_scale`): the bulk would shrink to where its squared
    distances underflow. No real scan holds a point 2**40 times its own extent away.

    Parameters
    ----------
    points : (n, 3) float64
        Finite coordinates.

    Returns
    -------
    (n,) bool or None
        True for the far points; None when there are none (most inputs: one pass over
        the bounds decides it).
    """
    n = len(points)
    bulk = far_reach(points[:: far_step(n)])
    if bulk is None:
        return None
    median, reach = bulk
    lo = np.array([points[:, i].min() for i in range(3)])
    hi = np.array([points[:, i].max() for i in range(3)])
    if max(float((hi - median).max()), float((median - lo).max())) <= reach:
        return None
    return is_far(points, median, reach)


def far_step(n: int) -> int:
    """The step between the points :func:`far_points` measures the bulk on (n points:
    every ``far_step(n)``-th from the first, at most ``FAR_SAMPLE``)."""
    return max(1, -(-n // FAR_SAMPLE))


def far_reach(sample: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The bulk's median (3,) and how far from it a point is far, from the
    :func:`far_step` sample (s, 3); None when the sample has no spread (or no point)."""
    if len(sample) == 0:
        return None
    low, median, high = np.quantile(sample, [0.25, 0.5, 0.75], axis=0)
    reach = FAR_SPREADS * float((high - low).max())
    return None if reach == 0.0 else (median, reach)


def is_far(points: np.ndarray, median: np.ndarray, reach: float) -> np.ndarray:
    """(n,) bool: the points (n, 3) with a coordinate further than ``reach`` from the
    ``median``'s."""
    far = np.zeros(len(points), bool)
    for i in range(3):
        far |= np.abs(points[:, i] - median[i]) > reach
    return far


def knn(points: np.ndarray, k: int, *, workers: int = -1) -> np.ndarray:
    """The k nearest neighbours of every point, itself included, in a fixed order.

    Neighbours are sorted by squared distance, ties broken by the lower index, so the
    first ``j`` columns are the j-nearest neighbourhood for every ``j <= k``, exactly as
    ALGORITHM.md defines it, whatever order the kd-tree returns tied points in.

    Parameters
    ----------
    points : (n, 3) float64
        Distinct points, ``n >= k``.
    k : int
        Neighbourhood size.
    workers : int, default -1
        Threads for the kd-tree query (-1: all cores).

    Returns
    -------
    (n, k) int32 or int64
        Neighbour indices, row ``i`` starting with ``i``.
    """
    n = len(points)
    if not 1 <= k <= n:
        raise InputError(f"k = {k} nearest neighbours needs at least {k} points, got {n}")
    dtype = np.int32 if n < 2**31 else np.int64
    tree = cKDTree(points)
    out = np.empty((n, k), dtype=dtype)
    for start in range(0, n, QUERY_BLOCK):
        rows = np.arange(start, min(start + QUERY_BLOCK, n))
        out[rows] = _knn_block(tree, points, rows, k, workers)
    return out


def _knn_block(
    tree: cKDTree, points: np.ndarray, rows: np.ndarray, k: int, workers: int
) -> np.ndarray:
    """kNN of ``points[rows]`` with exact (distance, index) ordering; see :func:`knn`."""
    n = len(points)
    kq = min(k + 1, n)
    _, idx = tree.query(points[rows], kq, workers=workers)
    idx = idx.reshape(len(rows), kq)
    d2 = squared_distances(points[idx], points[rows, None, :])
    order = np.lexsort((idx, d2), axis=-1)
    idx = np.take_along_axis(idx, order, axis=-1)
    d2 = np.take_along_axis(d2, order, axis=-1)
    if kq > k:
        # A tie across the k-th place may involve points the query left out: widen.
        tied = np.flatnonzero(d2[:, k - 1] == d2[:, k])
        for r in tied:
            idx[r, :k] = _knn_tied_row(tree, points, rows[r], k, d2[r, k - 1], workers)
    return idx[:, :k]


def _knn_tied_row(
    tree: cKDTree, points: np.ndarray, row: int, k: int, boundary: float, workers: int
) -> np.ndarray:
    """kNN of one point whose k-th neighbour is tied: query until the tie is complete."""
    n = len(points)
    kq = min(2 * k + 1, n)
    while True:
        _, idx = tree.query(points[row], kq, workers=workers)
        d2 = squared_distances(points[idx], points[row])
        if kq == n or d2.max() > boundary:
            order = np.lexsort((idx, d2))
            return idx[order[:k]]
        kq = min(2 * kq, n)


class KnnNeighbourhoods:
    """k-nearest-neighbour neighbourhoods of a point cloud at several scales.

    Parameters
    ----------
    points : (n, 3) float64
        Distinct points.
    k_max : int
        The largest scale; one query of this size serves every scale.
    workers : int, default -1
        Threads for the kd-tree query.
    backend : {"compiled", "numpy"}, optional
        Default: :func:`meshlab_sharp._kernels.default_backend`.
    tree : KdTree, optional
        The compiled backend's kd-tree of ``points``, already built; None: built here.
    """

    def __init__(
        self,
        points: np.ndarray,
        k_max: int,
        *,
        workers: int = -1,
        backend: str | None = None,
        tree: _kernels.KdTree | None = None,
    ) -> None:
        n = len(points)
        if not 1 <= k_max <= n:
            raise InputError(
                f"k = {k_max} nearest neighbours needs at least {k_max} points, got {n}"
            )
        self.k_max = k_max
        self.workers = workers
        self.backend = _kernels.resolve(backend)
        self._indices: np.ndarray | None = None
        #: The kd-tree of the compiled backend (None with numpy).
        self.tree: _kernels.KdTree | None = None
        if self.backend == "compiled":
            self.tree = tree if tree is not None else _kernels.build_tree(points, workers)
        else:
            self._indices = knn(points, k_max, workers=workers)

    @property
    def indices(self) -> np.ndarray:
        """(n, k_max) neighbour indices, rows sorted by (squared distance, index)."""
        if self._indices is None:
            assert self.tree is not None
            idx = _kernels.cloud_knn(self.tree, self.k_max, self.workers)
            dtype = np.int32 if len(idx) < 2**31 else np.int64
            self._indices = idx.astype(dtype)
        return self._indices

    def at(self, k: int) -> Neighbourhood:
        """The k-nearest neighbourhoods, ``k <= k_max``."""
        if not 1 <= k <= self.k_max:
            raise ValueError(f"scale {k} outside 1..{self.k_max}")
        indices = self.indices
        n = len(indices)
        return Neighbourhood(
            indptr=np.arange(n + 1, dtype=np.int64) * k,
            indices=np.ascontiguousarray(indices[:, :k]).reshape(-1),
        )


def face_order_adjacency(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's neighbours in the order its faces list them, each once.

    Face ``(a, b, c)``, in face order, lists ``b, c`` for ``a``, ``a, c`` for ``b`` and
    ``a, b`` for ``c``; a neighbour is kept where it is first listed. The numpy reading
    of :func:`meshlab_sharp._kernels.adjacency` (the same lists).

    Parameters
    ----------
    faces : (m, 3) int
        Triangles, indices in ``[0, n)``.
    n : int
        Number of vertices.

    Returns
    -------
    indptr : (n + 1,) int64
    indices : (nnz,) int64
        Vertex ``v``'s neighbours are ``indices[indptr[v]:indptr[v + 1]]``.
    """
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    owner = np.stack([a, a, b, b, c, c], axis=1).reshape(-1)
    other = np.stack([b, c, a, c, a, b], axis=1).reshape(-1)
    order = np.argsort(owner, kind="stable")
    return _first_occurrences(owner[order], other[order], n, n)


def _first_occurrences(
    owner: np.ndarray, member: np.ndarray, rows: int, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """CSR lists (``rows`` rows) of ``member`` (k,) grouped by ``owner`` (k,), increasing,
    each row in the order of the input, each member kept where it first occurs in its row
    (members in ``[0, n)``): indptr (rows + 1,) int64, indices int64."""
    key = owner * n + member
    order = np.argsort(key, kind="stable")
    key = key[order]
    new = np.ones(len(key), dtype=bool)
    new[1:] = key[1:] != key[:-1]
    first = np.sort(order[new])  # each row's first occurrences, in the input's order
    indptr = np.zeros(rows + 1, dtype=np.int64)
    np.cumsum(np.bincount(owner[first], minlength=rows), out=indptr[1:])
    return indptr, member[first]


def grow_rings(
    adjacency: tuple[np.ndarray, np.ndarray], rows: np.ndarray
) -> Iterator[Neighbourhood]:
    """The k-rings of the vertices ``rows``, k = 1, 2, ..., one level at a time.

    Each ring is listed in the order a breadth-first search meets its vertices: ring
    k + 1 is ring k's list, then the vertices not yet met, in the order met walking
    the adjacency lists of ring k's last level (its members not in ring k - 1) in
    ring k's order. Ring 0 is the vertex itself, so every ring starts with it. The
    compiled ring pass (``_kernels.ring_projected_distances``) sums each ring in
    this order.

    Parameters
    ----------
    adjacency : (indptr (n + 1,) int64, indices (nnz,) int)
        Each vertex's neighbours (:func:`face_order_adjacency`).
    rows : (r,) int
        The centres.

    Yields
    ------
    Neighbourhood
        Ring k (k = 1, 2, ...) of each centre, ``r`` rows.
    """
    r = len(rows)
    indptr = np.arange(r + 1, dtype=np.int64)
    indices = np.asarray(rows, np.int64)
    inner = np.zeros(r, dtype=np.int64)  # the length of the ring before, per row
    while True:
        sizes = np.diff(indptr)
        parts = []  # blocks of rows, which keep the temporaries small
        for a in range(0, r, RING_BLOCK):
            b = min(a + RING_BLOCK, r)
            lists = indices[indptr[a] : indptr[b]], indptr[a : b + 1] - indptr[a]
            parts.append(_next_ring(adjacency, *lists, inner[a:b]))
        indices = np.concatenate([p[1] for p in parts] or [indices])
        counts = np.concatenate([np.diff(p[0]) for p in parts] or [np.zeros(0, np.int64)])
        indptr = np.zeros(r + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        inner = sizes
        yield Neighbourhood(indptr=indptr, indices=indices)


def _next_ring(
    adjacency: tuple[np.ndarray, np.ndarray],
    indices: np.ndarray,
    indptr: np.ndarray,
    inner: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`grow_rings`' next level of the rings (``indptr`` (r + 1,), ``indices``)
    whose levels before the last hold ``inner`` (r,) members: (indptr, indices)."""
    aptr, adj = adjacency
    n, r = len(aptr) - 1, len(inner)
    sizes = np.diff(indptr)
    owner = np.repeat(np.arange(r), sizes)
    last = np.arange(len(indices)) - indptr[owner] >= inner[owner]
    members = indices[last]
    degree = aptr[members + 1] - aptr[members]
    ends = np.cumsum(degree)
    at = np.repeat(aptr[members] - (ends - degree), degree) + np.arange(
        ends[-1] if len(ends) else 0
    )
    # each row: its ring, then the lists of its last level's members, in order
    found = np.bincount(np.repeat(owner[last], degree), minlength=r)
    sequence_owner = np.repeat(np.arange(r), sizes + found)
    start = np.zeros(r + 1, dtype=np.int64)
    np.cumsum(sizes + found, out=start[1:])
    ring = np.arange(len(sequence_owner)) - start[sequence_owner] < sizes[sequence_owner]
    sequence = np.empty(len(sequence_owner), dtype=np.int64)
    sequence[ring] = indices
    sequence[~ring] = adj[at]
    return _first_occurrences(sequence_owner, sequence, r, n)


class RingNeighbourhoods:
    """k-ring neighbourhoods of a triangle mesh, grown one ring at a time.

    Rings must be asked for in increasing order (each is grown from the last one
    asked, which is all that is kept in memory). Each ring is listed in breadth-first
    order (:func:`grow_rings`).

    Parameters
    ----------
    faces : (m, 3) int
        Triangles.
    n : int
        Number of vertices.
    backend : {"compiled", "numpy"}, optional
        Default: :func:`meshlab_sharp._kernels.default_backend`. The compiled backend
        keeps the 1-ring adjacency (``adjacency``) for a breadth-first search in C and
        lists the rings only if ``at()`` is called, and then does not keep ``faces``
        (``detect`` frees them before the scales' pass: 48 bytes a vertex).
    adjacency : (indptr (n + 1,) int64, indices int32), optional
        The compiled backend's adjacency of ``faces``, when the caller has it already
        (``meshlab_sharp.cleaning.CleanGeometry.adjacency``); None: built here.
    """

    def __init__(
        self,
        faces: np.ndarray,
        n: int,
        *,
        backend: str | None = None,
        adjacency: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        self.n = n
        self.backend = _kernels.resolve(backend)
        #: (indptr, indices) 1-ring adjacency, each neighbour once (compiled backend), else
        #: None.
        self.adjacency: tuple[np.ndarray, np.ndarray] | None = None
        if self.backend == "compiled" and n < 2**31:
            self.adjacency = _kernels.adjacency(faces, n) if adjacency is None else adjacency
        #: The faces, where the lists are made from them (numpy backend), else None.
        self.faces = faces if self.adjacency is None else None
        self._ring = 0
        self._rings: Iterator[Neighbourhood] | None = None
        self._current: Neighbourhood | None = None

    def lists(self) -> tuple[np.ndarray, np.ndarray]:
        """The 1-ring adjacency (:func:`face_order_adjacency`; the compiled backend's
        ``adjacency``, the same lists, when built)."""
        if self.adjacency is not None:
            return self.adjacency
        assert self.faces is not None
        return face_order_adjacency(self.faces, self.n)

    def at(self, ring: int) -> Neighbourhood:
        """Every vertex within ``ring`` edges, the vertex itself first, in breadth-first
        order (:func:`grow_rings`)."""
        if ring < max(self._ring, 1):
            raise ValueError("rings must be requested in increasing order, from 1")
        if self._rings is None:
            self._rings = grow_rings(self.lists(), np.arange(self.n))
        while self._ring < ring:
            self._current = next(self._rings)
            self._ring += 1
        assert self._current is not None
        return self._current


def build_neighbourhoods(
    points: np.ndarray,
    faces: np.ndarray | None,
    scales: Sequence[int],
    *,
    workers: int = -1,
    backend: str | None = None,
    tree: _kernels.KdTree | None = None,
    adjacency: tuple[np.ndarray, np.ndarray] | None = None,
) -> KnnNeighbourhoods | RingNeighbourhoods:
    """kNN neighbourhoods for a cloud (``faces is None``), k-rings for a mesh.

    ``backend``: "compiled" or "numpy" (see the module's docstring); default
    :func:`meshlab_sharp._kernels.default_backend`. ``tree``: a cloud's kd-tree, already
    built (:class:`KnnNeighbourhoods`). ``adjacency``: a mesh's compiled adjacency,
    already built (:class:`RingNeighbourhoods`).
    """
    if faces is None:
        k = max(scales)
        return KnnNeighbourhoods(points, k, workers=workers, backend=backend, tree=tree)
    return RingNeighbourhoods(faces, len(points), backend=backend, adjacency=adjacency)
