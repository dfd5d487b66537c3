"""A mesh's own sharp edges, the numpy reference: the dihedral angle of every edge with
two faces, and the vertices on an edge that turns by more than a threshold
(:func:`meshlab_sharp.creases.crease_threshold`). The compiled kernels
(:func:`meshlab_sharp._kernels.two_face_edges`,
:func:`~meshlab_sharp._kernels.crease_vertices`) give the same edges, angles and masks.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


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
        Radians in [0, pi]: the normal of the second face negated where the two faces
        go the same way along the edge (one wound the other way round), so that only the
        line of each normal counts, never the faces' winding.
    """
    p0, p1, p2 = (points[faces[:, c]] for c in range(3))
    fn = np.cross(p1 - p0, p2 - p0)
    length = np.sqrt(fn[:, 0] * fn[:, 0] + fn[:, 1] * fn[:, 1] + fn[:, 2] * fn[:, 2])
    fn = fn / np.where(length > 0, length, 1.0)[:, None]
    edges, first, second, same = _two_face_edges(faces, len(points))
    u, v = fn[first], fn[second]
    dot = u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1] + u[:, 2] * v[:, 2]
    dot = np.where(same, -dot, dot)
    return edges, np.arccos(np.clip(dot, -1.0, 1.0))


def _two_face_edges(
    faces: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The edges (e, 2) with exactly two faces, as :func:`dihedral_angles` lists them;
    their two faces (e,) and (e,), the lower first; and whether the two go the same way
    along the edge (e,) bool: one of them wound the other way round."""
    # the 3 edges of each face in turn, so that owners never decrease: a stable sort of
    # the edge codes lo * n + hi (< 2**63 for n < 3e9) orders equal edges by owner
    pairs = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    n64 = np.int64(n)
    code = np.minimum(pairs[:, 0], pairs[:, 1]) * n64 + np.maximum(pairs[:, 0], pairs[:, 1])
    order = np.argsort(code, kind="stable")
    code, owner = code[order], order // 3
    up = (pairs[:, 0] < pairs[:, 1])[order]
    new = np.ones(len(code), bool)
    new[1:] = code[1:] != code[:-1]
    starts = np.flatnonzero(new)
    counts = np.diff(np.append(starts, len(code)))
    two = starts[counts == 2]
    edges = np.stack([code[two] // n64, code[two] % n64], axis=1)
    return edges, owner[two], owner[two + 1], up[two] == up[two + 1]


def face_windings(faces: np.ndarray, n: int) -> tuple[np.ndarray, int]:
    """Which faces to turn so that every face is wound as its neighbours are
    (:func:`meshlab_sharp.creases.face_windings`): ``faces`` (m, 3) int64 over ``n``
    vertices; returns the faces turned (m,) bool and the number of faces in parts with
    no consistent winding (non-orientable, left as they are wound). Faces are joined
    through their two-face edges; the lowest face of each part keeps its winding."""
    m = len(faces)
    if m == 0:
        return np.zeros(0, bool), 0
    _, first, second, same = _two_face_edges(faces, n)
    # the double cover: node 2 f + s is face f turned (s = 1) or not; joined faces'
    # nodes joined as their windings agree
    s = same.astype(np.int64)
    rows = np.concatenate([2 * first, 2 * first + 1])
    cols = np.concatenate([2 * second + s, 2 * second + 1 - s])
    graph = coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(2 * m, 2 * m))
    label = connected_components(graph, directed=False)[1]
    kept, turned = label[0::2], label[1::2]
    odd = kept == turned  # both windings of a face joined: no consistent one
    part = np.minimum(kept, turned)
    lowest = np.full(2 * m, m, np.int64)
    np.minimum.at(lowest, part, np.arange(m))
    flip = (kept != kept[lowest[part]]) & ~odd
    return flip, int(np.count_nonzero(odd))


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
