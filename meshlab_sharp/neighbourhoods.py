"""Neighbourhoods at every scale: k nearest neighbours for clouds, k-rings for meshes.

A neighbourhood is stored flat, as in CSR sparse matrices: the neighbours of point
``i`` are ``indices[indptr[i]:indptr[i + 1]]``, the point itself included. For clouds
one kNN query at the largest scale serves every scale (the smaller ones are prefixes);
for meshes each ring is grown from the previous one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .errors import InputError

#: Rows per block of kNN queries (bounds the temporary memory).
QUERY_BLOCK = 131072


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
    """

    def __init__(self, points: np.ndarray, k_max: int, *, workers: int = -1) -> None:
        self.indices = knn(points, k_max, workers=workers)
        self.k_max = k_max

    def at(self, k: int) -> Neighbourhood:
        """The k-nearest neighbourhoods, ``k <= k_max``."""
        if not 1 <= k <= self.k_max:
            raise ValueError(f"scale {k} outside 1..{self.k_max}")
        n = len(self.indices)
        return Neighbourhood(
            indptr=np.arange(n + 1, dtype=np.int64) * k,
            indices=np.ascontiguousarray(self.indices[:, :k]).reshape(-1),
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
    """

    def __init__(self, faces: np.ndarray, n: int) -> None:
        i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2], np.arange(n)])
        j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0], np.arange(n)])
        a = sp.coo_matrix((np.ones(len(i), dtype=bool), (i, j)), shape=(n, n)).tocsr()
        self.one_ring = (a + a.T).tocsr()
        self.one_ring.sort_indices()
        self._ring = 0
        self._current = sp.identity(n, dtype=bool, format="csr")

    def at(self, ring: int) -> Neighbourhood:
        """Every vertex within ``ring`` edges, the vertex itself included."""
        if ring < self._ring:
            raise ValueError("rings must be requested in increasing order")
        while self._ring < ring:
            self._current = (self._current @ self.one_ring).tocsr()
            self._ring += 1
        m = self._current
        return Neighbourhood(indptr=m.indptr.astype(np.int64), indices=m.indices)


def build_neighbourhoods(
    points: np.ndarray, faces: np.ndarray | None, scales: Sequence[int], *, workers: int = -1
) -> KnnNeighbourhoods | RingNeighbourhoods:
    """kNN neighbourhoods for a cloud (``faces is None``), k-rings for a mesh."""
    if faces is None:
        return KnnNeighbourhoods(points, max(scales), workers=workers)
    return RingNeighbourhoods(faces, len(points))
