"""Curve positions below the point spacing (clouds).

Each curve vertex moves onto the intersection line of the two surfaces that meet at the
edge: in the plane across the curve (normal to its direction), the non-feature points
near the vertex form two arms, one per surface; a line is fitted to each arm and the
vertex moves to their intersection. Where that fails (fewer than
:data:`MIN_ARM_POINTS` on an arm, arms nearly parallel, a poor fit, or a move of more
than :data:`MAX_SHIFT` spacings: near corners, or on false detections; arms on one
side that meet off the surface, across a thin wall, :data:`WALL_APART`) the vertex is
projected onto the line fitted to the curve's own vertices nearby. The arms end short of
another edge running beside the curve (the other rim of a thin wall,
:data:`OTHER_EDGE`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from ..._header import CURVES
from ..neighbourhoods import squared_distances
from .graph import nearest

__all__ = [
    "MAX_SHIFT",
    "MIN_ARM_POINTS",
    "REFINE_NEIGHBOURS",
    "CellGrid",
    "cell_neighbourhood",
    "line_fit_positions",
    "plane_intersection_positions",
    "refine_neighbours",
]

# The numbers are defined once, in native/include/meshlab_sharp.h.
#: Points near a vertex that the two arms are fitted to (before the features among
#: them are left out): a disc of about 3.5 spacings' radius.
REFINE_NEIGHBOURS = CURVES.integer("REFINE_NEIGHBOURS")
#: Each point's weight in the arms' fits falls off with its distance d along the curve
#: as ``exp(-(d / (SLAB * spacing))**2 / 2)``: on a curved edge of radius r the
#: cross-section of a point d away is off by ``d**2 / (2 r)``, 0.06 spacing for
#: d = 1 spacing and r = 8 spacings (unweighted, d up to 3.5 spacings: 0.8 spacing).
SLAB = CURVES.real("SLAB")
#: Rounds of fitting the two arms' lines, each point then going to the nearer line
#: (the first split is by the side of the points' mean direction, which mixes the arms
#: when the vertex lies on one of the faces rather than on the edge).
ARM_ITERATIONS = CURVES.integer("ARM_ITERATIONS")
#: Fewest non-feature points on each arm for a line fit (total weight).
MIN_ARM_POINTS = CURVES.real("MIN_ARM_POINTS")
#: Largest move onto the intersection, in spacings: a detected point lies within about
#: one spacing of the edge (a band 2 spacings wide), and the arms' fit adds noise.
MAX_SHIFT = CURVES.real("MAX_SHIFT")
#: Smallest angle, in degrees, between the two arms' lines: the crease angle below
#: which an edge is not sharp (``robust.CREASE_ANGLE``).
MIN_ARM_ANGLE = CURVES.real("MIN_ARM_ANGLE")
#: Largest RMS distance of an arm's points to its line, in spacings (the scanner noise
#: the fit copes with: 25 % of the spacing is one standard deviation).
MAX_ARM_RMS = CURVES.real("MAX_ARM_RMS")
#: Points closer than this, in spacings, to the vertex in the plane across the curve
#: have no direction from it and take no part in the arms.
ZERO_OFFSET = CURVES.real("ZERO_OFFSET")
#: The plane across a unit direction t is spanned from the x axis, or from the y axis
#: where ``|t_x|`` is at least this (t nearly along x).
FRAME_SWITCH = CURVES.real("FRAME_SWITCH")
#: Feature points farther than this, in spacings, from the vertex in the plane across
#: the curve belong to another edge (a band of features is about 2 spacings wide and
#: the vertex lies within it). Where such features lie both ahead of the vertex and
#: behind it along the curve, the other edge runs beside this one (the other rim of a
#: thin wall, whose far face would join an arm and tilt its line): the points at least
#: as far across as that edge (the farther of its nearest features ahead and behind),
#: less :data:`OTHER_EDGE_MARGIN` spacings, take no part in the arms.
OTHER_EDGE = CURVES.real("OTHER_EDGE")
#: See :data:`OTHER_EDGE`.
OTHER_EDGE_MARGIN = CURVES.real("OTHER_EDGE_MARGIN")
#: Two nearly parallel arms that leave the vertex on one side, their lines farther apart
#: than this in spacings, are the two faces of a thin wall at its rim (an edge, its
#: position from the curve's own vertices); a smooth surface runs on through the vertex
#: (its arms on opposite sides), or its noise leaves arms on one line.
THIN_WALL = CURVES.real("THIN_WALL")
#: Where the two arms leave the vertex on one side with their lines farther apart than
#: this, in spacings, the vertex does not move onto their intersection when that lies
#: farther than :data:`WALL_GAP` spacings from every point: across a wall about 3
#: spacings thick the arms are often a face of the wall and the face beside its other
#: rim, whose lines meet off the surface, 2 to 3 spacings from any point; an edge's own
#: intersection, an acute one's too, lies on the surface, within about a spacing of a
#: point.
WALL_APART = CURVES.real("WALL_APART")
#: See :data:`WALL_APART`.
WALL_GAP = CURVES.real("WALL_GAP")


#: :class:`CellGrid`'s limit (2**62): its largest cell coordinate along an axis (a
#: farther cell is merged into the last one: a coordinate beyond it would overflow an
#: int64 once offset; the far-points rule keeps inputs well inside it), and the most
#: cells it numbers by one int64 key ``(a * dims1 + b) * dims2 + c`` (a larger grid, an
#: extent huge against the features' spacing, keys its cells by their three coordinates).
MAX_CELL = CURVES.real("MAX_CELL")


class CellGrid:
    """Cubic cells of side ``radius`` over the box ``[lo, hi]``, with one cell of margin
    on every side; cells are numbered by a flat key (by their three coordinates when the
    grid has more than :data:`MAX_CELL` cells).

    Parameters
    ----------
    lo, hi : (3,) float64
        The box (the bounding box of the valid points).
    radius : float > 0
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, radius: float) -> None:
        self.lo = np.asarray(lo, np.float64)
        self.radius = radius
        span = self._along(np.asarray(hi, np.float64)) + 3
        self.flat = bool(span[0] * span[1] * span[2] <= MAX_CELL)
        self.dims = span.astype(np.int64)

    def _along(self, x: np.ndarray) -> np.ndarray:
        """``floor((x - lo) / radius)``, clipped to +-MAX_CELL (float64, x's shape)."""
        q = x - self.lo
        q /= self.radius
        np.floor(q, out=q)
        return np.clip(q, -MAX_CELL, MAX_CELL, out=q)

    def _key(self, cells: np.ndarray) -> np.ndarray:
        if self.flat:
            return (cells[..., 0] * self.dims[1] + cells[..., 1]) * self.dims[2] + cells[..., 2]
        # each cell's three coordinates as one 24-byte value
        rows = np.ascontiguousarray(cells.reshape(-1, 3))
        return rows.view(np.dtype((np.void, 24))).reshape(cells.shape[:-1])

    def keys(self, points: np.ndarray) -> np.ndarray:
        """Key of each point's cell, (n,) for points (n, 3): int64, or 24-byte values."""
        cells = self._along(points).astype(np.int64)  # n can be large: in place
        cells += 1
        return self._key(cells)

    def around(self, centres: np.ndarray) -> np.ndarray:
        """Keys of the 3x3x3 cells around each of the centres (f, 3): (w,), sorted,
        distinct."""
        cells = self._along(centres).astype(np.int64) + 1
        offsets = np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), -1).reshape(-1, 3)
        return np.unique(self._key(cells[:, None, :] + offsets[None, :, :]))


