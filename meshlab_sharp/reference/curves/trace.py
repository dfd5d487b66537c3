"""Polylines from the skeleton: traced between junctions, cut at sharp turns, and their
ends joined: across small gaps, into loops, and at corners.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..._header import CURVES
from .graph import DisjointSets, adjacency

__all__ = [
    "CORNER_TURN",
    "GAP_LENGTH",
    "TANGENT_WINDOW",
    "TURN_INNER",
    "TURN_OUTER",
    "TURN_SCALES",
    "Piece",
    "batch_tangents",
    "cut_at_turns",
    "end_clusters",
    "join_pieces",
    "meeting_clusters",
    "split_at_touches",
    "tangents",
    "trace_paths",
]

# The numbers are defined once, in native/include/meshlab_sharp.h.
#: Degrees: a curve turning by more than this at a vertex has a corner there; two curve
#: ends meeting at more than this meet at a corner (less: one curve continues into the
#: other). The turn at a vertex is the angle between the chords of the curve from
#: TURN_OUTER to TURN_INNER spacings of arc before it and from TURN_INNER to TURN_OUTER
#: after it (at several scales, :data:`TURN_SCALES`): a circle of radius r turns by
#: ``(TURN_INNER + TURN_OUTER) / r`` radians between the smallest chords, so circles down
#: to a radius of ``2.5 / radians(CORNER_TURN)`` = 4.1 spacings stay whole; the edges of
#: a 45-degree chamfer meet the faces' edges at 54.7 degrees, which the smoothing of
#: the positions (a few vertices) rounds off by up to 15 degrees.
CORNER_TURN = CURVES.real("CORNER_TURN")
#: Chords measuring the turn at a vertex start this far from it, in spacings of arc ...
TURN_INNER = CURVES.real("TURN_INNER")
#: ... and end this far.
TURN_OUTER = CURVES.real("TURN_OUTER")
#: The turn is measured with the chords at these multiples of their distances (see
#: turn_angles).
TURN_SCALES = CURVES.reals("TURN_SCALES")
#: Fewest chord scales that must fit on the piece for a turn to count.
MIN_TURN_SCALES = CURVES.integer("MIN_TURN_SCALES")
#: Half-width, in spacings of arc, of the chord giving a curve's direction at a vertex.
TANGENT_WINDOW = CURVES.real("TANGENT_WINDOW")
#: Curve ends closer than this, in spacings, are joined (one curve continues, a loop
#: closes, or curves meet at a corner): detection leaves gaps of a few points at
#: corners, where neighbourhoods straddle three faces.
GAP_LENGTH = CURVES.real("GAP_LENGTH")
#: Open pieces shorter than this, in spacings (twice GAP_LENGTH), are not cut: both
#: parts would be shorter than the shortest curve kept (``extract.MIN_CURVE_LENGTH`` =
#: GAP_LENGTH).
SHORTEST_CUT = CURVES.real("SHORTEST_CUT")
#: A piece whose two ends meet is a loop only if it is at least this many times
#: GAP_LENGTH long (a circle of 2 spacings' radius at least); a shorter one's two ends
#: are not joined, nor taken for a corner.
LOOP_LENGTH = CURVES.real("LOOP_LENGTH")
#: Two free ends facing each other are joined across up to this many spacings: the
#: gaps detection leaves along weak edges (a chamfer's 45-degree edges) and in noise.
LONG_GAP = CURVES.real("LONG_GAP")
#: Scale (index into :data:`TURN_SCALES`) of the end chords whose lines place corners:
#: chords from 2 to 8 spacings before the end (the last vertices bend in noise).
CORNER_SCALE = CURVES.integer("CORNER_SCALE")
#: Two ends continue one curve only if each (or its end chord's inner vertex) lies
#: within this many spacings of the other's line, and two end lines meet at a corner
#: only if they pass this close: the width of a feature band in noise (parallel edges
#: are farther apart).
LATERAL_OFFSET = CURVES.real("LATERAL_OFFSET")


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
        return float(piece_lengths([self])[0])


def piece_lengths(pieces: list[Piece]) -> np.ndarray:
    """:attr:`Piece.length` of many pieces, (p,) float64: the segments' lengths in one
    pass, each piece's sum of its own (the same bits as one piece at a time)."""
    rings = [np.vstack([pc.points, pc.points[:1]]) if pc.closed else pc.points for pc in pieces]
    if not rings:
        return np.zeros(0)
    p = np.concatenate(rings)
    d = p[1:] - p[:-1]
    seg = np.sqrt((d * d).sum(axis=1))  # np.linalg.norm's sums, cheaper
    stops = np.cumsum([len(r) for r in rings]).tolist()
    starts = [0, *stops[:-1]]
    total = np.add.reduce  # ndarray.sum without its Python wrapper
    return np.array([total(seg[a : max(a, b - 1)]) for a, b in zip(starts, stops, strict=True)])


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
    indptr_a, nbr_a, eid_a = adjacency(n, edges)
    degree_a = np.diff(indptr_a)
    # Python lists: the walks index them one element at a time
    indptr, nbr, eid, degree = indptr_a.tolist(), nbr_a.tolist(), eid_a.tolist(), degree_a.tolist()
    used = [False] * len(edges)
    paths: list[np.ndarray] = []

    def walk(start: int, j: int) -> np.ndarray:
        path = [start]
        while True:
            used[eid[j]] = True
            node = nbr[j]
            path.append(node)
            if degree[node] != 2:
                return np.array(path, np.int64)
            j = next((k for k in range(indptr[node], indptr[node + 1]) if not used[eid[k]]), -1)
            if j < 0:  # back at the start of a cycle
                return np.array(path, np.int64)

    for node in np.flatnonzero((degree_a != 2) & (degree_a > 0)).tolist():
        for j in range(indptr[node], indptr[node + 1]):
            if not used[eid[j]]:
                paths.append(walk(node, j))
    for node in np.flatnonzero(degree_a == 2).tolist():
        j = indptr[node]
        if not used[eid[j]]:
            paths.append(walk(node, j))
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


