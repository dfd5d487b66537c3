"""A mesh's sharp edges as curves: the chains of the mesh edges whose two faces turn by
more than the crease threshold, cut where three or more chains meet (the numpy reference
of the native library's native/src/curves_mesh.cpp).

An edge is sharp when the normals of its two faces differ by more than ``CREASE_ANGLE``,
the threshold of the detection's own creases on a mesh without noise
(:func:`meshlab_sharp.creases.crease_threshold`); where the noise raises that threshold
(``NOISE_FACTOR`` times the lower quartile of the angles of all the mesh's two-face
edges), no edge is taken alone and the features go to the skeleton. The sharp edges are
chained where the detection saw the crease (a sharp edge between two feature vertices),
also through the vertices on it that the detection left out, whatever their length: a
coarse tessellation's one long edge along a crease is a curve, the diagonal of a flat
quad (0 degrees) and the facets of a 24-segment cylinder (15 degrees) are not. A chain
ends at a vertex where one or three or more sharp edges meet, or where it turns by more
than ``CORNER_TURN`` degrees; those vertices, but the free ends, are corners. The other
feature vertices joined to a sharp edge through feature edges (the band of detections
beside a crease) take no further part; the rest are left to the skeleton of
:mod:`.extract`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..._header import KERNELS
from ..creases import _two_face_edges
from .trace import CORNER_TURN, Piece

__all__ = ["CreaseChains", "crease_chains"]

# The numbers are defined once, in native/include/meshlab_sharp.h. A chain is cut where
# consecutive sharp edges turn by more than CORNER_TURN degrees (trace.py).
#: The detection's crease angle floor (degrees) and its noise factor.
CREASE_ANGLE = KERNELS.real("CREASE_ANGLE")
NOISE_FACTOR = KERNELS.real("NOISE_FACTOR")


@dataclass
class CreaseChains:
    """The chains of a mesh's sharp edges.

    Attributes
    ----------
    pieces : list of Piece
        The chains (mesh vertices), in the order they are traced.
    corners : (c,) int64
        The vertices where three or more chains meet or a chain turns, ascending.
    rest : (n,) bool
        The feature vertices left to the skeleton: those not joined to a sharp edge by
        edges between feature vertices.
    """

    pieces: list[Piece]
    corners: np.ndarray
    rest: np.ndarray


def crease_chains(
    vertices: np.ndarray, faces: np.ndarray, mask: np.ndarray, usable: np.ndarray
) -> CreaseChains:
    """The chains of the sharp edges of the creases the detection saw.

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int
    mask : (n,) bool
        Feature vertices (valid ones).
    usable : (n,) bool
        The feature vertices that may be curve vertices (one per distinct position).

    Returns
    -------
    CreaseChains
    """
    n = len(vertices)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    sharp = _sharp_edges(vertices, f, mask, usable) if len(f) else np.zeros((0, 2), np.int64)
    rest = mask & ~_joined(f, usable, sharp, n)
    if len(sharp) == 0:
        return CreaseChains([], np.zeros(0, np.int64), rest)
    nbrs: dict[int, list[int]] = {}
    for a, b in sharp.tolist():
        nbrs.setdefault(a, []).append(b)
        nbrs.setdefault(b, []).append(a)
    for v in nbrs.values():
        v.sort()
    cos_turn = math.cos(math.radians(CORNER_TURN))
    rows = vertices.tolist()
    cuts = set()
    corners = []
    for v in sorted(nbrs):
        around = nbrs[v]
        if len(around) != 2:
            cuts.add(v)
            if len(around) >= 3:
                corners.append(v)
        elif _turns(rows[around[0]], rows[v], rows[around[1]], cos_turn):
            cuts.add(v)
            corners.append(v)
    used: set[tuple[int, int]] = set()

    def walk(start: int, nxt: int) -> list[int]:
        path, prev, here = [start], start, nxt
        used.add((min(start, nxt), max(start, nxt)))
        while here not in cuts and here != start:
            path.append(here)
            step = next(w for w in nbrs[here] if w != prev)
            used.add((min(here, step), max(here, step)))
            prev, here = here, step
        path.append(here)
        return path

    pieces = []
    for v in sorted(cuts):
        for w in nbrs[v]:
            if (min(v, w), max(v, w)) not in used:
                pieces.append(_piece(vertices, walk(v, w), False))
    for v in sorted(nbrs):  # loops without a cut
        w = nbrs[v][0]
        if (min(v, w), max(v, w)) not in used:
            pieces.append(_piece(vertices, walk(v, w)[:-1], True))
    return CreaseChains(pieces, np.array(corners, np.int64), rest)


def _piece(vertices: np.ndarray, path: list[int], closed: bool) -> Piece:
    nodes = np.array(path, np.int64)
    return Piece(nodes, vertices[nodes], closed)


def _turns(a: list[float], b: list[float], c: list[float], cos_turn: float) -> bool:
    """Whether the polyline a-b-c turns at b by more than the angle of ``cos_turn``
    (plain floats: the native library's arithmetic)."""
    u = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
    w = (c[0] - b[0], c[1] - b[1], c[2] - b[2])
    dot = (u[0] * w[0] + u[1] * w[1]) + u[2] * w[2]
    nu = math.sqrt((u[0] * u[0] + u[1] * u[1]) + u[2] * u[2])
    nw = math.sqrt((w[0] * w[0] + w[1] * w[1]) + w[2] * w[2])
    return dot < cos_turn * (nu * nw)


def _sharp_edges(
    vertices: np.ndarray, faces: np.ndarray, mask: np.ndarray, usable: np.ndarray
) -> np.ndarray:
    """The sharp edges to chain, (s, 2) int64, (a, b), a < b, sorted: the edges whose two
    faces turn by more than CREASE_ANGLE (the angles of
    :func:`meshlab_sharp.reference.creases.dihedral_angles`; faces of zero area left
    out), none where the noise raises the crease threshold of the mesh's two-face edges
    above it, between usable or non-feature vertices, in the parts of the graph of
    such edges that hold one between two usable vertices (a crease the detection saw,
    through the vertices on it that it left out)."""
    p0, p1, p2 = (vertices[faces[:, c]] for c in range(3))
    fn = np.cross(p1 - p0, p2 - p0)
    length = np.sqrt(fn[:, 0] * fn[:, 0] + fn[:, 1] * fn[:, 1] + fn[:, 2] * fn[:, 2])
    solid = length > 0
    none = np.zeros((0, 2), np.int64)
    if not solid.any():
        return none
    # creases.dihedral_angles' dot products, of the faces of non-zero area
    edges, first, second, same = _two_face_edges(faces[solid], len(vertices))
    if len(edges) == 0:
        return none
    fn = fn[solid] / length[solid][:, None]
    u, v = fn[first], fn[second]
    dot = u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1] + u[:, 2] * v[:, 2]
    dot = np.clip(np.where(same, -dot, dot), -1.0, 1.0)
    # the lower quartile of the angles (element (e - 1) // 4 in increasing order): the
    # arccos of the dot product as far from the top
    top = len(dot) - 1 - (len(dot) - 1) // 4
    quartile = float(np.arccos(np.partition(dot, top)[top : top + 1])[0])
    threshold = math.radians(CREASE_ANGLE)
    if NOISE_FACTOR * quartile > threshold:
        return none  # a noisy mesh: its creases are left to the skeleton of the features
    angle = np.arccos(dot)
    allowed = usable | ~mask
    edges = edges[(angle > threshold) & allowed[edges[:, 0]] & allowed[edges[:, 1]]]
    seen = usable[edges[:, 0]] & usable[edges[:, 1]]
    if not seen.any():
        return none
    n = len(vertices)
    graph = coo_matrix((np.ones(len(edges), np.int8), (edges[:, 0], edges[:, 1])), shape=(n, n))
    label = connected_components(graph, directed=False)[1]
    part = np.zeros(n, bool)
    part[label[edges[seen, 0]]] = True
    return edges[part[label[edges[:, 0]]]]


def _joined(faces: np.ndarray, usable: np.ndarray, sharp: np.ndarray, n: int) -> np.ndarray:
    """The usable vertices (n,) bool joined to a vertex of a sharp edge by edges between
    usable vertices."""
    if len(sharp) == 0:
        return np.zeros(n, bool)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = e[usable[e[:, 0]] & usable[e[:, 1]]]
    graph = coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(n, n))
    label = connected_components(graph, directed=False)[1]
    crease = np.zeros(n, bool)
    crease[label[sharp.ravel()]] = True
    return crease[label] & usable
