"""A mesh's own sharp edges, the numpy reference: the dihedral angle of every edge with
two faces, and the vertices on an edge that turns by more than
:func:`crease_threshold`. The compiled kernels
(:func:`meshlab_sharp._kernels.two_face_edges`,
:func:`~meshlab_sharp._kernels.crease_vertices`) give the same edges, angles and masks.
"""

from __future__ import annotations

import math

import numpy as np

from .. import _header

#: Degrees: the smallest turn of the surface that counts as a sharp edge (the ground
#: truth's crease angle, ``meshlab_sharp.parts.CREASE_ANGLE``).
CREASE_ANGLE = _header.real("CREASE_ANGLE")
#: On a noisy mesh the dihedral angles of flat regions are close to half-normal
#: (measured: median / lower quartile = 2.1, half-normal 2.11): their lower quartile is
#: ``0.3186 sigma`` (``Phi^-1(0.625)``), and 4 sigma (one false alarm per 16,000 edges)
#: is ``4 / 0.3186 = 12.6`` lower quartiles. Sharp edges must turn by more than
#: ``NOISE_FACTOR * lower quartile`` as well as by more than ``CREASE_ANGLE``. The
#: quartile, not the median: on a small CAD mesh (a box: 24 edges) half the edges can
#: be creases, a quarter cannot (the triangulation's diagonals turn by 0).
NOISE_FACTOR = _header.real("NOISE_FACTOR")


def dihedral_angles(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edges with exactly two faces and the angle between their face normals
    (:func:`meshlab_sharp.creases.dihedral_angles`).

    Parameters
    ----------
    points : (n, 3) float64
    faces : (f, 3) int64
        Triangles of non-zero area (cleaned), at least one.

    Returns
    -------
    edges : (e, 2) int64
        Vertex pairs ``(a, b)``, ``a < b``, sorted lexicographically.
    angles : (e,) float64
        Radians in [0, pi].
    """
    p0, p1, p2 = (points[faces[:, c]] for c in range(3))
    fn = np.cross(p1 - p0, p2 - p0)
    length = np.sqrt(fn[:, 0] * fn[:, 0] + fn[:, 1] * fn[:, 1] + fn[:, 2] * fn[:, 2])
    fn = fn / np.where(length > 0, length, 1.0)[:, None]
    # the 3 edges of each face in turn, so that owners never decrease: a stable sort of
    # the edge codes lo * n + hi (< 2**63 for n < 3e9) orders equal edges by owner
    pairs = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    n = np.int64(len(points))
    code = np.minimum(pairs[:, 0], pairs[:, 1]) * n + np.maximum(pairs[:, 0], pairs[:, 1])
    order = np.argsort(code, kind="stable")
    code, owner = code[order], order // 3
    new = np.ones(len(code), bool)
    new[1:] = code[1:] != code[:-1]
    starts = np.flatnonzero(new)
    counts = np.diff(np.append(starts, len(code)))
    two = starts[counts == 2]
    u, v = fn[owner[two]], fn[owner[two + 1]]
    dot = u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1] + u[:, 2] * v[:, 2]
    edges = np.stack([code[two] // n, code[two] % n], axis=1)
    return edges, np.arccos(np.clip(dot, -1.0, 1.0))


#: Angles per block of crease_threshold's count.
_BLOCK = 1 << 16


def crease_threshold(angles: np.ndarray, *, zeros: int = 0) -> float:
    """Radians: ``max(CREASE_ANGLE, NOISE_FACTOR * lower quartile of the angles)``.

    Parameters
    ----------
    angles : (e,) float64
        Dihedral angles of the mesh's two-face edges (radians).
    zeros : int, default 0
        How many more angles are 0 (edges left out of ``angles``, the compiled
        :func:`sharp_vertices`' flat ones): the same threshold as with them in.

    Returns
    -------
    float
        The lower quartile is element ``(e + zeros - 1) // 4`` of all the angles sorted in
        increasing order (``CREASE_ANGLE`` when there are none).
    """
    floor = math.radians(CREASE_ANGLE)
    if len(angles) + zeros == 0:
        return floor
    at = (len(angles) + zeros - 1) // 4
    # When more than ``at`` angles a give NOISE_FACTOR * a <= floor, so does the quartile
    # (rounding is monotonic) and the floor wins: no partial sort (most of a mesh's edges
    # are flat; the zeros among them). Otherwise the zeros are the ``zeros`` smallest
    # angles (at most ``at`` of them), and the quartile is among ``angles``.
    # (counted in blocks: no temporary as long as the angles)
    below = zeros + sum(
        int(np.count_nonzero(NOISE_FACTOR * angles[i : i + _BLOCK] <= floor))
        for i in range(0, len(angles), _BLOCK)
    )
    if below > at:
        return floor
    quartile = float(np.partition(angles, at - zeros)[at - zeros])
    return max(floor, NOISE_FACTOR * quartile)


def sharp_vertices(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, float]:
    """Vertices on a sharp edge (:func:`meshlab_sharp.creases.sharp_vertices`).

    Parameters
    ----------
    points : (n, 3) float64
    faces : (f, 3) int64
        Triangles of non-zero area, three distinct vertices each.

    Returns
    -------
    mask : (n,) bool
    threshold : float
        The angle used (radians).
    """
    edges, angles = (
        dihedral_angles(points, faces) if len(faces) else (np.zeros((0, 2), np.int64), np.zeros(0))
    )
    threshold = crease_threshold(angles)
    mask = np.zeros(len(points), bool)
    mask[edges[angles > threshold].reshape(-1)] = True
    return mask, threshold