def _norm(v: np.ndarray) -> float:
    """``np.linalg.norm`` of a (3,) float64 vector, the same bits (its ``sqrt(v.dot(v))``)
    without its Python overhead."""
    return math.sqrt(v.dot(v))


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


def batch_tangents(pieces: list[Piece], window: float) -> np.ndarray:
    """:func:`tangents` of many pieces at once (open pieces in one vectorised pass),
    their vertices concatenated. Shape (sum of m, 3)."""
    if not pieces:
        return np.zeros((0, 3))
    sizes = np.array([len(pc.points) for pc in pieces])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    points = np.concatenate([pc.points for pc in pieces])
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    step[starts[1:] - 1] = 0.0  # no step between pieces
    cum = np.concatenate([[0.0], np.cumsum(step)])
    piece = np.repeat(np.arange(len(pieces)), sizes)
    cum -= cum[starts][piece]  # arc length within each piece
    gap = float(cum.max()) + 2 * window + 1.0  # pieces far apart on one axis
    key = cum + piece * gap
    lo, hi = starts[piece], (starts + sizes - 1)[piece]
    back = np.clip(np.searchsorted(key, key - window, side="right") - 1, lo, hi)
    ahead = np.clip(np.searchsorted(key, key + window, side="left"), lo, hi)
    out = _unit(points[ahead] - points[back])
    for i, pc in enumerate(pieces):
        if pc.closed:
            out[starts[i] : starts[i] + sizes[i]] = tangents(pc, window)
    return out


def _chords(piece: Piece, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit chords before and after each vertex (TURN_OUTER to TURN_INNER spacings of
    arc before it, TURN_INNER to TURN_OUTER after), at every scale of
    :data:`TURN_SCALES`, both pointing along the curve. Shapes (S, m, 3); zero where an
    open piece's end is nearer than TURN_INNER (times the scale)."""
    m = len(piece.points)
    pad = m if piece.closed else 0
    p = _padded(piece, pad)
    cum = _arc(p)
    scales = np.asarray(TURN_SCALES)[:, None] * spacing  # (S, 1)
    last = len(p) - 1

    def window(offset: np.ndarray, side: str, shift: int) -> np.ndarray:
        return np.clip(np.searchsorted(cum, cum[None, :] + offset, side=side) + shift, 0, last)

    far_b = window(-TURN_OUTER * scales, "right", -1)
    near_b = window(-TURN_INNER * scales, "right", -1)
    far_a = window(TURN_OUTER * scales, "left", 0)
    near_a = window(TURN_INNER * scales, "left", 0)
    before = _unit(p[near_b] - p[far_b])
    after = _unit(p[far_a] - p[near_a])
    return before[:, pad : pad + m], after[:, pad : pad + m]


def _least_turn(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """The turn between the chords (S, m, 3) before and after each vertex: the smallest
    over the scales whose chords are not empty, 0 where fewer than MIN_TURN_SCALES
    are. Degrees, shape (m,)."""
    valid = (np.linalg.norm(before, axis=2) > 0) & (np.linalg.norm(after, axis=2) > 0)
    cos = np.einsum("sij,sij->si", before, after)
    stack = np.where(valid, np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))), np.inf)
    least = np.min(stack, axis=0)
    enough = valid.sum(axis=0) >= MIN_TURN_SCALES
    return np.where(enough, least, 0.0)