def cell_neighbourhood(
    points: np.ndarray,
    valid: np.ndarray,
    centres: np.ndarray,
    radius: float,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Indices of the valid points in the grid cells (side ``radius``) around the centres.

    A cheap superset of the points within ``radius`` of a centre, so that the kd-tree
    of the refinement holds only the points near the curves.

    Parameters
    ----------
    points : (n, 3) float64
    valid : (n,) bool
    centres : (f, 3) float64
    radius : float > 0
    bounds : ((3,), (3,)) float64, optional
        The box the grid is laid over; default the valid points' bounding box. Given when
        ``points`` is the part of a larger cloud near the centres (out of core): the
        box of the larger cloud's valid points gives the same cells.

    Returns
    -------
    (s,) int64, ascending.
    """
    # only the valid points are read: the others may lie outside the grid, and one
    # dropped far away (cleaning's far points) would stretch it past what its keys number
    inside = np.flatnonzero(valid)
    read = points if len(inside) == len(points) else points[inside]
    if bounds is None:
        # column by column: a strided reduction over axis 0 is several times slower
        # (the same values; min and max do not round)
        lo = np.array([read[:, j].min() for j in range(3)])
        hi = np.array([read[:, j].max() for j in range(3)])
    else:
        lo, hi = bounds
    grid = CellGrid(lo, hi, radius)
    return inside[np.isin(grid.keys(read), grid.around(centres))]


def refine_neighbours(tree: cKDTree, vertices: np.ndarray) -> np.ndarray:
    """The REFINE_NEIGHBOURS nearest points of each vertex, (v, k) indices into the
    tree's points (k = REFINE_NEIGHBOURS, or all the points when fewer), ordered by
    squared distance, ties by the lower index (:func:`.graph.nearest`)."""
    return nearest(tree, vertices, min(REFINE_NEIGHBOURS, tree.n))


def _frame(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors orthogonal to each unit row of ``t`` and to each other."""
    helper = np.where(np.abs(t[:, :1]) < FRAME_SWITCH, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(t, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(t, u)


def _arm_lines(
    xy: np.ndarray, w: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Weighted 2-D line fits: centroid (v, 2), direction (v, 2), RMS residual (v,),
    weight total (v,)."""
    total = w.sum(axis=1)
    safe = np.where(total > 0, total, 1.0)
    c = (w[..., None] * xy).sum(axis=1) / safe[:, None]
    d = xy - c[:, None, :]
    sxx = (w * d[..., 0] ** 2).sum(axis=1)
    syy = (w * d[..., 1] ** 2).sum(axis=1)
    sxy = (w * d[..., 0] * d[..., 1]).sum(axis=1)
    theta = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    a = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    off = d[..., 0] * -a[:, None, 1] + d[..., 1] * a[:, None, 0]
    rms = np.sqrt((w * off**2).sum(axis=1) / safe)
    return c, a, rms, total


def _offset(xy: np.ndarray, c: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Distance of 2-D points (v, k, 2) to the lines through c (v, 2) along a (v, 2)."""
    d = xy - c[:, None, :]
    return np.abs(d[..., 0] * a[:, None, 1] - d[..., 1] * a[:, None, 0])


def plane_intersection_positions(
    vertices: np.ndarray,
    directions: np.ndarray,
    neighbours: np.ndarray,
    tree_points: np.ndarray,
    tree_is_feature: np.ndarray,
    spacing: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Move curve vertices onto the intersection of the surfaces on each side.

    Parameters
    ----------
    vertices : (v, 3) float64
        Curve vertices.
    directions : (v, 3) float64
        Unit curve direction at each vertex.
    neighbours : (v, k) int
        Each vertex's REFINE_NEIGHBOURS nearest points, indices into ``tree_points``
        (:func:`refine_neighbours`).
    tree_points : (s, 3) float64
        Points near the curves.
    tree_is_feature : (s,) bool
        Which of them are features (left out of the fits).
    spacing : float

    Returns
    -------
    positions : (v, 3) float64
        Moved vertices (unchanged where the fit failed).
    ok : (v,) bool
        Where the fit succeeded.
    flat : (v,) bool
        Where both arms were fitted well but meet at less than MIN_ARM_ANGLE, and are
        not the two faces of a thin wall (:data:`THIN_WALL`): no edge there (false
        detections on a smooth surface).
    """
    v = len(vertices)
    if v == 0:
        return vertices.copy(), np.zeros(0, bool), np.zeros(0, bool)
    idx = neighbours
    u, w = _frame(directions)
    d = tree_points[idx] - vertices[:, None, :]
    xy = np.stack([np.einsum("vkj,vj->vk", d, u), np.einsum("vkj,vj->vk", d, w)], axis=-1)
    along = np.einsum("vkj,vj->vk", d, directions) / (SLAB * spacing)
    weight = np.exp(-0.5 * along**2)
    r = np.linalg.norm(xy, axis=-1)
    # the arms end short of another edge running beside this one (a thin wall's other
    # rim): its features are seen on both sides along the curve, those of an edge that
    # crosses the plane near a corner on one side only
    other = tree_is_feature[idx] & (r > OTHER_EDGE * spacing)
    ahead = np.where(other & (along > 0), r, np.inf).min(axis=1)
    behind = np.where(other & (along < 0), r, np.inf).min(axis=1)
    reach = np.maximum(ahead, behind) - OTHER_EDGE_MARGIN * spacing
    use = ~tree_is_feature[idx] & (r > ZERO_OFFSET * spacing) & (r < reach[:, None])
    unit = xy / np.where(r > 0, r, 1.0)[..., None]
    bisector = (unit * use[..., None]).sum(axis=1)
    side = (bisector[:, None, 0] * unit[..., 1] - bisector[:, None, 1] * unit[..., 0]) > 0
    for _ in range(ARM_ITERATIONS):
        c1, a1, rms1, n1 = _arm_lines(xy, np.where(use & side, weight, 0.0))
        c2, a2, rms2, n2 = _arm_lines(xy, np.where(use & ~side, weight, 0.0))
        side = _offset(xy, c1, a1) <= _offset(xy, c2, a2)  # each point to its nearer line
    cross = a1[:, 0] * a2[:, 1] - a1[:, 1] * a2[:, 0]
    safe = np.where(np.abs(cross) > 0, cross, 1.0)
    diff = c2 - c1
    s = (diff[:, 0] * a2[:, 1] - diff[:, 1] * a2[:, 0]) / safe
    hit = c1 + s[:, None] * a1
    fitted = (
        (n1 >= MIN_ARM_POINTS)
        & (n2 >= MIN_ARM_POINTS)
        & (np.maximum(rms1, rms2) <= MAX_ARM_RMS * spacing)
    )
    crease = np.abs(cross) >= math.sin(math.radians(MIN_ARM_ANGLE))
    # a thin wall's two faces (parallel arms) leave its rim on one side, a wall apart
    one_side = (c1[:, 0] * a1[:, 0] + c1[:, 1] * a1[:, 1]) * (
        c2[:, 0] * a1[:, 0] + c2[:, 1] * a1[:, 1]
    ) > 0
    apart = np.abs(diff[:, 0] * a1[:, 1] - diff[:, 1] * a1[:, 0])
    wall = one_side & (apart > THIN_WALL * spacing)
    ok = (
        fitted
        & crease
        & (np.linalg.norm(bisector, axis=1) > 0)
        & (np.linalg.norm(hit, axis=1) <= MAX_SHIFT * spacing)
    )
    moved = vertices + hit[:, :1] * u + hit[:, 1:] * w
    # arms on one side and far apart whose lines meet far from every point: across a
    # thin wall, not on its rim
    rows = np.flatnonzero(ok & one_side & (apart > WALL_APART * spacing))
    if len(rows):
        near = nearest(cKDTree(tree_points), moved[rows], 1)[:, 0]
        gap = WALL_GAP * spacing
        ok[rows] = squared_distances(tree_points[near], moved[rows]) <= gap * gap
    return np.where(ok[:, None], moved, vertices), ok, fitted & ~crease & ~wall


def line_fit_positions(
    points: np.ndarray, directions: np.ndarray, sizes: np.ndarray, closed: np.ndarray, half: int
) -> np.ndarray:
    """Project each vertex onto the line through the mean of its ``2 half + 1``
    neighbours along its curve, in the curve's direction there; many curves at once.

    An open curve's ends count their end vertex in place of the missing neighbours; a
    loop wraps round (a loop of ``half`` vertices or fewer is left as it is).

    Parameters
    ----------
    points : (v, 3) float64
        The curves' vertices, one curve after the other.
    directions : (v, 3) float64
        Unit directions.
    sizes : (c,) int
        Vertices of each curve (summing to v).
    closed : (c,) bool
        Which curves are loops.
    half : int
        Vertices on each side.

    Returns
    -------
    (v, 3) float64
    """
    sizes = np.asarray(sizes, np.int64)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    piece = np.repeat(np.arange(len(sizes)), sizes)
    local = np.arange(len(points)) - starts[piece]
    m, loop = sizes[piece], np.asarray(closed, bool)[piece]
    total = np.zeros_like(points)
    for j in range(-half, half + 1):
        k = np.where(loop, (local + j) % m, np.clip(local + j, 0, m - 1))
        total = total + points[starts[piece] + k]  # in order, like the native library
    mean = total / (2 * half + 1)
    rel = points - mean
    out = mean + np.einsum("ij,ij->i", rel, directions)[:, None] * directions
    return np.where((loop & (m <= half))[:, None], points, out)
