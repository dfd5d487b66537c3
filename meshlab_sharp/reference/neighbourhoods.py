"""Neighbourhoods, the numpy reference: k nearest neighbours with scipy's cKDTree (ties
broken by index) and k-rings grown one level at a time with array operations. The
compiled kernels (:mod:`meshlab_sharp._kernels`) give the same lists.

A neighbourhood is stored flat, as in CSR sparse matrices (:class:`Neighbourhood`): the
neighbours of point ``i`` are ``indices[indptr[i]:indptr[i + 1]]``, the point itself
included.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError

#: Rows per block of kNN queries (bounds the temporary memory).
QUERY_BLOCK = 131072
#: Rows per block when the rings are grown (bounds the temporaries).
RING_BLOCK = 16384


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