def turn_angles(piece: Piece, spacing: float) -> np.ndarray:
    """Degrees the piece turns at each vertex (see :data:`CORNER_TURN`): the smallest
    of the turns measured with the chords at the :data:`TURN_SCALES` (a corner turns at
    all; a vertex off the line sways only the short chords, noise the shorter ones
    more; a circle turns more at the longer ones), over the scales whose chords fit on
    the piece; 0 where fewer than MIN_TURN_SCALES fit (near an open piece's ends).
    Shape (m,)."""
    return _least_turn(*_chords(piece, spacing))


@dataclass
class _ArcKeys:
    """Many polylines laid end to end for vectorised searches along their arcs.

    ``key`` is each vertex's arc length from its own polyline's start plus a per-polyline
    offset wider than any chord window, so that ``np.searchsorted(key, ...)`` finds
    positions along one polyline without reaching into the next.
    """

    points: np.ndarray  # (v, 3) the polylines' vertices, concatenated
    starts: np.ndarray  # (p,) first vertex of each polyline
    stops: np.ndarray  # (p,) last vertex of each polyline
    piece: np.ndarray  # (v,) polyline of each vertex
    scales: np.ndarray  # (S, 1) the TURN_SCALES in model units
    key: np.ndarray  # (v,) ascending

    @classmethod
    def of(cls, polylines: list[np.ndarray], spacing: float) -> _ArcKeys:
        """Of polylines of at least one vertex each ((m_i, 3) arrays)."""
        sizes = np.array([len(p) for p in polylines])
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        stops = starts + sizes - 1
        points = np.concatenate(polylines)
        step = np.linalg.norm(np.diff(points, axis=0), axis=1)
        step[starts[1:] - 1] = 0.0
        cum = np.concatenate([[0.0], np.cumsum(step)])
        piece = np.repeat(np.arange(len(polylines)), sizes)
        cum -= cum[starts][piece]
        scales = np.asarray(TURN_SCALES)[:, None] * spacing
        gap = float(cum.max()) + 2 * TURN_OUTER * float(scales.max()) + 1.0
        return cls(points, starts, stops, piece, scales, cum + piece * gap)


def _open_turn_angles(pieces: list[Piece], spacing: float) -> list[np.ndarray]:
    """:func:`turn_angles` of many open pieces in one vectorised pass (their arc lengths
    and chords as in :func:`_ends`). One (m,) array per piece."""
    if not pieces:
        return []
    arc = _ArcKeys.of([pc.points for pc in pieces], spacing)
    points, starts, stops, scales, key = arc.points, arc.starts, arc.stops, arc.scales, arc.key
    lo, hi = starts[arc.piece], stops[arc.piece]

    def window(offset: np.ndarray, side: str, shift: int) -> np.ndarray:
        return np.clip(np.searchsorted(key, key[None, :] + offset, side=side) + shift, lo, hi)

    before = _unit(
        points[window(-TURN_INNER * scales, "right", -1)]
        - points[window(-TURN_OUTER * scales, "right", -1)]
    )
    after = _unit(
        points[window(TURN_OUTER * scales, "left", 0)]
        - points[window(TURN_INNER * scales, "left", 0)]
    )
    return _split_rows(_least_turn(before, after), starts[1:])


