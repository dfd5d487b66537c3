"""Neighbourhoods at every scale: k nearest neighbours for clouds, k-rings for meshes.

A neighbourhood is stored flat, as in CSR sparse matrices: the neighbours of point
``i`` are ``indices[indptr[i]:indptr[i + 1]]``, the point itself included. For clouds
one kNN query at the largest scale serves every scale (the smaller ones are prefixes);
for meshes each ring is grown from the previous one.

Two backends give the same neighbourhoods (``tests/test_equivalence.py``): "numpy",
the reference (cKDTree, sparse matrix powers), and "compiled" (the default when built,
:mod:`meshlab_sharp._kernels`), which builds a balanced kd-tree and searches it in C.
With the compiled backend the neighbourhoods are not stored:
:func:`meshlab_sharp.multiscale.run_scales` searches them and uses them at once, point by
point, and ``at()`` computes a scale's table only when asked for.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from . import _header, _kernels
from .errors import InputError

#: Rows per block of kNN queries (bounds the temporary memory).
QUERY_BLOCK = 131072
#: Coordinates up to 2**UNIT_RANGE in absolute value, and at least 2**-UNIT_RANGE for
#: the largest, are used as they are; others are scaled (:func:`unit_scale`).
UNIT_RANGE = _header.integer("UNIT_RANGE")


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
    e = math.frexp(largest)[1]
    if largest == 0.0 or -UNIT_RANGE < e <= UNIT_RANGE:
        return points, 0
    return np.ldexp(points, -e), e


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
    """

    def __init__(
        self, points: np.ndarray, k_max: int, *, workers: int = -1, backend: str | None = None
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
            self.tree = _kernels.build_tree(points, workers)
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


class RingNeighbourhoods:
    """k-ring neighbourhoods of a triangle mesh, grown one ring at a time.

    Rings must be asked for in increasing order (each is grown from the last one
    asked, which is all that is kept in memory).

    Parameters
    ----------
    faces : (m, 3) int
        Triangles.
    n : int
        Number of vertices.
    backend : {"compiled", "numpy"}, optional
        Default: :func:`meshlab_sharp._kernels.default_backend`. The compiled backend
        keeps the 1-ring adjacency (``adjacency``) for a breadth-first search in C and
        builds the sparse matrices only if ``at()`` is called.
    """

    def __init__(self, faces: np.ndarray, n: int, *, backend: str | None = None) -> None:
        self.faces = faces
        self.n = n
        self.backend = _kernels.resolve(backend)
        #: (indptr, indices) 1-ring adjacency, each neighbour once (compiled backend), else
        #: None.
        self.adjacency: tuple[np.ndarray, np.ndarray] | None = None
        self._one_ring: sp.csr_matrix | None = None
        if self.backend == "compiled" and n < 2**31:
            self.adjacency = _kernels.adjacency(faces, n)
        else:
            self._one_ring = self._build_one_ring()
        self._ring = 0
        self._current = None

    def _build_one_ring(self) -> sp.csr_matrix:
        faces, n = self.faces, self.n
        i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2], np.arange(n)])
        j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0], np.arange(n)])
        a = sp.coo_matrix((np.ones(len(i), dtype=bool), (i, j)), shape=(n, n)).tocsr()
        one_ring = (a + a.T).tocsr()
        one_ring.sort_indices()
        return one_ring

    @property
    def one_ring(self) -> sp.csr_matrix:
        """The 1-ring (and self) as a boolean sparse matrix."""
        if self._one_ring is None:
            self._one_ring = self._build_one_ring()
        return self._one_ring

    def at(self, ring: int) -> Neighbourhood:
        """Every vertex within ``ring`` edges, the vertex itself included."""
        if ring < self._ring:
            raise ValueError("rings must be requested in increasing order")
        if self._current is None:
            self._current = sp.identity(self.n, dtype=bool, format="csr")
        while self._ring < ring:
            self._current = (self._current @ self.one_ring).tocsr()
            self._ring += 1
        m = self._current
        return Neighbourhood(indptr=m.indptr.astype(np.int64), indices=m.indices)


def build_neighbourhoods(
    points: np.ndarray,
    faces: np.ndarray | None,
    scales: Sequence[int],
    *,
    workers: int = -1,
    backend: str | None = None,
) -> KnnNeighbourhoods | RingNeighbourhoods:
    """kNN neighbourhoods for a cloud (``faces is None``), k-rings for a mesh.

    ``backend``: "compiled" or "numpy" (see the module's docstring); default
    :func:`meshlab_sharp._kernels.default_backend`.
    """
    if faces is None:
        return KnnNeighbourhoods(points, max(scales), workers=workers, backend=backend)
    return RingNeighbourhoods(faces, len(points), backend=backend)
