"""Feature curves from a detection: the skeleton of the feature points, traced into
polylines, refined (clouds), cut and joined at corners (the numpy reference of the native
library's native/src/curves.cpp; :func:`meshlab_sharp.curves.extract_curves` classifies
them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..._header import CURVES
from .graph import (
    BRIDGE_ANGLE,
    BRIDGE_REACH,
    IRREGULAR_BRIDGE_ANGLE,
    IRREGULAR_BRIDGE_REACH,
    SPUR_LENGTH,
    MeshPaths,
    bridge_leaves,
    close_loops,
    cloud_graph,
    mesh_graph,
    prune_spurs,
    spanning_forest,
)
from .mesh import CreaseChains, crease_chains
from .refine import (
    cell_neighbourhood,
    line_fit_positions,
    plane_intersection_positions,
    refine_neighbours,
)
from .trace import (
    CORNER_SCALE,
    GAP_LENGTH,
    LONG_GAP,
    LOOP_LENGTH,
    Bridge,
    Piece,
    batch_tangents,
    cut_at_turns,
    end_clusters,
    join_pieces,
    meeting_clusters,
    piece_lengths,
    split_at_touches,
    trace_paths,
)

__all__ = [
    "MIN_CURVE_LENGTH",
    "CurveSet",
    "cloud_spacing",
    "extract_curves",
    "local_spacings",
    "support_radius",
]

# The numbers are defined once, in native/include/meshlab_sharp.h.
#: An open curve shorter than this, in spacings (GAP_LENGTH), is dropped: what is left of a spur
#: between two junctions, or a blob of false detections.
MIN_CURVE_LENGTH = CURVES.real("MIN_CURVE_LENGTH")
#: A piece shorter than this, in spacings (twice GAP_LENGTH), from a junction of three
#: or more curve ends to a free end is a spur (noise beside a line) and is dropped.
SPUR_PIECE = CURVES.real("SPUR_PIECE")
#: A skeleton piece of a cloud is dropped when at more than this share of its vertices
#: the two surfaces fitted around it meet at less than the crease angle: false
#: detections on a smooth or noisy surface (near corners the fit fails otherwise and
#: does not count).
MAX_FLAT_SHARE = CURVES.real("MAX_FLAT_SHARE")
#: Side of the grid cells, in feature spacings, that select the points near the curves
#: for the refinement (3x3x3 cells around each feature hold its REFINE_NEIGHBOURS).
CELL_SPACINGS = CURVES.real("CELL_SPACINGS")
#: Irregular (iid) clouds: where DENSITY_SCALE times the median distance from a feature
#: to its DENSITY_NEIGHBOURS-th nearest point exceeds the median nearest distance d by a
#: factor q > 1, the spacing is d q^1.5. Independently drawn points cluster: their
#: nearest distances are short (0.6 times blue noise's of the same density) and the
#: features along an edge leave gaps of several of them, which split the feature graph.
#: On Poisson-disk (blue noise) clouds, noisy or not, d is 0.47-0.50 times the 8th
#: nearest distance (q < 1): they are regular and keep d; on iid clouds d is 0.30-0.33
#: times it (q about 1.4, the spacing about 1.7 d, blue noise's of the same density).
DENSITY_NEIGHBOURS = CURVES.integer("DENSITY_NEIGHBOURS")
#: See DENSITY_NEIGHBOURS.
DENSITY_SCALE = CURVES.real("DENSITY_SCALE")
#: A cloud feature's own spacing (:func:`local_spacings`, which links the feature graph
#: where a scan's density falls with range) is at most this many times the cloud's.
MAX_LOCAL_SPACING = CURVES.real("MAX_LOCAL_SPACING")
#: Before the joins, a regular cloud's pieces and spurs are dropped only below this
#: share of MIN_CURVE_LENGTH and SPUR_PIECE (an irregular cloud's none, a mesh's all):
#: the shortest are noise beside the edges, the others may be parts of an edge that
#: noise or the sampling cut, and join.
EARLY_DROP = CURVES.real("EARLY_DROP")
#: Cloud vertices closer than this along the curve's direction to the previous vertex
#: kept, in spacings, are dropped after refinement (a skeleton that zigzags across a
#: wide band of features leaves vertices that double back once refined).
MIN_ADVANCE = CURVES.real("MIN_ADVANCE")
#: Vertices on each side of a vertex in the fallback line fit (2 spacings or so).
LINE_FIT_HALF = CURVES.integer("LINE_FIT_HALF")
#: Half-width, in spacings of arc, of the chord giving the skeleton's direction at a
#: vertex, across which the vertex is refined (clouds): twice TANGENT_WINDOW.
RAW_TANGENT_WINDOW = CURVES.real("RAW_TANGENT_WINDOW")
#: A curve end farther than this, in spacings, from its corner gets the corner as an
#: extra vertex; a nearer one moves onto the corner (clouds).
SNAP = CURVES.real("SNAP")
#: The corner where curve ends meet is the least-squares meeting point of their lines
#: only where that 3x3 system's condition number is below this (lines not nearly
#: parallel).
MAX_CORNER_CONDITION = CURVES.real("MAX_CORNER_CONDITION")
#: Of the curve ends meeting at a corner (clouds), those whose lines pass farther than
#: this, in spacings, from the others' meeting point are left out of it, the farthest
#: first: a short piece's direction is noisy, and the ends of two corners a few
#: spacings apart fall into one group; two or more left out meet at a corner of
#: their own.
CORNER_OFFSET = CURVES.real("CORNER_OFFSET")


@dataclass
class CurveSet:
    """The feature curves and corners of a detection, before classification.

    Attributes
    ----------
    curves : list of ((m, 3) float64, (m,) int64, bool, float)
        Each curve's vertices in order, the input point (mesh vertex) each came from,
        whether it is a loop (the last vertex connects to the first, which is not
        repeated), and its length (the closing segment included); in a deterministic
        order (by first vertex, last vertex, length), independent of the input's order.
        Clouds: refined positions, a vertex moved onto a corner keeps the index of the
        point it came from, an added corner vertex has the corner's index; meshes: mesh
        vertices.
    corner_points : (c, 3) float64
        Where curves meet at an angle or three or more curves meet, in coordinate order
        (clouds: where the curves' end lines meet; meshes: a mesh vertex).
    corner_indices : (c,) int64
        The input point (mesh vertex) nearest each corner among the curves' ends.
    spacing : float
        The spacing the steps are measured in (0 when there is no curve).
    """

    curves: list[tuple[np.ndarray, np.ndarray, bool, float]]
    corner_points: np.ndarray
    corner_indices: np.ndarray
    spacing: float


def _no_curves() -> CurveSet:
    return CurveSet([], np.zeros((0, 3)), np.zeros(0, np.int64), 0.0)


def extract_curves(
    vertices: np.ndarray,
    mask: np.ndarray,
    faces: np.ndarray | None = None,
    valid: np.ndarray | None = None,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
) -> CurveSet:
    """Feature curves and corners of a detection, unclassified: the arguments of
    :func:`meshlab_sharp.curves.extract_curves` (but its ``backend``).

    Returns
    -------
    CurveSet
    """
    pts = np.asarray(vertices, np.float64)
    feat_mask = np.asarray(mask, bool)
    ok = np.ones(len(pts), bool) if valid is None else np.asarray(valid, bool)
    feat = np.flatnonzero(feat_mask & ok)
    # nodes: distinct feature positions in coordinate order (independent of input order)
    fp = pts[feat]
    order = np.lexsort((feat, fp[:, 2], fp[:, 1], fp[:, 0]))
    feat, fp = feat[order], fp[order]
    if len(fp):
        first = np.ones(len(fp), bool)
        first[1:] = (fp[1:] != fp[:-1]).any(axis=1)
        feat, fp = feat[first], fp[first]
    if len(feat) < 2:
        return _no_curves()
    paths: MeshPaths | None = None
    creases: CreaseChains | None = None
    irregular = False
    if faces is None:
        pieces, spacing, irregular = _cloud_pieces(pts, feat_mask, ok, feat, fp, bounds)
    else:
        usable = np.zeros(len(pts), bool)
        usable[feat] = True
        creases = crease_chains(pts, np.asarray(faces), feat_mask & ok, usable)
        pieces, spacing = _mesh_pieces(
            pts, np.asarray(faces), feat_mask & ok, feat, fp, creases.rest
        )
        paths = MeshPaths(pts, np.asarray(faces), creases.rest)
    if spacing <= 0:
        return _no_curves()
    bridge = None if paths is None else _bridge(pts, paths, spacing)
    pieces = cut_at_turns(pieces, spacing)
    # a mesh's short pieces are dropped before joining; a cloud's sampling gaps cut an
    # edge's features into short pieces, which join first: on a regular cloud only the
    # shortest are dropped before, on an irregular one (iid points, a scan) none
    if paths is not None:
        pieces = _drop_short(pieces, spacing)
    elif not irregular:
        pieces = _drop_short(pieces, spacing, EARLY_DROP)
    pieces = _drop_short(join_pieces(pieces, spacing, bridge), spacing)
    pieces = join_pieces(pieces, spacing, bridge)
    # joining may have run a curve round a corner whose vertex was near a piece's end
    pieces = cut_at_turns(pieces, spacing)
    pieces = split_at_touches(pieces, spacing, lines=paths is None)
    if paths is None:
        pieces = _drop_isolated(pieces, spacing)
    pieces, corner_points, corner_indices = _corners(pieces, spacing, pts, paths)
    if creases is not None and len(creases.pieces):
        pieces += creases.pieces
        corner_points, corner_indices = _merged_corners(
            corner_points, corner_indices, pts, creases.corners
        )
    oriented = [_oriented(pc) for pc in pieces if len(pc.points) >= 2]
    lengths = piece_lengths(oriented).tolist()
    order = sorted(
        range(len(oriented)),
        key=lambda i: (*oriented[i].points[0], *oriented[i].points[-1], lengths[i]),
    )
    curves = [
        (oriented[i].points, oriented[i].nodes, oriented[i].closed, lengths[i]) for i in order
    ]
    return CurveSet(curves, corner_points, corner_indices, spacing)


def _skeleton_pieces(
    n: int,
    edges: np.ndarray,
    weights: np.ndarray,
    positions: np.ndarray,
    spacing: float,
    bridge: tuple[float, float] | None = None,
) -> list[np.ndarray]:
    """The skeleton's paths; ``bridge``: the free ends' reach (spacings) and angle
    (degrees) for :func:`meshlab_sharp.reference.curves.graph.bridge_leaves`, none by
    default (meshes)."""
    forest = spanning_forest(n, edges, weights)
    forest = close_loops(n, forest, edges, positions, LOOP_LENGTH * GAP_LENGTH * spacing)
    if bridge is not None:
        forest = bridge_leaves(n, forest, positions, bridge[0] * spacing, bridge[1])
    forest = prune_spurs(n, forest, positions, SPUR_LENGTH * spacing)
    return trace_paths(n, forest)


def support_radius(features: np.ndarray) -> float:
    """Side of the grid cells around the features whose valid points the refinement of
    a cloud's curves reads: CELL_SPACINGS times the median distance from a feature to
    the nearest other one.

    Parameters
    ----------
    features : (f, 3) float64
        The distinct feature positions, any order, f >= 2.
    """
    d, _ = cKDTree(features).query(features, k=2, workers=-1)
    return CELL_SPACINGS * float(np.median(d[:, 1]))


def cloud_spacing(tree: cKDTree, features: np.ndarray) -> tuple[float, bool]:
    """Spacing of a cloud's curves, and whether the cloud is irregular (iid).

    ``d`` the median distance from a feature to the nearest other point, ``q``
    DENSITY_SCALE times the median distance to the DENSITY_NEIGHBOURS-th nearest over
    ``d``: the spacing is ``d`` where ``q <= 1``, else ``d * (q * sqrt(q))`` (irregular).

    Parameters
    ----------
    tree : cKDTree
        Of the points near the features (the features among them), at least 2.
    features : (f, 3) float64
        The distinct feature positions.

    Returns
    -------
    spacing : float
    irregular : bool
    """
    d = _neighbour_distances(tree, features)
    nearest = float(np.median(d[:, 1]))
    density = DENSITY_SCALE * float(np.median(d[:, -1]))
    if nearest <= 0.0 or not density > nearest:
        return nearest, False
    q = density / nearest
    return nearest * (q * math.sqrt(q)), True


def local_spacings(tree: cKDTree, features: np.ndarray, spacing: float) -> np.ndarray:
    """Each feature's own spacing, (f,) float64: DENSITY_SCALE times its distance to the
    DENSITY_NEIGHBOURS-th nearest point, clipped to 1 to MAX_LOCAL_SPACING times the
    cloud's ``spacing``; ``tree`` and ``features`` as for :func:`cloud_spacing`."""
    d = _neighbour_distances(tree, features)
    return np.minimum(np.maximum(DENSITY_SCALE * d[:, -1], spacing), MAX_LOCAL_SPACING * spacing)


def _neighbour_distances(tree: cKDTree, features: np.ndarray) -> np.ndarray:
    """Distances (f, k) from each feature to its k nearest points (itself first), k
    DENSITY_NEIGHBOURS + 1 or the tree's size if smaller."""
    return tree.query(features, k=min(DENSITY_NEIGHBOURS + 1, tree.n), workers=-1)[0]


def _cloud_pieces(
    pts: np.ndarray,
    mask: np.ndarray,
    ok: np.ndarray,
    feat: np.ndarray,
    fp: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[list[Piece], float, bool]:
    """Skeleton polylines of a cloud's features, refined; the spacing; whether the
    cloud is irregular (:func:`cloud_spacing`)."""
    near = cell_neighbourhood(pts, ok, fp, support_radius(fp), bounds)
    near_pts = pts[near]
    order = np.lexsort((near_pts[:, 2], near_pts[:, 1], near_pts[:, 0]))
    near, near_pts = near[order], near_pts[order]
    tree = cKDTree(near_pts)
    spacing, irregular = cloud_spacing(tree, fp)
    edges, lengths = cloud_graph(fp, spacing, local_spacings(tree, fp, spacing))
    bridge = (
        (IRREGULAR_BRIDGE_REACH, IRREGULAR_BRIDGE_ANGLE)
        if irregular
        else (BRIDGE_REACH, BRIDGE_ANGLE)
    )
    paths = _skeleton_pieces(len(fp), edges, lengths, fp, spacing, bridge)
    pieces = []
    for path in paths:
        closed = len(path) > 2 and path[0] == path[-1]
        nodes = path[:-1] if closed else path
        pieces.append(Piece(nodes, fp[nodes], closed))
    if not pieces:
        return [], spacing, irregular
    # refine every vertex at once, across the skeleton's directions over a wide window
    # (the skeleton zigzags across the band of features)
    raw = np.concatenate([pc.points for pc in pieces])
    neighbours = refine_neighbours(tree, raw)
    dirs = batch_tangents(pieces, RAW_TANGENT_WINDOW * spacing)
    moved, fitted, flat = plane_intersection_positions(
        raw, dirs, neighbours, near_pts, mask[near], spacing
    )
    sizes = np.array([len(pc.points) for pc in pieces])
    closed = np.array([pc.closed for pc in pieces])
    # where the fit failed, onto the line of the curve's own vertices; then smoothed
    # along the curve: each vertex onto the line of its neighbours
    line = line_fit_positions(raw, dirs, sizes, closed, LINE_FIT_HALF)
    smooth = line_fit_positions(
        np.where(fitted[:, None], moved, line), dirs, sizes, closed, LINE_FIT_HALF
    )
    ends = np.cumsum(sizes).tolist()
    n_flat = np.add.reduceat(flat.astype(np.int64), [0, *ends[:-1]]).tolist()
    out = []
    for pc, stop, size, n_no_edge in zip(pieces, ends, sizes.tolist(), n_flat, strict=True):
        if n_no_edge / size > MAX_FLAT_SHARE:
            continue  # not an edge between two surfaces: false detections
        p, d = smooth[stop - size : stop], dirs[stop - size : stop]
        keep = _advancing(p, d, spacing)
        out.append(Piece(feat[pc.nodes[keep]], p[keep], pc.closed))
    return out, spacing, irregular


def _advancing(p: np.ndarray, t: np.ndarray, spacing: float) -> np.ndarray:
    """Indices of the vertices that advance by at least MIN_ADVANCE spacings along the
    curve's direction from the previous one kept (the last vertex always kept)."""
    rows, dirs = list(p), list(t)  # row views made at once
    keep, last = [0], rows[0]
    step = MIN_ADVANCE * spacing
    for i in range(1, len(p) - 1):
        if float((rows[i] - last) @ dirs[i]) >= step:
            keep.append(i)
            last = rows[i]
    if len(p) > 1:
        keep.append(len(p) - 1)
    return np.array(keep, np.int64)


def _mesh_pieces(
    pts: np.ndarray,
    faces: np.ndarray,
    mask: np.ndarray,
    feat: np.ndarray,
    fp: np.ndarray,
    rest: np.ndarray,
) -> tuple[list[Piece], float]:
    """Skeleton chains of mesh edges between the feature vertices ``rest`` (n,) bool
    (those away from the mesh's sharp edges, :func:`.mesh.crease_chains`); and the
    spacing (median length of the edges around all the features ``mask``)."""
    edges, weights, around = mesh_graph(pts, faces, mask)
    if len(edges) == 0:
        return [], 0.0
    spacing = float(np.median(around))
    node = np.full(len(pts), -1, np.int64)
    node[feat] = np.arange(len(feat))
    local = node[edges]
    # duplicated positions keep one vertex
    keep = (local >= 0).all(axis=1) & rest[edges[:, 0]] & rest[edges[:, 1]]
    paths = _skeleton_pieces(len(feat), local[keep], weights[keep], fp, spacing)
    pieces = []
    for path in paths:
        closed = len(path) > 2 and path[0] == path[-1]
        nodes = path[:-1] if closed else path
        pieces.append(Piece(feat[nodes], fp[nodes], closed))
    return pieces, spacing


def _bridge(pts: np.ndarray, paths: MeshPaths, spacing: float) -> Bridge:
    """Mesh vertices between two curve vertices: the shortest path along the mesh edges
    near the features (none when longer than twice GAP_LENGTH spacings)."""

    def bridge(a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        inner = paths.path(a, b, 2 * GAP_LENGTH * spacing)
        inner = np.zeros(0, np.int64) if inner is None else inner
        return inner, pts[inner]

    return bridge


def _drop_short(pieces: list[Piece], spacing: float, share: float = 1.0) -> list[Piece]:
    """Leave out open pieces shorter than ``share`` times MIN_CURVE_LENGTH spacings, and
    spurs: pieces shorter than ``share`` times SPUR_PIECE spacings with one end free and
    the other where three or more ends meet."""
    ends, clusters = end_clusters(pieces, spacing)
    size = np.ones(len(ends.piece), np.int64)
    for c in clusters:
        size[c] = len(c)
    spur = set()
    for i in range(0, len(ends.piece), 2):  # the two ends of one piece are consecutive
        if sorted((size[i], size[i + 1]))[0] == 1 and max(size[i], size[i + 1]) >= 3:
            spur.add(int(ends.piece[i]))
    lengths = piece_lengths(pieces).tolist()
    return [
        pc
        for i, (pc, length) in enumerate(zip(pieces, lengths, strict=True))
        if pc.closed
        or (
            length >= share * MIN_CURVE_LENGTH * spacing
            and (i not in spur or length >= share * SPUR_PIECE * spacing)
        )
    ]


def _drop_isolated(pieces: list[Piece], spacing: float) -> list[Piece]:
    """Leave out open pieces shorter than SPUR_PIECE spacings whose two ends are free (no
    other end within GAP_LENGTH spacings, nor one whose line meets theirs at a corner):
    fragments of detections along noisy edges (clouds)."""
    ends, clusters = end_clusters(pieces, spacing)
    joined = np.zeros(len(pieces), bool)
    for c in meeting_clusters(ends, clusters, spacing):
        joined[ends.piece[c]] = True
    lengths = piece_lengths(pieces)
    return [
        pc
        for i, pc in enumerate(pieces)
        if pc.closed or joined[i] or lengths[i] >= SPUR_PIECE * spacing
    ]


def _corners(
    pieces: list[Piece], spacing: float, pts: np.ndarray, paths: MeshPaths | None
) -> tuple[list[Piece], np.ndarray, np.ndarray]:
    """Corners where curve ends meet (not as one continuing curve), and the ends brought
    onto them. The corner is the point nearest the lines of the ends (least squares).
    On a cloud the ends whose lines meet across a wider gap join the corner too
    (:func:`meshlab_sharp.reference.curves.trace.meeting_clusters`), and the lines are the end
    chords at CORNER_SCALE; on a mesh, the lines of the last edges, and the corner is
    the mesh vertex nearest their meeting point, reached from each end along mesh
    edges (``paths``). Returns the pieces, and the corners' points (c, 3) and indices
    (c,) in coordinate order."""
    ends, clusters = end_clusters(pieces, spacing)
    # clouds: the end lines 2-8 spacings back (noise bends the last vertices), which
    # may meet far from the ends; meshes: the lines of the last mesh edges
    if paths is None:
        clusters = meeting_clusters(ends, clusters, spacing)
        out, through = ends.out[CORNER_SCALE], ends.anchor[CORNER_SCALE]
    else:
        out, through = ends.out[0], ends.point
    points, indices = [], []
    pieces = [Piece(pc.nodes.copy(), pc.points.copy(), pc.closed) for pc in pieces]
    work = list(clusters)
    while work:
        c = work.pop(0)
        a, b = _line_system(c, out, through)
        if paths is None and np.linalg.cond(a) < MAX_CORNER_CONDITION:
            # ends whose lines pass far from the others' meeting point: a short piece's
            # noisy direction, or the ends of a nearby corner; two or more meet apart
            rest = _outlying(c, out, through, spacing)
            if len(rest):
                kept = c[~np.isin(c, rest)]
                a, b = _line_system(kept, out, through)
                if len(rest) >= 2:
                    work.append(rest)
                    c = kept
        mean = ends.point[c].mean(axis=0)
        corner = mean
        if np.linalg.cond(a) < MAX_CORNER_CONDITION:
            x = _solve3(a, b)
            if paths is None:  # within LONG_GAP spacings of every end
                near = np.linalg.norm(ends.point[c] - x, axis=1).max() <= LONG_GAP * spacing
            else:
                near = np.linalg.norm(x - mean) <= GAP_LENGTH * spacing
            if near:
                corner = x
        if paths is None:
            nearest = int(c[np.argmin(np.linalg.norm(ends.point[c] - corner, axis=1))])
            pc0 = pieces[ends.piece[nearest]]
            index = int(pc0.nodes[0] if ends.side[nearest] == 0 else pc0.nodes[-1])
        else:
            index = paths.nearest(corner)
            corner = pts[index].copy()
        points.append(corner)
        indices.append(index)
        for i in c:
            pc = pieces[ends.piece[i]]
            at = 0 if ends.side[i] == 0 else len(pc.nodes) - 1
            here = int(pc.nodes[at])
            if here == index or (
                paths is None and np.linalg.norm(pc.points[at] - corner) <= SNAP * spacing
            ):
                pc.points[at] = corner
                continue
            inner = None if paths is None else paths.path(here, index, 2 * GAP_LENGTH * spacing)
            add = np.append(np.zeros(0, np.int64) if inner is None else inner, index)
            add_points = np.vstack([pts[add[:-1]], corner])
            if ends.side[i] == 0:
                pc.nodes = np.concatenate([add[::-1], pc.nodes])
                pc.points = np.vstack([add_points[::-1], pc.points])
            else:
                pc.nodes = np.concatenate([pc.nodes, add])
                pc.points = np.vstack([pc.points, add_points])
    # a short piece with both ends brought onto one corner is a knot of detections there
    short = LOOP_LENGTH * GAP_LENGTH * spacing
    pieces = [
        pc
        for pc in pieces
        if pc.closed or not np.array_equal(pc.points[0], pc.points[-1]) or pc.length >= short
    ]
    if not points:
        return pieces, np.zeros((0, 3)), np.zeros(0, np.int64)
    p = np.array(points)
    order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))
    return pieces, p[order], np.array(indices, np.int64)[order]


def _line_system(
    c: np.ndarray, out: np.ndarray, through: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The normal equations ``a x = b`` ((3, 3), (3,)) of the point nearest the lines
    through ``through[i]`` along the unit ``out[i]``, ``i`` in ``c``."""
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for i in c:
        proj = np.eye(3) - np.outer(out[i], out[i])
        a += proj
        b += proj @ through[i]
    return a, b


def _outlying(c: np.ndarray, out: np.ndarray, through: np.ndarray, spacing: float) -> np.ndarray:
    """The ends of the cluster ``c`` (whose lines' system is well-conditioned) whose
    lines pass farther than CORNER_OFFSET spacings from the meeting point of the
    others' (least squares): the farthest (the first of equally far ones) left out
    first, one at a time, while more than two remain and their system stays
    well-conditioned. Ascending."""
    kept = [int(i) for i in c]
    a, b = _line_system(c, out, through)
    while len(kept) > 2:
        x = _solve3(a, b)
        far, worst = CORNER_OFFSET * spacing, -1
        for i in kept:
            v = x - through[i]
            r = v - float(v @ out[i]) * out[i]
            d = math.sqrt(float(r @ r))
            if d > far:
                far, worst = d, i
        if worst < 0:
            break
        trial = [i for i in kept if i != worst]
        a, b = _line_system(np.array(trial), out, through)
        if not np.linalg.cond(a) < MAX_CORNER_CONDITION:
            break
        kept = trial
    return np.array(sorted(set(c.tolist()) - set(kept)), np.int64)


def _merged_corners(
    points: np.ndarray, indices: np.ndarray, pts: np.ndarray, more: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The corners ``points`` (c, 3) and ``indices`` (c,) with the mesh vertices
    ``more`` (k,) added, all in coordinate order."""
    p = np.vstack([points, pts[more]])
    i = np.concatenate([indices, more]).astype(np.int64)
    order = np.lexsort((p[:, 2], p[:, 1], p[:, 0]))
    return p[order], i[order]


def _solve3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with a x = b for a (3, 3) non-singular: Gaussian elimination with partial
    pivoting in plain floats, the native library's arithmetic (``solve3`` in native/src/curves.cpp),
    so that both place a corner on the same bits (on a regular grid, corners tie in
    a coordinate and their order is decided by the last bits). Shape (3,)."""
    m = [[float(v) for v in row] for row in a]
    y = [float(v) for v in b]
    for c in range(3):
        piv = max(range(c, 3), key=lambda r: (abs(m[r][c]), -r))  # the first largest
        m[c], m[piv] = m[piv], m[c]
        y[c], y[piv] = y[piv], y[c]
        for r in range(c + 1, 3):
            f = m[r][c] / m[c][c]
            for k in range(c, 3):
                m[r][k] -= f * m[c][k]
            y[r] -= f * y[c]
    x = [0.0, 0.0, 0.0]
    for r in (2, 1, 0):
        s = y[r]
        for k in range(r + 1, 3):
            s -= m[r][k] * x[k]
        x[r] = s / m[r][r]
    return np.array(x)


def _oriented(pc: Piece) -> Piece:
    """The final curve in canonical orientation: an open curve from its lesser end, a
    loop from its least vertex towards the lesser of its two neighbours."""
    p, n = pc.points, pc.nodes
    if pc.closed:
        start = int(np.lexsort(p.T[::-1])[0])
        p, n = np.roll(p, -start, axis=0), np.roll(n, -start)
        if len(p) > 2 and tuple(p[-1]) < tuple(p[1]):
            p = np.vstack([p[:1], p[:0:-1]])
            n = np.concatenate([n[:1], n[:0:-1]])
    elif tuple(p[-1]) < tuple(p[0]):
        p, n = p[::-1], n[::-1]
    nodes = np.ascontiguousarray(n, dtype=np.int64)
    return Piece(nodes, np.ascontiguousarray(p), bool(pc.closed))