def cut_at_turns(pieces: list[Piece], spacing: float) -> list[Piece]:
    """Split pieces where they turn by more than :data:`CORNER_TURN`.

    The cut vertex is the sharpest turn within TURN_OUTER spacings of arc; it ends both
    pieces it separates. Open pieces shorter than SHORTEST_CUT spacings are not cut.

    Parameters
    ----------
    pieces : list of Piece
    spacing : float

    Returns
    -------
    list of Piece
        In order; a piece itself when it has no sharp turn (or is a loop with only
        one).
    """
    long_open = np.flatnonzero(
        (piece_lengths(pieces) >= SHORTEST_CUT * spacing)
        & ~np.array([pc.closed for pc in pieces], bool)
    ).tolist()
    angles = dict(
        zip(long_open, _open_turn_angles([pieces[i] for i in long_open], spacing), strict=True)
    )
    out: list[Piece] = []
    for i, pc in enumerate(pieces):
        if pc.closed:
            out += _cut(pc, turn_angles(pc, spacing), spacing)
        elif i in angles:
            out += _cut(pc, angles[i], spacing)
        else:
            out.append(pc)  # too short to hold two curves
    return out


def _cut(piece: Piece, angle: np.ndarray, spacing: float) -> list[Piece]:
    """The piece split at its sharp turns, given its turn angles (m,)."""
    window = TURN_OUTER * spacing
    m = len(angle)
    cum = _arc(piece.points)
    total = piece.length if piece.closed else 0.0
    cuts: list[int] = []
    for i in np.argsort(-angle, kind="stable"):
        if angle[i] <= CORNER_TURN:
            break
        near = [c for c in cuts if abs(cum[c] - cum[i]) < window]
        if piece.closed:
            near = [
                c for c in cuts if min(abs(cum[c] - cum[i]), total - abs(cum[c] - cum[i])) < window
            ]
        if not near:
            cuts.append(int(i))
    if not cuts or (piece.closed and len(cuts) == 1):
        return [piece]  # a loop with one sharp turn: a wobble, not a teardrop
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
    out: np.ndarray  # (s, q, 3) unit direction leaving the curve (its end chord), per scale
    anchor: np.ndarray  # (s, q, 3) the end chord's vertex nearer the end, per scale


def _ends(pieces: list[Piece], spacing: float) -> _Ends:
    """The two ends of every open piece, with the chords of :func:`_chords` there at
    every scale of :data:`TURN_SCALES` (the whole piece's chord where a scale's chord
    is empty), pointing out of the piece. All pieces in one vectorised pass."""
    which = np.array(
        [i for i, pc in enumerate(pieces) if not pc.closed and len(pc.points) >= 2], np.int64
    )
    if len(which) == 0:
        z = np.zeros((0, 3))
        empty = np.zeros((len(TURN_SCALES), 0, 3))
        return _Ends(np.zeros(0, np.int64), np.zeros(0, np.int64), z, empty, empty)
    arc = _ArcKeys.of([pieces[i].points for i in which], spacing)
    points, starts, stops, scales, key = arc.points, arc.starts, arc.stops, arc.scales, arc.key
    first_key, last_key = key[starts], key[stops]

    def index(target: np.ndarray, side: str, shift: int) -> np.ndarray:
        return np.clip(np.searchsorted(key, target, side=side) + shift, starts, stops)

    near = index(first_key + TURN_INNER * scales, "left", 0)  # (S, q)
    far = index(first_key + TURN_OUTER * scales, "left", 0)
    near_b = index(last_key - TURN_INNER * scales, "right", -1)
    far_b = index(last_key - TURN_OUTER * scales, "right", -1)
    chord = points[stops] - points[starts]  # (q, 3)
    first = np.where((near == far)[..., None], chord, points[far] - points[near])
    last = np.where((near_b == far_b)[..., None], chord, points[near_b] - points[far_b])
    q = len(which)
    out = np.empty((len(TURN_SCALES), 2 * q, 3))
    out[:, 0::2] = -_unit(first)
    out[:, 1::2] = _unit(last)
    ends_points = np.empty((2 * q, 3))
    ends_points[0::2], ends_points[1::2] = points[starts], points[stops]
    anchor = np.empty((len(TURN_SCALES), 2 * q, 3))
    anchor[:, 0::2] = np.where((near == far)[..., None], points[starts], points[near])
    anchor[:, 1::2] = np.where((near_b == far_b)[..., None], points[stops], points[near_b])
    return _Ends(np.repeat(which, 2), np.tile([0, 1], q), ends_points, out, anchor)


