"""Neighbourhoods at every scale: k nearest neighbours for clouds, k-rings for meshes.

A neighbourhood is stored flat, as in CSR sparse matrices: the neighbours of point
``i`` are ``indices[indptr[i]:indptr[i + 1]]``, the point itself included. For clouds
one kNN query at the largest scale serves every scale (the smaller ones are prefixes);
for meshes each ring is grown from the previous one.

Two backends give the same neighbourhoods (``tests/test_equivalence.py``): "numpy",
the reference (:mod:`meshlab_sharp.reference.neighbourhoods`: cKDTree; rings listed one
level at a time), and "compiled" (the default when built, :mod:`meshlab_sharp._kernels`),
which builds a balanced kd-tree and searches it, or a mesh's rings, in C.
With the compiled backend the neighbourhoods are not stored:
:func:`meshlab_sharp.multiscale.run_scales` searches them and uses them at once, point by
point, and ``at()`` computes a scale's table only when asked for.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np

from . import _header, _kernels
from .errors import InputError
from .reference.neighbourhoods import (
    Neighbourhood,
    face_order_adjacency,
    grow_rings,
    knn,
    squared_distances,
)

__all__ = [
    "KnnNeighbourhoods",
    "Neighbourhood",
    "RingNeighbourhoods",
    "build_neighbourhoods",
    "face_order_adjacency",
    "grow_rings",
    "knn",
    "squared_distances",
    "unit_scale",
]

#: Coordinates up to 2**UNIT_RANGE in absolute value, and at least 2**-UNIT_RANGE for
#: the largest, are used as they are; others are scaled (:func:`unit_scale`).
UNIT_RANGE = _header.integer("UNIT_RANGE")
#: A point further from a cloud's median than this many of its spreads is far (and
#: points up to this far are used as they are: the unit then stays within UNIT_RANGE
#: of the bulk's); the spread is measured on at most FAR_SAMPLE points
#: (:func:`far_points`).
FAR_SPREADS = _header.real("FAR_SPREADS")  # 2**40
FAR_SAMPLE = _header.integer("FAR_SAMPLE")


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

    ``points``: (n, 3) float64, finite. Returns (n,) bool, True for the far points, or
    None when there are none (most inputs: one pass over the bounds decides it).
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
