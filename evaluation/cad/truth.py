"""Exact sharp edges of a B-rep, read through gmsh's OpenCASCADE kernel.

A B-rep curve between two faces is **sharp** where the faces' normals differ by
:data:`SHARP_ANGLE` degrees or more: the curve is sampled every ``step`` of its length
(at least :data:`MIN_SAMPLES` samples), the normal of each adjacent face is evaluated
at the sample (``gmsh.model.getNormal`` at the sample's parametric coordinates on the
face), and a piece between two samples is sharp when both its ends are. A curve with
one adjacent face (a seam, as on a cylinder) or none is never sharp. A **corner** is a
B-rep vertex where three or more sharp curves end (sharp at that end). A mesh's own
dihedral angles are never used: a coarse tessellation makes false creases.

The truth is **ambiguous** where a sharp or nearly sharp curve has an angle between
:data:`AMBIGUOUS_ANGLES` (a detection may or may not call it sharp), or where two
separate sharp features come closer than :data:`CLOSE_SPACINGS` point spacings (the
features merge at that sampling): two corners, or two points of the sharp edges
whose way between them along the sharp edges is more than twice their distance (two
curves that do not meet, or meet only far away or at a sharp angle; one curve that
comes back near itself), see :func:`closest_gap`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "AMBIGUOUS_ANGLES",
    "CLOSE_SPACINGS",
    "MIN_SAMPLES",
    "SHARP_ANGLE",
    "BrepTruth",
    "brep_truth",
    "closest_gap",
]

#: Degrees: a curve is sharp where its faces' normals differ by this much or more.
SHARP_ANGLE = 20.0
#: Degrees: angles in this range make the truth ambiguous.
AMBIGUOUS_ANGLES = (15.0, 30.0)
#: Spacings: separate sharp features closer than this make the truth ambiguous.
CLOSE_SPACINGS = 3.0
#: Samples along every curve, at least.
MIN_SAMPLES = 16


@dataclass(frozen=True)
class BrepTruth:
    """The sharp edges of one B-rep.

    Attributes
    ----------
    segments : (e, 2, 3) float64
        The sharp pieces of the curves, as segments between consecutive samples.
    segment_curve : (e,) int64
        The B-rep curve tag of each segment.
    corners : (c, 3) float64
        B-rep vertices where three or more sharp curves end.
    sharp_curves : tuple of int
        Tags of the curves with at least one sharp piece.
    angles : dict of int to (float, float)
        Per curve between two faces: the smallest and largest angle between the
        faces' normals along it, in degrees.
    diagonal : float
        The bounding-box diagonal of the model.
    curve_vertices : dict of int to tuple of int
        The end vertices of every sharp curve, the one at its first sample first (a
        closed curve has one).
    """

    segments: np.ndarray
    segment_curve: np.ndarray
    corners: np.ndarray
    sharp_curves: tuple[int, ...]
    angles: dict[int, tuple[float, float]]
    diagonal: float
    curve_vertices: dict[int, tuple[int, ...]] = field(default_factory=dict)

    @property
    def edge_length(self) -> float:
        """Total length of the sharp pieces."""
        return float(np.linalg.norm(self.segments[:, 1] - self.segments[:, 0], axis=1).sum())

    def ambiguous_angles(self) -> list[int]:
        """Curves with an angle in :data:`AMBIGUOUS_ANGLES` somewhere along them."""
        lo, hi = AMBIGUOUS_ANGLES
        return [c for c, (a, b) in self.angles.items() if a < hi and b > lo]


def _face_normals(face: int, points: np.ndarray) -> np.ndarray:
    """Unit normals of a face at points on its boundary (parametric projection)."""
    import gmsh

    uv = np.asarray(gmsh.model.getParametrization(2, face, points.ravel().tolist()))
    n = np.asarray(gmsh.model.getNormal(face, uv.tolist())).reshape(-1, 3)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def brep_truth(step: float | None = None) -> BrepTruth:
    """The sharp edges of the model loaded in gmsh (OpenCASCADE, synchronized).

    Parameters
    ----------
    step : float, optional
        Sampling step along the curves (default 1/400 of the bounding-box diagonal).

    Returns
    -------
    BrepTruth
    """
    import gmsh

    box = np.asarray(gmsh.model.getBoundingBox(-1, -1), np.float64)
    diagonal = float(np.linalg.norm(box[3:] - box[:3]))
    step = diagonal / 400 if step is None else float(step)
    cos_sharp = math.cos(math.radians(SHARP_ANGLE))
    segments: list[np.ndarray] = []
    seg_curve: list[np.ndarray] = []
    angles: dict[int, tuple[float, float]] = {}
    sharp_ends: dict[int, list[int]] = {}
    curve_vertices: dict[int, tuple[int, ...]] = {}
    for _, curve in gmsh.model.getEntities(1):
        faces = sorted(set(gmsh.model.getAdjacencies(1, curve)[0].tolist()))
        if len(faces) < 2:
            continue  # a seam or a free edge
        lo, hi = gmsh.model.getParametrizationBounds(1, curve)
        length = gmsh.model.occ.getMass(1, curve)
        n = max(MIN_SAMPLES, math.ceil(length / step)) + 1
        t = np.linspace(lo[0], hi[0], n)
        pts = np.asarray(gmsh.model.getValue(1, curve, t.tolist())).reshape(-1, 3)
        normals = [_face_normals(f, pts) for f in faces]
        # the largest angle between any two adjacent faces (two faces on a manifold)
        cosine = np.ones(n)
        for i in range(len(faces)):
            for j in range(i + 1, len(faces)):
                cosine = np.minimum(cosine, np.einsum("ij,ij->i", normals[i], normals[j]))
        deg = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))
        angles[curve] = (float(deg.min()), float(deg.max()))
        sharp = cosine <= cos_sharp
        piece = sharp[:-1] & sharp[1:]
        if not piece.any():
            continue
        segments.append(np.stack([pts[:-1][piece], pts[1:][piece]], axis=1))
        seg_curve.append(np.full(int(piece.sum()), curve, np.int64))
        ends = [int(v) for _, v in gmsh.model.getBoundary([(1, curve)], oriented=False)]
        if len(ends) == 2:  # the vertex at the curve's first sample first
            at = [np.linalg.norm(np.asarray(gmsh.model.getValue(0, v, [])) - pts[0]) for v in ends]
            ends = ends if at[0] <= at[1] else ends[::-1]
        curve_vertices[curve] = tuple(ends)
        first_last = [sharp[0], sharp[-1]] if len(ends) == 2 else [sharp[0]] * len(ends)
        for v, s in zip(ends, first_last, strict=True):
            if s:
                sharp_ends.setdefault(v, []).append(curve)
    corner_tags = [v for v, cs in sharp_ends.items() if len(cs) >= 3]
    corners = (
        np.array([gmsh.model.getValue(0, v, []) for v in corner_tags], np.float64)
        if corner_tags
        else np.zeros((0, 3))
    )
    return BrepTruth(
        segments=np.concatenate(segments) if segments else np.zeros((0, 2, 3)),
        segment_curve=np.concatenate(seg_curve) if seg_curve else np.zeros(0, np.int64),
        corners=corners.reshape(-1, 3),
        sharp_curves=tuple(curve_vertices),
        angles=angles,
        diagonal=diagonal,
        curve_vertices=curve_vertices,
    )


def closest_gap(truth: BrepTruth, radius: float) -> float:
    """The smallest distance under ``radius`` between two separate sharp features.

    Two corners are separate features. Two points of the sharp edges are separate
    features when the way between them along the sharp edges (through the curves' end
    vertices) is more than twice their distance: two curves that do not meet, or meet
    only far away, or leave a vertex less than about 47 degrees apart; one curve that
    comes back near itself (as across a small hole). The way is measured with a
    slack of two sampling steps (``radius / 4``).

    Parameters
    ----------
    truth : BrepTruth
    radius : float
        Distances at or above it are not looked for.

    Returns
    -------
    float
        ``inf`` when no two separate features come closer than ``radius``.
    """
    from scipy.sparse.csgraph import dijkstra

    from evaluation.scoring import sample_segments

    c = truth.corners
    pairs = cKDTree(c).query_pairs(radius, output_type="ndarray")
    gap = (
        float(np.linalg.norm(c[pairs[:, 0]] - c[pairs[:, 1]], axis=1).min())
        if len(pairs)
        else math.inf
    )
    step = radius / 4
    pts, piece, sid = sample_segments(truth.segments, step)
    pairs = cKDTree(pts).query_pairs(radius, output_type="ndarray")
    if len(pairs) == 0:
        return gap
    curve = truth.segment_curve[sid]
    # length along each curve's sharp pieces from its first end vertex (samples come
    # in curve order) and the curve's length
    start = np.r_[True, curve[1:] != curve[:-1]]
    run = np.cumsum(start) - 1
    total = np.cumsum(piece)
    along = total - piece / 2 - (total - piece)[start][run]
    length = np.bincount(run, piece)[run]
    # the shortest ways between the curves' end vertices along the sharp curves (the
    # shortest of two curves between the same vertices)
    verts = truth.curve_vertices
    node = {v: k for k, v in enumerate(sorted({v for e in verts.values() for v in e}))}
    seg_length = np.linalg.norm(truth.segments[:, 1] - truth.segments[:, 0], axis=1)
    weight = np.bincount(truth.segment_curve, seg_length)
    graph = np.zeros((len(node), len(node)))  # 0: no curve between them
    for c_tag, e in verts.items():
        if len(set(e)) == 2:
            a, b = node[e[0]], node[e[1]]
            w = weight[c_tag] if graph[a, b] == 0 else min(graph[a, b], weight[c_tag])
            graph[a, b] = graph[b, a] = w
    way = dijkstra(graph, limit=3 * radius)
    # each sample's curve's end vertices (a closed curve's one vertex twice; -1: none)
    ends = np.array(
        [
            [node[e[0]], node[e[-1]]] if e else [-1, -1]
            for e in (verts.get(int(k), ()) for k in curve)
        ],
        np.int64,
    ).reshape(-1, 2)
    to_end = np.stack([along, length - along], axis=1)  # to the first, the last end
    i, j = pairs[:, 0], pairs[:, 1]
    dist = np.linalg.norm(pts[i] - pts[j], axis=1)
    # on one curve: the length between the two (either way round a closed curve)
    arc = np.abs(along[i] - along[j])
    closed = np.array([len(set(verts.get(int(k), ()))) < 2 for k in curve[i]])
    arc = np.where(closed, np.minimum(arc, length[i] - arc), arc)
    path = np.where(curve[i] == curve[j], arc, np.inf)
    # through the vertices: from an end of one curve to an end of the other
    for a in (0, 1):
        for b in (0, 1):
            ok = (ends[i, a] >= 0) & (ends[j, b] >= 0)
            via = np.full(len(i), np.inf)
            via[ok] = way[ends[i, a][ok], ends[j, b][ok]]
            path = np.minimum(path, to_end[i, a] + via + to_end[j, b])
    separate = path > 2 * dist + 2 * step
    return min(gap, float(dist[separate].min())) if separate.any() else gap