def _split_rows(values: np.ndarray, bounds: np.ndarray) -> list[np.ndarray]:
    """``np.split(values, bounds)`` (views of the rows between the ascending ``bounds``,
    (p,) int), without its per-part overhead."""
    cuts = [0, *bounds.tolist(), len(values)]
    return [values[a:b] for a, b in itertools.pairwise(cuts)]


def _groups(roots: np.ndarray) -> list[np.ndarray]:
    """The indices sharing each root (ascending; groups in the order of their roots),
    the groups of two or more."""
    order = np.argsort(roots, kind="stable")
    bounds = np.flatnonzero(np.diff(roots[order])) + 1
    return [g for g in _split_rows(order, bounds) if len(g) >= 2]


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
    sets = DisjointSets(q)
    if q:
        of = ends.piece.tolist()
        pairs = sorted(cKDTree(ends.point).query_pairs(GAP_LENGTH * spacing))
        both = sorted({of[a] for a, b in pairs if of[a] == of[b]})
        lengths = piece_lengths([pieces[i] for i in both]).tolist()
        short = {
            i for i, x in zip(both, lengths, strict=True) if x < LOOP_LENGTH * GAP_LENGTH * spacing
        }
        for a, b in pairs:
            if of[a] == of[b] and of[a] in short:
                continue  # the two ends of a short piece: no loop
            sets.join(a, b)
    return ends, _groups(sets.roots())


def meeting_clusters(ends: _Ends, clusters: list[np.ndarray], spacing: float) -> list[np.ndarray]:
    """``clusters`` with the free ends (in no cluster) added to the ends whose lines they
    meet at a corner: where detection left a gap of more than GAP_LENGTH spacings at a
    corner. Two ends of different pieces within :data:`LONG_GAP` spacings meet when
    their lines (the end chords at :data:`CORNER_SCALE`, through the chords' vertices
    nearer the ends) cross at more than :data:`CORNER_TURN` and pass within
    :data:`LATERAL_OFFSET` spacings of each other, at most LONG_GAP spacings ahead of
    each end and at most LATERAL_OFFSET spacings behind it. Nearest pairs first; the
    result is grouped transitively.

    Parameters
    ----------
    ends : the curve ends (:func:`end_clusters`)
    clusters : list of (c,) int64
        The ends' clusters from :func:`end_clusters`.
    spacing : float

    Returns
    -------
    list of (c,) int64
        Indices into ``ends``, every cluster of two or more ends, deterministic order.
    """
    q = len(ends.piece)
    free = np.ones(q, bool)
    for c in clusters:
        free[c] = False
    if not free.any() or q < 2:
        return clusters
    sets = DisjointSets(q)  # over the ends, each cluster already one set
    for c in clusters:
        for i in c.tolist():
            sets.parent[i] = int(c[0])

    pairs = cKDTree(ends.point).query_pairs(LONG_GAP * spacing, output_type="ndarray")
    pairs = pairs[(free[pairs[:, 0]] | free[pairs[:, 1]])]
    pairs = pairs[ends.piece[pairs[:, 0]] != ends.piece[pairs[:, 1]]]
    gaps = np.linalg.norm(ends.point[pairs[:, 0]] - ends.point[pairs[:, 1]], axis=1)
    out, anchor = ends.out[CORNER_SCALE], ends.anchor[CORNER_SCALE]
    turn = math.cos(math.radians(CORNER_TURN))
    for k in np.lexsort((pairs[:, 1], pairs[:, 0], gaps)):
        a, b = int(pairs[k, 0]), int(pairs[k, 1])
        cos = float(out[a] @ out[b])
        if abs(cos) > turn:
            continue  # (anti)parallel: no corner
        w = anchor[a] - anchor[b]
        da, db = float(out[a] @ w), float(out[b] @ w)
        det = 1.0 - cos * cos
        sa, sb = (cos * db - da) / det, (db - cos * da) / det
        xa, xb = anchor[a] + sa * out[a], anchor[b] + sb * out[b]
        if _norm(xa - xb) > LATERAL_OFFSET * spacing:
            continue
        meet = 0.5 * (xa + xb)
        ahead = (
            float((meet - ends.point[a]) @ out[a]),
            float((meet - ends.point[b]) @ out[b]),
        )
        if min(ahead) < -LATERAL_OFFSET * spacing or max(ahead) > LONG_GAP * spacing:
            continue
        sets.join(a, b)
    return _groups(sets.roots())


