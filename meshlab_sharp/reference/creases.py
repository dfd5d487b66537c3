"""A mesh's own sharp edges, the numpy reference: the dihedral angle of every edge with
two faces, and the vertices on an edge that turns by more than a threshold
(:func:`meshlab_sharp.creases.crease_threshold`). The compiled kernels
(:func:`meshlab_sharp._kernels.two_face_edges`,
:func:`~meshlab_sharp._kernels.crease_vertices`) give the same edges, angles and masks.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


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


def sharp_vertices(
    points: np.ndarray, faces: np.ndarray, threshold_of: Callable[[np.ndarray], float]
) -> tuple[np.ndarray, float]:
    """Vertices on a sharp edge (:func:`meshlab_sharp.creases.sharp_vertices`): an edge
    of two faces whose angle exceeds ``threshold_of(angles)``.

    Parameters
    ----------
    points : (n, 3) float64
    faces : (f, 3) int64
        Triangles of non-zero area, three distinct vertices each.
    threshold_of : callable
        The threshold (radians) of the angles (e,) of all the two-face edges
        (:func:`meshlab_sharp.creases.crease_threshold`).

    Returns
    -------
    mask : (n,) bool
    threshold : float
        The angle used (radians).
    """
    edges, angles = (
        dihedral_angles(points, faces) if len(faces) else (np.zeros((0, 2), np.int64), np.zeros(0))
    )
    threshold = threshold_of(angles)
    mask = np.zeros(len(points), bool)
    mask[edges[angles > threshold].reshape(-1)] = True
    return mask, threshold
