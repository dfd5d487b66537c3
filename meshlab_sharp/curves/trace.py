"""Polylines from the skeleton: traced between junctions, cut at sharp turns, and their
ends joined: across small gaps, into loops, and at corners.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .graph import adjacency

__all__ = [
    "CORNER_TURN",
    "GAP_LENGTH",
    "TURN_WINDOW",
    "Piece",
    "cut_at_turns",
    "end_clusters",
    "join_pieces",
    "tangents",
    "trace_paths",
]

#: Degrees: a curve turning by more than this within :data:`TURN_WINDOW` spacings on
#: each side of a vertex has a corner there; two curve ends meeting at more than this
#: meet at a corner (less: one curve continues into the other). A circle turns by this
#: within a window of w spacings when its radius is below ``2 w / radians(CORNER_TURN)``
#: = 5.1 spacings: smaller holes than that are not sampled finely enough to be curves.
CORNER_TURN = 45.0
#: Spacings on each side of a vertex over which a curve's direction is measured.
TURN_WINDOW = 2.0
#: Curve ends closer than this, in spacings, are joined (one curve continues, a loop
#: closes, or curves meet at a corner): detection leaves gaps of a few points at
#: corners, where neighbourhoods straddle three faces.
GAP_LENGTH = 4.0


@dataclass
class Piece:
    """A polyline during extraction.

    Attributes
    ----------
    nodes : (m,) int64
        Input point index of each vertex.
    points : (m, 3) float64
        Vertex positions.
    closed : bool
        True for a loop (the last vertex connects to the first, not repeated).
    """

    nodes: np.ndarray
    points: np.ndarray
    closed: bool = False

    @property
    def length(self) -> float:
        """Length of the polyline (the closing segment included for loops)."""
        p = np.vstack([self.points, self.points[:1]]) if self.closed else self.points
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def trace_paths(n: int, edges: np.ndarray) -> list[np.ndarray]:
    """Split a graph into paths between nodes whose degree is not 2, and cycles.

    Parameters
    ----------
    n : int
        Number of nodes.
    edges : (e, 2) int

    Returns
    -------
    list of (m,) int64
        Node sequences; a cycle is returned with its first node repeated at the end.
    """
    indptr, nbr, eid = adjacency(n, edges)
    degree = np.diff(indptr)
    used = np.zeros(len(edges), bool)
    paths: list[np.ndarray] = []

    def walk(start: int, j: int) -> np.ndarray:
        path = [start]
        while True:
            used[eid[j]] = True
            node = int(nbr[j])
            path.append(node)
            if degree[node] != 2:
                return np.array(path, np.int64)
            j = next((k for k in range(indptr[node], indptr[node + 1]) if not used[eid[k]]), -1)
            if j < 0:  # back at the start of a cycle
                return np.array(path, np.int64)

    for node in np.flatnonzero((degree != 2) & (degree > 0)):
        for j in range(indptr[node], indptr[node + 1]):
            if not used[eid[j]]:
                paths.append(walk(int(node), j))
    for node in np.flatnonzero(degree == 2):
        j = indptr[node]
        if not used[eid[j]]:
            paths.append(walk(int(node), int(j)))
    return paths


def _window_ends(cum: np.ndarray, window: float) -> tuple[np.ndarray, np.ndarray]:
    """For each vertex, the vertices about ``window`` of arc length before and after."""
    m = len(cum)
    back = np.clip(np.searchsorted(cum, cum - window, side="right") - 1, 0, m - 1)
    ahead = np.clip(np.searchsorted(cum, cum + window, side="left"), 0, m - 1)
    return back, ahead


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(norm > 0, norm, 1.0)


def _arc(points: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def _padded(piece: Piece, pad: int) -> np.ndarray:
    """The piece's points, a closed piece's wrapped by ``pad`` vertices on each side."""
    if not piece.closed:
        return piece.points
    p = piece.points
    reps = -(-pad // len(p))
    return np.concatenate([*([p] * reps), p, *([p] * reps)])[len(p) * reps - pad :][
        : len(p) + 2 * pad
    ]


def tangents(piece: Piece, window: float) -> np.ndarray:
    """Unit direction of the piece at each vertex, over ``window`` of arc length on each
    side. Shape (m, 3)."""
    m = len(piece.points)
    pad = m if piece.closed else 0
    p = _padded(piece, pad)
    back, ahead = _window_ends(_arc(p), window)
    t = _unit(p[ahead] - p[back])
    return t[pad : pad + m]


def turn_angles(piece: Piece, window: float) -> np.ndarray:
    """Degrees the piece turns at each vertex (between its directions over ``window``
    before and after it); 0 at the ends of an open piece. Shape (m,)."""
    m = len(piece.points)
    pad = m if piece.closed else 0
    p = _padded(piece, pad)
    back, ahead = _window_ends(_arc(p), window)
    i = np.arange(len(p))
    before, after = _unit(p - p[back]), _unit(p[ahead] - p)
    cos = np.einsum("ij,ij->i", before, after)
    valid = (back < i) & (ahead > i)
    angle = np.where(valid, np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))), 0.0)
    return angle[pad : pad + m]


def cut_at_turns(piece: Piece, spacing: float) -> list[Piece]:
    """Split a piece where it turns by more than :data:`CORNER_TURN`.

    A vertex is a corner when the piece turns there by more than CORNER_TURN both over
    :data:`TURN_WINDOW` spacings of arc on each side and over twice that (a corner
    turns over any window; one vertex off the line does not over the wider one). The
    cut vertex is the sharpest turn within TURN_WINDOW spacings of arc, and ends both
    pieces it separates.

    Parameters
    ----------
    piece : Piece
    spacing : float

    Returns
    -------
    list of Piece
        The piece itself when it has no sharp turn.
    """
    window = TURN_WINDOW * spacing
    angle = np.minimum(turn_angles(piece, window), turn_angles(piece, 2 * window))
    m = len(angle)
    cum = _arc(piece.points)
    cuts: list[int] = []
    for i in np.argsort(-angle, kind="stable"):
        if angle[i] <= CORNER_TURN:
            break
        near = [c for c in cuts if abs(cum[c] - cum[i]) < window]
        if piece.closed:
            total = piece.length
            near = [
                c for c in cuts if min(abs(cum[c] - cum[i]), total - abs(cum[c] - cum[i])) < window
            ]
        if not near:
            cuts.append(int(i))
    if not cuts:
        return [piece]
    cuts.sort()
    if piece.closed:
        shift = cuts[0]
        idx = np.concatenate([np.arange(shift, m), np.arange(shift + 1)])
        bounds = [c - shift for c in cuts] + [m]
    else:
        idx = np.arange(m)
        bounds = [0, *cuts, m - 1]
    out = []
    for a, b in itertools.pairwise(bounds):
        if b > a:
            sel = idx[a : b + 1]
            out.append(Piece(piece.nodes[sel], piece.points[sel]))
    return out


@dataclass
class _Ends:
    piece: np.ndarray  # (q,) piece of each end
    side: np.ndarray  # (q,) 0: first vertex, 1: last
    point: np.ndarray  # (q, 3)
    out: np.ndarray  # (q, 3) unit direction leaving the curve


def _ends(pieces: list[Piece], spacing: float) -> _Ends:
    rows = []
    for i, pc in enumerate(pieces):
        if pc.closed or len(pc.points) < 2:
            continue
        t = tangents(Piece(pc.nodes, pc.points), TURN_WINDOW * spacing)
        rows.append((i, 0, pc.points[0], -t[0]))
        rows.append((i, 1, pc.points[-1], t[-1]))
    if not rows:
        z = np.zeros((0, 3))
        return _Ends(np.zeros(0, np.int64), np.zeros(0, np.int64), z, z)
    return _Ends(
        np.array([r[0] for r in rows]),
        np.array([r[1] for r in rows]),
        np.array([r[2] for r in rows]),
        _unit(np.array([r[3] for r in rows])),
    )


def end_clusters(pieces: list[Piece], spacing: float) -> tuple[_Ends, list[np.ndarray]]:
    """Curve ends grouped by distance (:data:`GAP_LENGTH` spacings, transitively).

    Returns
    -------
    ends : the ends (piece, side, point (q, 3), outward direction (q, 3))
    clusters : list of (c,) int64
        Indices into ``ends``, every cluster of two or more ends, deterministic order.
    """
    ends = _ends(pieces, spacing)
    q = len(ends.piece)
    parent = np.arange(q)

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = int(parent[i])
        return i

    if q:
        for a, b in sorted(cKDTree(ends.point).query_pairs(GAP_LENGTH * spacing)):
            ra, rb = root(a), root(b)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([root(i) for i in range(q)], np.int64)
    clusters = [np.flatnonzero(roots == r) for r in np.unique(roots)]
    return ends, [c for c in clusters if len(c) >= 2]


def _continues(ends: _Ends, a: int, b: int, spacing: float) -> bool:
    """Ends ``a`` and ``b`` belong to one curve: they face each other within
    :data:`CORNER_TURN`, and so does the gap between them."""
    limit = math.cos(math.radians(CORNER_TURN))
    if -float(ends.out[a] @ ends.out[b]) < limit:
        return False
    gap = ends.point[b] - ends.point[a]
    length = float(np.linalg.norm(gap))
    if length <= 0.5 * spacing:
        return True
    g = gap / length
    return float(ends.out[a] @ g) >= limit and float(-ends.out[b] @ g) >= limit


def join_pieces(pieces: list[Piece], spacing: float) -> list[Piece]:
    """Join pieces whose ends meet as one curve (two ends, facing each other), closing
    loops; ends meeting at a corner are left as they are.

    Parameters
    ----------
    pieces : list of Piece
    spacing : float

    Returns
    -------
    list of Piece
    """
    ends, clusters = end_clusters(pieces, spacing)
    link: dict[tuple[int, int], tuple[int, int]] = {}
    for c in clusters:
        if len(c) != 2 or not _continues(ends, int(c[0]), int(c[1]), spacing):
            continue
        a, b = (int(ends.piece[i]) for i in c)
        sa, sb = (int(ends.side[i]) for i in c)
        if a == b and pieces[a].length < 3 * GAP_LENGTH * spacing:
            continue  # a short piece bent onto itself is no loop
        link[(a, sa)] = (b, sb)
        link[(b, sb)] = (a, sa)
    if not link:
        return pieces
    done = np.zeros(len(pieces), bool)
    out: list[Piece] = []

    def chain(start: int, entry_side: int) -> Piece:
        parts, (p, side), closed = [], (start, entry_side), False
        while True:
            done[p] = True
            pc = pieces[p]
            parts.append(pc if side == 0 else Piece(pc.nodes[::-1], pc.points[::-1]))
            nxt = link.get((p, 1 - side))
            if nxt is None:
                break
            if done[nxt[0]]:
                closed = nxt == (start, entry_side)
                break
            p, side = nxt
        nodes = np.concatenate([q.nodes for q in parts])
        points = np.concatenate([q.points for q in parts])
        keep = np.ones(len(nodes), bool)  # a vertex shared by consecutive parts once
        keep[1:] = nodes[1:] != nodes[:-1]
        nodes, points = nodes[keep], points[keep]
        if closed and len(nodes) > 1 and nodes[0] == nodes[-1]:
            nodes, points = nodes[:-1], points[:-1]
        return Piece(nodes, points, closed)

    for i, pc in enumerate(pieces):
        if done[i]:
            continue
        if pc.closed:
            done[i] = True
            out.append(pc)
        elif (i, 0) not in link:
            out.append(chain(i, 0))
        elif (i, 1) not in link:
            out.append(chain(i, 1))
    for i in range(len(pieces)):
        if not done[i]:
            out.append(chain(i, 0))
    return out