def _continues(ends: _Ends, a: int, b: int, spacing: float) -> bool:
    """Ends ``a`` and ``b`` belong to one curve: at one scale of the end chords they face
    each other within :data:`CORNER_TURN`, and each end (or each chord's vertex nearer
    the end: noise bends the last vertices off the line) lies within
    :data:`LATERAL_OFFSET` spacings of the other's line (ends may overlap side by side
    where a skeleton broke a loop)."""
    limit = LATERAL_OFFSET * spacing
    for out, anchor in zip(ends.out, ends.anchor, strict=True):
        if -float(out[a] @ out[b]) < math.cos(math.radians(CORNER_TURN)):
            continue
        for gap in (ends.point[b] - ends.point[a], anchor[b] - anchor[a]):
            off_a = _norm(gap - (gap @ out[a]) * out[a])
            if not off_a <= limit:
                continue  # then max(off_a, off_b) <= limit fails too, NaN or not
            off_b = _norm(gap - (gap @ out[b]) * out[b])
            if max(off_a, off_b) <= limit:
                return True
    return False


#: Vertices (input indices, positions (k, 3)) strictly between two curve vertices given by
#: input index, on a mesh.
Bridge = Callable[[int, int], tuple[np.ndarray, np.ndarray]]


def _faces_gap(ends: _Ends, a: int, b: int) -> bool:
    """The gap from end ``a`` to end ``b`` leaves each end forwards (within
    :data:`CORNER_TURN`), at the widest chord scale."""
    gap = ends.point[b] - ends.point[a]
    length = _norm(gap)
    limit = math.cos(math.radians(CORNER_TURN)) * length
    return bool(gap @ ends.out[-1, a] >= limit and -gap @ ends.out[-1, b] >= limit)


def join_pieces(pieces: list[Piece], spacing: float, bridge: Bridge | None = None) -> list[Piece]:
    """Join pieces whose ends meet as one curve (two ends, facing each other), closing
    loops; ends meeting at a corner are left as they are. Two free ends (no other end
    within GAP_LENGTH) facing each other are also joined across up to
    :data:`LONG_GAP` spacings, nearest pairs first.

    Parameters
    ----------
    pieces : list of Piece
    spacing : float
    bridge : callable, optional
        The vertices to insert between two joined ends (meshes: a path along the mesh
        edges); none (a straight segment) by default.

    Returns
    -------
    list of Piece
    """
    ends, clusters = end_clusters(pieces, spacing)
    link: dict[tuple[int, int], tuple[int, int]] = {}

    def connect(i: int, j: int) -> None:
        a, b = int(ends.piece[i]), int(ends.piece[j])
        sa, sb = int(ends.side[i]), int(ends.side[j])
        if (a, sa) in link or (b, sb) in link:
            return
        if a == b and pieces[a].length < LOOP_LENGTH * GAP_LENGTH * spacing:
            return  # a short piece bent onto itself is no loop
        link[(a, sa)] = (b, sb)
        link[(b, sb)] = (a, sa)

    for c in clusters:
        if len(c) == 2 and _continues(ends, int(c[0]), int(c[1]), spacing):
            connect(int(c[0]), int(c[1]))
    free = np.ones(len(ends.piece), bool)
    for c in clusters:
        free[c] = False
    alone = np.flatnonzero(free)
    if len(alone) >= 2:
        pairs = cKDTree(ends.point[alone]).query_pairs(LONG_GAP * spacing, output_type="ndarray")
        pairs = alone[pairs]
        gaps = np.linalg.norm(ends.point[pairs[:, 0]] - ends.point[pairs[:, 1]], axis=1)
        for k in np.lexsort((pairs[:, 1], pairs[:, 0], gaps)):
            i, j = int(pairs[k, 0]), int(pairs[k, 1])
            if _continues(ends, i, j, spacing) and _faces_gap(ends, i, j):
                connect(i, j)
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
        if bridge is not None:
            parts = _bridged(parts, closed, bridge)
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


def _bridged(parts: list[Piece], closed: bool, bridge: Bridge) -> list[Piece]:
    """``parts`` with the bridge between consecutive parts (and from the last to the
    first when ``closed``) inserted where they do not share their end vertex."""
    out: list[Piece] = []
    pairs = list(zip(parts, parts[1:] + (parts[:1] if closed else []), strict=False))
    for a, b in pairs:
        out.append(a)
        if a.nodes[-1] != b.nodes[0]:
            nodes, points = bridge(int(a.nodes[-1]), int(b.nodes[0]))
            if len(nodes):
                out.append(Piece(nodes, points))
    if not closed:
        out.append(parts[-1])
    return out


def split_at_touches(pieces: list[Piece], spacing: float, lines: bool = False) -> list[Piece]:
    """Cut a curve where the free end of another one touches it (a T-junction whose
    stem detection left short of the line): at the vertex nearest the end, if it is
    within GAP_LENGTH spacings of the end and farther than that from both ends of its
    own curve. The cut and the end then meet at a corner.

    Parameters
    ----------
    pieces : list of Piece
    spacing : float
    lines : bool, default False
        Clouds: where no other curve is that near, the end's line reaches on
        (:func:`_vertex_ahead`): detection thins out where three faces meet, and the
        stem may stop up to LONG_GAP spacings short of the curve it meets.

    Returns
    -------
    list of Piece
    """
    ends, clusters = end_clusters(pieces, spacing)
    free = np.ones(len(ends.piece), bool)
    for c in clusters:
        free[c] = False
    if not free.any():
        return pieces
    owner = np.concatenate([np.full(len(pc.points), i) for i, pc in enumerate(pieces)])
    local = np.concatenate([np.arange(len(pc.points)) for pc in pieces])
    tree = cKDTree(np.concatenate([pc.points for pc in pieces]))
    reach = GAP_LENGTH * spacing
    cuts: dict[int, set[int]] = {}
    for e in np.flatnonzero(free):
        near = tree.query_ball_point(ends.point[e], reach)
        near = [j for j in near if owner[j] != ends.piece[e]]
        if near:
            j = min(near, key=lambda j: (_norm(tree.data[j] - ends.point[e]), j))
        else:
            j = _vertex_ahead(ends, int(e), tree, owner, spacing) if lines else -1
            if j < 0:
                continue
        pc, v = pieces[owner[j]], int(local[j])
        cum = _arc(pc.points)
        if pc.closed or (cum[v] > reach and cum[-1] - cum[v] > reach):
            cuts.setdefault(int(owner[j]), set()).add(v)
    if not cuts:
        return pieces
    out = []
    for i, pc in enumerate(pieces):
        if i not in cuts:
            out.append(pc)
            continue
        at = sorted(cuts[i])
        if pc.closed:
            m = len(pc.points)
            order = np.concatenate([np.arange(at[0], m), np.arange(at[0] + 1)])
            bounds = [a - at[0] for a in at] + [m]
        else:
            order = np.arange(len(pc.points))
            bounds = [0, *at, len(pc.points) - 1]
        for a, b in itertools.pairwise(bounds):
            if b > a:
                sel = order[a : b + 1]
                out.append(Piece(pc.nodes[sel], pc.points[sel]))
    return out


def _vertex_ahead(ends: _Ends, e: int, tree: cKDTree, owner: np.ndarray, spacing: float) -> int:
    """The vertex of another curve (an index into ``tree``'s points, owned by the pieces
    ``owner``) that end ``e``'s line (the end chord at :data:`CORNER_SCALE`) reaches
    first: ahead of the end, within LONG_GAP spacings of it and LATERAL_OFFSET
    spacings of the line (the lowest index of equally near ones); -1 when none."""
    out, anchor, point = ends.out[CORNER_SCALE][e], ends.anchor[CORNER_SCALE][e], ends.point[e]
    limit = LATERAL_OFFSET * spacing
    best, best_key = -1, (math.inf, 0)
    for j in tree.query_ball_point(point, LONG_GAP * spacing):
        if owner[j] == ends.piece[e]:
            continue
        q = tree.data[j]
        ahead = float((q - point) @ out)
        w = q - anchor
        if ahead <= 0.0 or _norm(w - float(w @ out) * out) > limit:
            continue
        if (ahead, j) < best_key:
            best, best_key = int(j), (ahead, j)
    return best
