"""Robust mode: the projected-distance method where the paper's reading fails.

``detect(..., mode="robust")`` changes these things of the paper's method (measured
choices, see ``docs/method.md``; the arithmetic the plugin shares is pinned down in
``docs/contributing.md``):

1. **Isolated points are left out** (point clouds): point ``i`` is isolated when it is
   not among the ``k_max`` nearest neighbours of its own nearest neighbour. Detection
   runs on the other points; isolated points are never features.
1a. **Neighbourhoods stay on their own sheet** (point clouds): the neighbours lying on
   a parallel sheet (the other side of a thin wall), separated from the point's own
   sheet along the normal (of the ``k_max`` nearest) by a gap wider than ``SHEET_GAP``
   times the spacing, are left out of every neighbourhood below, with whatever lies
   beyond them (a rib standing on the far side of a floor), when they are at least
   ``SHEET_MIN`` points, and no more than ``1 / SHEET_OWN`` times the points kept (at
   an edge or a corner every neighbour lies to one side). Where that finds no such gap
   (near a rim the end face joins the two sides of the wall), the same in the column
   around the point (within ``SHEET_COLUMN`` spacings of its normal line; gap
   ``SHEET_COLUMN_GAP``; one sheet: a single gap on that side), unless the points left
   out on one side span more than ``SHEET_FAR_SPAN`` spacings of height (a face turning
   away at an edge, not a parallel sheet). Where both find nothing, both again along
   the normal of the neighbours within ``SHEET_TRIM`` spacings of the point's plane,
   when that normal turns little (``SHEET_TRIM_COS``): a rib standing on the far side of
   a floor tilts the normal of the ``k_max`` nearest and blurs the gap.
1b. **Scales from the noise** (point clouds): the median over the points of
   ``|d . n| / |d|`` (``d`` the offset to the nearest neighbour, ``n`` the normal of the
   point and its 6 nearest, both on its own sheet) measures the noise; above
   ``NOISE_TOLERATED`` the scales grow as its square, at most ``NOISE_MAX_FACTOR``-fold
   (the noise of ``r`` falls as ``1 / sqrt(k)``).
2. **Relative projected distance** instead of min-max normalisation: per scale,
   ``r_i = pdis_i / l_i`` with ``l_i`` the mean distance from ``p_i`` to the members of
   its neighbourhood (itself included). ``0 <= r_i <= 1`` always (``pdis_i`` is the
   normal component of the centroid offset, whose length is at most ``l_i``), so the
   histogram range is fixed: a few far points cannot stretch it, and the value does not
   depend on the local point density.
3. **Threshold with a floor**: ``T = max(otsu(r), R_MIN)`` with ``R_MIN`` the value of
   ``r`` on a straight edge that turns by ``CREASE_ANGLE`` (20) degrees,
   ``(2 / pi) * sin(10 deg)``. On a smooth object Otsu still splits the histogram, but
   below the floor: "no sharp features" becomes a possible answer. On a cloud whose
   measured noise (step 1b) is at most ``NOISE_QUIET``, ``T = R_MIN`` alone: without
   noise the flat and smooth points have ``r`` near 0 and the floor is the definition
   of sharp, while Otsu's split, above it on parts with strong edges, drops the weaker
   ones (the fandisk's, concave edges and the rims of thin walls).
3b. **Acute tips** (:func:`acute_tips`): on a cloud thresholded at the floor alone, a
   point that is not a candidate at every scale but whose score (step 5's ranking)
   lies in ``[ACUTE_SCORE, ACUTE_SCORE_MAX)`` and that lies between two candidates of
   its thinning list is a candidate too: at an acute edge the PCA normal turns
   perpendicular to the wedge's mid-plane, ``r`` is small on the tip and the
   candidates lie on the two faces beside it, while ``o / l`` peaks on the tip.
4. **Support**: a point that is a candidate at every scale is kept only when at least
   ``SUPPORT_MIN`` (2) other such points among its ``SUPPORT_KNN`` (16) nearest (its
   ``THIN_RING``-ring on meshes) lie along its feature line: a line has neighbours
   along it, a point lifted by noise has none, or only the line it lies beside. On a
   cloud thresholded at the floor alone (step 3) the candidates whose score (step 5's
   ranking) is below ``SUPPORT_FREE_SCORE`` need none: without noise nothing is lifted
   alone, and the candidates of weak edges come only here and there.
5. **Thinning**: a point is dropped when a supported neighbour among its ``THIN_KNN``
   (12) nearest (grown with the scales on noisy clouds), lying across the feature
   line (more than 60 degrees from the line's direction; on noisy clouds about 63,
   ``THIN_CONE_COS_NOISY``: noise tilts a line's own offsets), ranks higher (mean over the
   scales of the centroid's distance relative to ``l``, which peaks on acute edges
   where ``r`` does not): non-maximum suppression
   across the line, so lines stay one point wide; comparing only within about 1.9
   spacings keeps most of two parallel lines (the rims of a thin wall) apart, and on
   a cloud thresholded at the floor alone a point that is not a candidate, or ranks
   below the point (a valley of the ranking), lying between the two (the middle of a
   wall's end face) keeps both (:func:`thin_blockers`). Where the noise grew the scales
   to the cap, the ranking is the mean over the ``THIN_KNN`` nearest (points lifted by
   the noise beside a line do not outrank it).
6. **Meshes: the mesh's own sharp edges** (:mod:`meshlab_sharp.creases`): vertices on
   an edge whose two faces turn by more than ``CREASE_ANGLE`` (more on a noisy mesh)
   are features too. On a CAD tessellation they are all of them. A mesh's rings (its
   neighbourhoods at every step) are listed breadth-first
   (:class:`meshlab_sharp.neighbourhoods.RingNeighbourhoods`), the order in which the
   sums over them are taken.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import _header, _kernels
from .creases import CREASE_ANGLE, sharp_vertices
from .neighbourhoods import (
    KnnNeighbourhoods,
    Neighbourhood,
    RingNeighbourhoods,
    build_neighbourhoods,
    grow_rings,
)
from .normals import DEFAULT_WEIGHTING, Weighting
from .projected_distance import projected_distances
from .threshold import histogram, otsu_from_histogram

__all__ = [
    "ACUTE_SCORE",
    "ACUTE_SCORE_MAX",
    "CREASE_ANGLE",
    "NOISE_KNN",
    "NOISE_MAX_FACTOR",
    "NOISE_QUIET",
    "NOISE_TOLERATED",
    "R_MIN",
    "SHEET_COLUMN",
    "SHEET_COLUMN_GAP",
    "SHEET_FAR_SPAN",
    "SHEET_GAP",
    "SHEET_MIN",
    "SHEET_OWN",
    "SHEET_TRIM",
    "SHEET_TRIM_COS",
    "SUPPORT_FREE_SCORE",
    "SUPPORT_KNN",
    "SUPPORT_MIN",
    "THIN_CONE_COS",
    "THIN_CONE_COS_NOISY",
    "THIN_KNN",
    "THIN_RING",
    "RelativeRule",
    "RobustSetup",
    "SheetNeighbourhoods",
    "acute_tests",
    "acute_tips",
    "grown_scales",
    "isolated_points",
    "line_directions",
    "local_scale",
    "noise_factor",
    "noise_ratios",
    "noise_ratios_lists",
    "noise_scale_factor",
    "otsu_splits",
    "quiet_cloud",
    "relative_distances",
    "robust_threshold",
    "robust_threshold_from_histogram",
    "sheet_mask",
    "sheet_parameters",
    "support_exempt",
    "support_free_score",
    "supported",
    "thin",
    "thin_blockers",
    "thin_cone",
    "thin_knn",
]

#: Relative projected distance at a point on a straight edge turning by CREASE_ANGLE,
#: with a disc-shaped neighbourhood: ``(2 / pi) * sin(CREASE_ANGLE / 2)`` = 0.1106.
R_MIN = (2.0 / math.pi) * math.sin(math.radians(CREASE_ANGLE / 2.0))
#: Thinning compares a point with candidate neighbours whose offset makes more than
#: 60 degrees with the line direction: ``|d . e| < THIN_CONE_COS * |d|``.
THIN_CONE_COS = _header.real("THIN_CONE_COS")
#: ... and by more than about 63 degrees on a noisy cloud (:func:`thin_cone`).
THIN_CONE_COS_NOISY = _header.real("THIN_CONE_COS_NOISY")
#: Neighbourhood of the comparison in thinning: the 12 nearest points (clouds; within
#: about 1.9 spacings: across the band of candidates (1.3-1.5 spacings) and the points
#: that noise lifts beside it, mostly short of a second line 2-3 spacings away, such as
#: the other rim of a thin wall) ...
THIN_KNN = _header.integer("THIN_KNN")
#: ... or the 2-ring (meshes; about 19 vertices on a regular mesh). The 2-ring is also
#: the support neighbourhood on meshes.
THIN_RING = _header.integer("THIN_RING")
#: Support: a feature needs at least SUPPORT_MIN other features among its SUPPORT_KNN
#: nearest points (clouds), the neighbourhood that thinning used to compare with: a
#: line one point wide has two neighbours along it within 16 points, a point lifted
#: alone by noise has none.
SUPPORT_KNN = _header.integer("SUPPORT_KNN")
SUPPORT_MIN = _header.integer("SUPPORT_MIN")
#: ... except, on a cloud thresholded at the floor alone (:func:`support_exempt`), the
#: candidates whose score (:class:`RelativeRule`'s, the mean ``o / l``) is below
#: SUPPORT_FREE_SCORE: without noise no point is lifted alone, and a weak edge beside
#: strong ones (the fandisk's) is a candidate at every scale only here and there, one
#: or none of the 16 nearest. Points lifted off the surface (outliers that are not
#: isolated: scores 0.68-0.94) and the bands of candidates down walls 1 spacing thick
#: (0.25-0.31) stay subject to support; the fandisk's weak edges score 0.16-0.21.
#: Measured (20,000 points): fandisk 0.925 -> 0.950, clean 0.964
#: -> 0.967, 1 % outliers 0.9506 -> 0.9535, density 0.956 -> 0.960, thin walls within
#: 0.002.
SUPPORT_FREE_SCORE = _header.real("SUPPORT_FREE_SCORE")
#: On a cloud thresholded at the floor alone, a point that is not a candidate at every
#: scale but scores (the mean ``o / l``) at least ACUTE_SCORE and below
#: ACUTE_SCORE_MAX, and lies between two candidates of its thinning list, is a candidate
#: too (:func:`acute_tips`): the tip of an acute edge, where the PCA normal turns
#: into the wedge's mid-plane and ``r`` is small, while the centroid's offset along the
#: bisector makes ``o / l`` peak (0.5-0.8 on the 30-60 degree wedges, the star prism
#: and the rims of walls 1 spacing thick; outliers that are not isolated: 0.8-0.96;
#: the density gradient's offsets along the surface: below 0.5, and not between two
#: candidates). Measured (20,000 points): clean 0.966 -> 0.974 (star prism 0.901 ->
#: 0.961), acute 0.929 -> 0.964, thin walls 1 spacing 0.736 -> 0.80.
ACUTE_SCORE = _header.real("ACUTE_SCORE")
ACUTE_SCORE_MAX = _header.real("ACUTE_SCORE_MAX")
#: The plane of the noise estimate: the point and its 6 nearest (the 1-ring of a
#: regular triangulation of the samples); the smallest scale (12) takes in the other
#: sheet of a wall 2 spacings thick and reads it as noise.
NOISE_KNN = _header.integer("NOISE_KNN")
#: Noise the default scales tolerate, as the median of ``|d . n| / |d|`` between nearest
#: neighbours (``d``) across the plane (normal ``n``) of the ``NOISE_KNN`` nearest.
#: Measured on Poisson-disk samples: 0 clean, 0.20 with normal noise of 25 % of the
#: spacing, 0.30 at 50 %, 0.01-0.02 on walls 2-3 spacings thick, 0.03 at most on the
#: smooth controls, 0.08-0.13 on the simulated scans. Above it the scales grow as the
#: square of the ratio (the noise of ``r`` at scale k goes as ``sigma / sqrt(k)``).
NOISE_TOLERATED = _header.real("NOISE_TOLERATED")
#: At most this noise ratio (the lower median of :func:`noise_ratios`), a cloud is
#: thresholded at the floor alone (:func:`otsu_splits`). Measured on the evaluation's
#: clouds (20,000 points): 0-0.003 clean, 0-0.01 thin walls, 0.004-0.018 smooth
#: controls, 0.09-0.096 with normal noise of 10 % of the spacing, 0.068-0.115 on the
#: simulated scans; a third of ``NOISE_TOLERATED`` lies between.
NOISE_QUIET = _header.real("NOISE_QUIET")
#: The scales grow at most 3-fold (``k_max`` 120 with the default scales: the kNN table
#: of a million points stays below 0.5 GB); measured at 50 % noise, quick size: x2 0.64,
#: x3 0.66.
NOISE_MAX_FACTOR = _header.real("NOISE_MAX_FACTOR")
#: Sheet filter: along the normal ``n`` of its ``k_max`` nearest (the weighted PCA
#: normal, which sees the two sheets of a thin wall as one plane), a point's neighbours
#: ``j`` have heights ``h_j = (p_j - p_i) . n``; its own sheet is the run of sorted
#: heights reached from 0 (its own) by steps of at most SHEET_GAP times its spacing
#: ``a`` (the mean distance to its 6 nearest). The other side of a wall 1-3 spacings
#: thick lies beyond a gap of 1-3 spacings (``a`` is about 1.1-1.3 spacings); a
#: surface that bends at an edge, however sharply, or curves, has no gap.
#: Measured (quick size, thin1 / thin2 / thin3 F1): 0.25: 0.61 / 0.60 / 0.88, 0.35:
#: 0.71 / 0.65 / 0.88, 0.4: 0.70 / 0.69 / 0.88, 0.5: 0.62 / 0.70 / 0.88, 0.7: 0.59 /
#: 0.64 / 0.88.
SHEET_GAP = _header.real("SHEET_GAP")
#: ... and the points beyond the gaps are left out only when they are at least
#: SHEET_MIN: another sheet, not the sparse points of a face seen at a grazing angle (a
#: scan) or the tail of the noise.
SHEET_MIN = _header.integer("SHEET_MIN")
#: ... and only when the kept points are at least SHEET_OWN times as many as those
#: left out: at an edge or a corner every neighbour lies to one side of the point, and
#: on a regular grid the face turning away comes in rows (a row of the 40 nearest
#: beyond the first gap leaves 1-7 kept against 33-39 left out; a wall 1 spacing thick
#: holds about as many points on either sheet). Measured (quick size, thin1): 1.0:
#: 0.55, 0.5 / 0.33: 0.70; 0.2 loses two thirds of a regular grid cube's edges.
SHEET_OWN = _header.real("SHEET_OWN")
#: Second rule, where the first drops none: near a rim of a wall the end face joins
#: the two sides and fills the gap in the heights of the whole list, but not in the
#: column around the point (the neighbours within SHEET_COLUMN times its spacing
#: ``a`` of the line along the normal through it): there a gap wider than
#: SHEET_COLUMN_GAP times ``a`` parts the sheets (the cut in its middle), unless the
#: heights left out on one side span more than SHEET_FAR_SPAN times ``a`` (a face
#: turning away at an edge, sampled sparsely in the column, not a parallel sheet).
#: Measured (20,000 points, thin1 / thin2 / thin3 F1): without
#: the rule 0.744 / 0.711 / 0.913; column 1.1, gap 0.75, span 1.25: 0.757 / 0.797 /
#: 0.911 (1 % outliers 0.9507 -> 0.9506; span 1.5: thin2 0.805 but outliers 0.9498).
SHEET_COLUMN = _header.real("SHEET_COLUMN")
SHEET_COLUMN_GAP = _header.real("SHEET_COLUMN_GAP")
SHEET_FAR_SPAN = _header.real("SHEET_FAR_SPAN")
#: Second pass, where the rules keep every neighbour: a rib standing on the far side of
#: a floor 1 spacing thick tilts the normal of the ``k_max`` nearest (by 5-10 degrees),
#: which spreads each sheet's heights over the gap between them. The rules are applied
#: again along the normal of the neighbours within SHEET_TRIM times ``a`` of the point's
#: plane (the rib's points, higher, left out of it), where that normal turns by at most
#: about 10 degrees (``|n2 . n| >= SHEET_TRIM_COS``; beside an edge of a scan it turns
#: more, and the sparse face turning away showed gaps). Measured (20,000 points, thin1 /
#: thin2 / thin3 / scan F1): without the pass 0.745 /
#: 0.866 / 0.922 / 0.888; trim 1.3, no turn limit: 0.754 / 0.874 / 0.927 / 0.871; at
#: most 10 / 15 / 20 degrees: 0.753 / 0.873 / 0.923 / 0.888, 0.754 / 0.874 / 0.925 /
#: 0.888, 0.754 / 0.874 / 0.927 / 0.878; trim 1.6 (no limit): 0.749 / 0.872 / 0.929.
SHEET_TRIM = _header.real("SHEET_TRIM")
SHEET_TRIM_COS = _header.real("SHEET_TRIM_COS")


def isolated_points(indices: np.ndarray) -> np.ndarray:
    """Points that are not among the k nearest neighbours of their nearest neighbour.

    Parameters
    ----------
    indices : (n, k) int
        k-nearest-neighbour indices of distinct points, each row sorted by distance
        with the point itself first (column 0) and its nearest neighbour in column 1.
        ``k >= 2``.

    Returns
    -------
    (n,) bool
        True for isolated points (outliers): ``i`` does not occur in
        ``indices[indices[i, 1]]``.
    """
    idx = np.asarray(indices)
    n = len(idx)
    if n == 0 or idx.shape[1] < 2:
        return np.zeros(n, bool)
    nearest = idx[:, 1]
    return ~(idx[nearest] == np.arange(n)[:, None]).any(axis=1)


def noise_scale_factor(points: np.ndarray, indices: np.ndarray, k: int) -> float:
    """How much larger the scales must be for the noise of the points.

    Parameters
    ----------
    points : (n, 3) float64
    indices : (n, k_max) int
        kNN lists sorted by distance, the point itself first, ``k_max >= k >= 2``.
    k : int
        The first ``k`` columns give each point's plane (unweighted PCA normal ``n_i``;
        ``NOISE_KNN``).

    Returns
    -------
    float
        ``min(max(1, (nu / NOISE_TOLERATED)**2), NOISE_MAX_FACTOR)``, ``nu`` the lower
        median over the points of :func:`noise_ratios`.
    """
    return _noise_factor(noise_ratios(points, indices, k))


def noise_ratios(points: np.ndarray, indices: np.ndarray, k: int) -> np.ndarray:
    """``|d . n_i| / |d|`` of every point, ``d = p_{N(i)[1]} - p_i`` (the nearest
    neighbour's offset across the plane of the ``k`` nearest, relative to its distance;
    0 when ``d = 0``). ``points`` (n, 3), ``indices`` (n, >= k) as
    :func:`noise_scale_factor`; returns (n,) float64."""
    idx = np.asarray(indices)[:, :k]
    return _plane_ratios(points[idx] - points[:, None, :])


def _plane_ratios(q: np.ndarray) -> np.ndarray:
    """:func:`noise_ratios` from the offsets q (n, k, 3) of each point's list."""
    c = q.mean(axis=1)
    r = q - c[:, None, :]
    cov = np.einsum("nka,nkb->nab", r, r)
    normal = np.linalg.eigh(cov)[1][:, :, 0]
    d = q[:, 1]
    length = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    across = np.abs(d[:, 0] * normal[:, 0] + d[:, 1] * normal[:, 1] + d[:, 2] * normal[:, 2])
    return np.where(length > 0, across / np.where(length > 0, length, 1.0), 0.0)


def noise_ratios_lists(points: np.ndarray, lists: Neighbourhood) -> np.ndarray:
    """:func:`noise_ratios` of lists of any length: point ``i``'s plane is that of
    ``lists[i]`` (``i`` first, its nearest next; 0 for lists shorter than 2).
    ``points`` (n, 3); returns (n,) float64."""
    indptr = np.asarray(lists.indptr, np.int64)
    indices = np.asarray(lists.indices, np.int64)
    size = np.diff(indptr)
    out = np.zeros(len(points))
    for m in np.unique(size[size >= 2]):
        rows = np.flatnonzero(size == m)
        table = indices[indptr[rows][:, None] + np.arange(m)]
        out[rows] = _plane_ratios(points[table] - points[rows][:, None, :])
    return out


def noise_factor(nu: float) -> float:
    """The scales' growth for the median noise ratio ``nu``:
    ``min(max(1, (nu / NOISE_TOLERATED)**2), NOISE_MAX_FACTOR)``."""
    return min(max(1.0, (nu / NOISE_TOLERATED) ** 2), NOISE_MAX_FACTOR)


def grown_scales(scales: tuple[int, ...], factor: float) -> tuple[int, ...]:
    """The scales times ``factor``, rounded half up."""
    return tuple(math.floor(k * factor + 0.5) for k in scales)


def thin_knn(growth: float) -> int:
    """Thinning's comparison list (clouds): ``THIN_KNN`` grown with the scales
    (``growth`` the factor the noise grew them by, 1 when it did not), rounded half
    up: the band of points that noise lifts beside a line widens with the noise."""
    return grown_scales((THIN_KNN,), growth)[0]


def _noise_factor(ratio: np.ndarray) -> float:
    """:func:`noise_factor` of the lower median of the per-point ratios (n,), which are
    reordered in place (no copy of n values)."""
    return noise_factor(_noise_median(ratio))


def _noise_median(ratio: np.ndarray) -> float:
    """The lower median of the per-point noise ratios (n,), reordered in place."""
    at = (len(ratio) - 1) // 2
    ratio.partition(at)
    return float(ratio[at])


def _pass_noise_median(ratio: np.ndarray, workers: int = -1) -> float:
    """:func:`_noise_median` of the compiled pass's ratios (n,), the same value, on
    ``workers`` threads (:func:`meshlab_sharp._kernels.lower_median`)."""
    median = _kernels.lower_median(ratio, workers)
    return _noise_median(ratio) if median is None else median


def sheet_parameters() -> _kernels.SheetParameters:
    """The sheet filter's parameters as the module holds them now: ``(SHEET_GAP,
    SHEET_MIN, SHEET_OWN, SHEET_COLUMN, SHEET_COLUMN_GAP, SHEET_FAR_SPAN, SHEET_TRIM,
    SHEET_TRIM_COS)``."""
    return (
        SHEET_GAP,
        SHEET_MIN,
        SHEET_OWN,
        SHEET_COLUMN,
        SHEET_COLUMN_GAP,
        SHEET_FAR_SPAN,
        SHEET_TRIM,
        SHEET_TRIM_COS,
    )


def sheet_mask(
    points: np.ndarray,
    indices: np.ndarray,
    normals: np.ndarray,
    parameters: _kernels.SheetParameters | None = None,
) -> np.ndarray:
    """The neighbours on each point's own sheet.

    Parameters
    ----------
    points : (n, 3) float64
    indices : (n, k) int
        kNN lists sorted by distance, the point itself first.
    normals : (n, 3) float64
        Unit normal of each list (the weighted PCA normal of its ``k`` points).
    parameters : (gap, minimum, own, column, column_gap, far_span, trim, trim_cos), optional
        Default :func:`sheet_parameters` (0.4, 6, 0.5, 1.1, 0.75, 1.25, 1.3, 0.985).

    Returns
    -------
    (n, k) bool
        ``keep[i, j]``: with ``q_j = p_{indices[i, j]} - p_i``, ``h_j = q_j . n_i``
        (``x*x' + y*y' + z*z'``), ``a_i`` the mean of ``|q_1| .. |q_m|`` (``m = min(6,
        k - 1)``, added in order). **Rule 1**: with the ``h`` sorted increasingly, a gap
        is a step ``> gap * a_i`` between consecutive ``h``. Above 0 (``i``'s own
        height) the points beyond the first gap are dropped, whatever lies beyond them
        (a rib standing on the far side of a floor adds gaps of its own); likewise
        below 0. A row that
        would drop fewer than ``minimum`` points, or keep fewer than ``own`` times as
        many as it drops (the points of an edge or a corner have all their neighbours
        to one side), keeps them all. **Rule 2**, on the rows that rule 1 keeps whole
        (none when ``column <= 0``): the same with the heights of the column only
        (``t_j^2 = |q_j|^2 - h_j^2 <= (column * a_i)^2``; the others' heights read as
        0), gaps ``> column_gap * a_i``, a side cut only when its gap is the only one
        on that side, and the cut in the middle of the gap (``h_j``
        above ``(hs[c] + hs[c + 1]) / 2`` dropped, for the gap between sorted
        ``hs[c]`` and ``hs[c + 1]``; below likewise); it also keeps the row whole when
        the heights it would drop on one side span more than ``far_span * a_i``.
        **Pass 2**, on the rows that rules 1 and 2 keep whole where some ``|h_j| >
        trim * a_i`` and at least 3 have ``|h_j| <= trim * a_i`` (none when ``trim <=
        0``): rules 1 and 2 again with ``n_i`` replaced by the unweighted PCA normal
        (the eigenvector of the smallest eigenvalue of ``sum (q_j - c)(q_j - c)^T``,
        ``c`` their mean) of the ``q_j`` with ``|h_j| <= trim * a_i``, when it turns
        little from ``n_i``: ``|n2 . n_i| >= trim_cos`` (``x*x' + y*y' + z*z'``).
    """
    gap, minimum, own, column, column_gap, far_span, trim, trim_cos = (
        sheet_parameters() if parameters is None else parameters
    )

    def rules(h: np.ndarray, d2: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Rules 1 and 2 on heights h (r, k), squared lengths d2 (r, k), spacings a (r,)."""
        lo, hi = _sheet_cuts(h, gap * a, column=False)
        kept = _sheet_apply(h, lo, hi, minimum, own, np.full(len(h), np.inf))
        if column > 0:
            whole = np.flatnonzero(kept.all(axis=1))
            hw, aw = h[whole], a[whole]
            inside = d2[whole] - hw * hw <= ((column * aw) ** 2)[:, None]
            lo, hi = _sheet_cuts(np.where(inside, hw, 0.0), column_gap * aw, column=True)
            kept[whole] = _sheet_apply(hw, lo, hi, minimum, own, far_span * aw)
        return kept

    idx = np.asarray(indices, np.int64)
    n, k = idx.shape
    keep = np.ones((n, k), bool)
    m = min(6, k - 1)
    if m < 1:
        return keep
    for start in range(0, n, _SHEET_BLOCK):
        rows = np.arange(start, min(start + _SHEET_BLOCK, n))
        q = points[idx[rows]] - points[rows][:, None, :]
        nrm = normals[rows]
        h = q[..., 0] * nrm[:, 0:1] + q[..., 1] * nrm[:, 1:2] + q[..., 2] * nrm[:, 2:3]
        d2 = q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1] + q[..., 2] * q[..., 2]
        dist = np.sqrt(d2)
        a = dist[:, 1].copy()
        for j in range(2, m + 1):
            a = a + dist[:, j]
        a = a / m
        kept = rules(h, d2, a)
        if trim > 0:
            near = np.abs(h) <= (trim * a)[:, None]
            count = near.sum(axis=1)
            again = np.flatnonzero(kept.all(axis=1) & (count < k) & (count >= 3))
            qa, na = q[again], near[again][..., None]
            c = np.where(na, qa, 0.0).sum(axis=1) / count[again][:, None]
            r = np.where(na, qa - c[:, None, :], 0.0)
            normal = np.linalg.eigh(np.einsum("rka,rkb->rab", r, r))[1][:, :, 0]
            was = nrm[again]
            turn = np.abs(
                normal[:, 0] * was[:, 0] + normal[:, 1] * was[:, 1] + normal[:, 2] * was[:, 2]
            )
            little = turn >= trim_cos
            again, qa, normal = again[little], qa[little], normal[little]
            h2 = (
                qa[..., 0] * normal[:, 0:1]
                + qa[..., 1] * normal[:, 1:2]
                + qa[..., 2] * normal[:, 2:3]
            )
            kept[again] = rules(h2, d2[again], a[again])
        keep[rows] = kept
    return keep


def _sheet_cuts(h: np.ndarray, g: np.ndarray, *, column: bool) -> tuple[np.ndarray, np.ndarray]:
    """The kept range ``lo <= h <= hi`` per row of heights h (r, k), a gap being a step
    ``> g`` (r,) between sorted heights: above 0, the first gap's near end (rule 1) or,
    ``column`` (rule 2), its middle when it is the only gap above 0; ``+inf`` when
    there is none; below 0 likewise, else ``-inf``. Returns lo, hi (r,)."""
    k = h.shape[1]
    hs = np.sort(h, axis=1)
    z = (hs < 0).sum(axis=1)
    step = (hs[:, 1:] - hs[:, :-1]) > g[:, None]
    col = np.arange(k - 1)[None, :]
    up = step & (col >= z[:, None])
    down = step & (col < z[:, None])
    r = np.arange(len(hs))
    c_up = up.argmax(axis=1)
    c_down = (k - 2) - down[:, ::-1].argmax(axis=1)
    if column:
        top = 0.5 * (hs[r, c_up] + hs[r, c_up + 1])
        bottom = 0.5 * (hs[r, c_down] + hs[r, c_down + 1])
    else:
        top, bottom = hs[r, c_up], hs[r, c_down + 1]
    n_up, n_down = up.sum(axis=1), down.sum(axis=1)
    hi = np.where((n_up == 1) if column else (n_up >= 1), top, np.inf)
    lo = np.where((n_down == 1) if column else (n_down >= 1), bottom, -np.inf)
    return lo, hi


def _sheet_apply(
    h: np.ndarray, lo: np.ndarray, hi: np.ndarray, minimum: int, own: float, span: np.ndarray
) -> np.ndarray:
    """``lo <= h <= hi`` (r, k) from heights h (r, k) and cuts (r,); a row keeps every
    point when it would drop fewer than ``minimum``, keep fewer than ``own`` times as
    many as it drops, or drop heights on one side that span more than ``span`` (r,)."""
    below, above = h < lo[:, None], h > hi[:, None]
    kept = (h >= lo[:, None]) & (h <= hi[:, None])
    dropped = (~kept).sum(axis=1)
    whole = (dropped < minimum) | ((h.shape[1] - dropped) < own * dropped)
    whole |= (_span(h, below) > span) | (_span(h, above) > span)
    kept[whole] = True
    return kept


def _span(h: np.ndarray, sel: np.ndarray) -> np.ndarray:
    """``max - min`` of the heights h (r, k) where ``sel`` (r, k), per row (0 where none)."""
    top = np.where(sel, h, -np.inf).max(axis=1)
    bottom = np.where(sel, h, np.inf).min(axis=1)
    return np.where(sel.any(axis=1), top - bottom, 0.0)


#: Rows per block of :func:`sheet_mask` (bounds its (rows, k, 3) temporaries).
_SHEET_BLOCK = 32768


class SheetNeighbourhoods:
    """kNN neighbourhoods less the neighbours on other sheets (:func:`sheet_mask`).

    Parameters
    ----------
    points : (n, 3) float64
    base : KnnNeighbourhoods
        The lists at the largest scale ``k_max``.
    weighting : {"gaussian", "none"}
        Weighting of the PCA normal of each ``k_max``-list (paper mode's normal at the
        largest scale).

    Attributes
    ----------
    keep : (n, k_max) bool
        :func:`sheet_mask` of ``base``'s lists.
    """

    def __init__(self, points: np.ndarray, base: KnnNeighbourhoods, weighting: Weighting) -> None:
        self.base = base
        self.k_max = base.k_max
        self.tree = None
        self.workers = base.workers
        self._idx = np.asarray(base.indices, np.int64)
        _, normals = projected_distances(points, base.at(base.k_max), weighting=weighting)
        self.keep = sheet_mask(points, self._idx, normals, sheet_parameters())

    def at(self, k: int) -> Neighbourhood:
        """The kept points among each point's ``k`` nearest (CSR, ``k <= k_max``)."""
        return self._csr(self.keep[:, :k], self._idx[:, :k])

    def first(self, k: int) -> Neighbourhood:
        """The first ``k`` kept points of each list (fewer when fewer are kept)."""
        keep = self.keep & (np.cumsum(self.keep, axis=1) <= k)
        return self._csr(keep, self._idx)

    @staticmethod
    def _csr(keep: np.ndarray, idx: np.ndarray) -> Neighbourhood:
        indptr = np.concatenate([[0], np.cumsum(keep.sum(axis=1))]).astype(np.int64)
        return Neighbourhood(indptr, idx[keep])


def _isolated_from_stats(
    points: np.ndarray, stats: _kernels.CloudStats, workers: int = -1
) -> np.ndarray:
    """:func:`isolated_points` from the pass's :class:`~meshlab_sharp._kernels.CloudStats` at
    ``k_max`` (no kNN table): ``i`` is among the k_max nearest of ``j = near[i]`` when
    ``(|p_i - p_j|^2, i)`` does not come after ``j``'s k_max-th neighbour in the
    lists' order (squared distance, then index). (n,) bool, computed in C
    (:func:`meshlab_sharp._kernels.isolated_from_stats`)."""
    return _kernels.isolated_from_stats(points, stats, workers)


def _segment_sums(values: np.ndarray, indptr: np.ndarray) -> np.ndarray:
    """Sums of ``values`` (len(indices),) or (len(indices), d) over CSR segments."""
    n = len(indptr) - 1
    out = np.zeros((n,) + values.shape[1:], dtype=values.dtype)
    nonempty = indptr[1:] > indptr[:-1]
    if nonempty.any():
        out[nonempty] = np.add.reduceat(values, indptr[:-1][nonempty], axis=0)
    return out


def _expand(starts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(starts[c], starts[c] + sizes[c])`` over c."""
    total = int(sizes.sum())
    first = np.repeat(starts - (np.cumsum(sizes) - sizes), sizes)
    return first + np.arange(total, dtype=np.int64)


def _rows(lists: Neighbourhood, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The entries of the CSR ``lists`` in ``rows``, flat: (position in ``rows``, index)."""
    indptr = np.asarray(lists.indptr, np.int64)
    indices = np.asarray(lists.indices, np.int64)
    starts = indptr[rows]
    sizes = indptr[rows + 1] - starts
    owner = np.repeat(np.arange(len(rows)), sizes)
    flat = _expand(starts, sizes)
    return owner, indices[flat] if len(flat) else np.zeros(0, np.int64)


def local_scale(
    points: np.ndarray, neighbourhood: Neighbourhood, *, backend: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Mean distance from each point to its neighbourhood, and its centroid's distance.

    Parameters
    ----------
    points : (m, 3) float64
    neighbourhood : Neighbourhood
        CSR lists (``indptr`` (m + 1,), ``indices``); each point's own index included.
    backend : {"compiled", "numpy"}, optional
        Default :func:`meshlab_sharp._kernels.default_backend`. Both give the same bits:
        the sums are numpy's ``add.reduceat`` (the first term plus the pairwise sum of
        the others), which the C kernel reproduces.

    Returns
    -------
    scale : (m,) float64
        ``l_i = (1 / |N(i)|) * sum_{j in N(i)} |p_j - p_i|`` (0 for an empty list).
    offset : (m,) float64
        ``o_i = |(1 / |N(i)|) * sum_{j in N(i)} (p_j - p_i)|``, the distance from
        ``p_i`` to the centroid (0 for an empty list); ``o_i <= l_i``.
    """
    if _kernels.resolve(backend) == "compiled":
        return _kernels.local_scale_csr(points, neighbourhood.indptr, neighbourhood.indices)
    indptr = np.asarray(neighbourhood.indptr, np.int64)
    indices = np.asarray(neighbourhood.indices, np.int64)
    size = np.diff(indptr)
    owner = np.repeat(np.arange(len(points)), size)
    q = points[indices] - points[owner]
    d = np.sqrt(q[:, 0] * q[:, 0] + q[:, 1] * q[:, 1] + q[:, 2] * q[:, 2])
    count = np.maximum(size, 1)
    scale = np.where(size > 0, _segment_sums(d, indptr) / count, 0.0)
    c = _segment_sums(q, indptr) / count[:, None]
    offset = np.sqrt(c[:, 0] * c[:, 0] + c[:, 1] * c[:, 1] + c[:, 2] * c[:, 2])
    return scale, offset


def relative_distances(pdis: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Projected distances relative to the local scale, clipped to [0, 1].

    Parameters
    ----------
    pdis : (m,) float64
        Projected distances ``|mean . n|``.
    scale : (m,) float64
        :func:`local_scale` at the same neighbourhoods.

    Returns
    -------
    (m,) float64
        ``min(pdis / scale, 1)``; 0 where ``scale == 0``.
    """
    r = np.zeros(np.shape(pdis))
    np.divide(pdis, scale, out=r, where=scale > 0)
    return np.minimum(r, 1.0, out=r)


def robust_threshold(r: np.ndarray, otsu: bool = True) -> float:
    """Otsu's threshold of relative distances on [0, 1], never below ``R_MIN``.

    Parameters
    ----------
    r : (m,) float64
        Relative projected distances in [0, 1] (isolated points left out).
    otsu : bool, default True
        False on a cloud without noise (:func:`otsu_splits`): the floor alone.

    Returns
    -------
    float
        ``max(otsu_threshold(r), R_MIN)``, or ``R_MIN`` when not ``otsu`` (then no
        histogram is made); candidates are ``r >= T``.
    """
    return robust_threshold_from_histogram(histogram(r)) if otsu else R_MIN


def robust_threshold_from_histogram(counts: np.ndarray, otsu: bool = True) -> float:
    """:func:`robust_threshold` from the 256-bin histogram (B,) int of the relative
    distances (:func:`meshlab_sharp.threshold.histogram`): histograms summed over parts of
    the points give the whole's threshold (the out-of-core tiles)."""
    return max(otsu_from_histogram(counts), R_MIN) if otsu else R_MIN


def quiet_cloud(mesh: bool, noise: float) -> bool:
    """Whether the input is a cloud without noise: not a mesh, and its noise ratio
    ``noise`` (the lower median of :func:`noise_ratios`, as :func:`noise_scale_factor`
    takes it) not above ``NOISE_QUIET``. The one test behind every rule kept for such
    clouds: the floor alone (:func:`otsu_splits`), :func:`support_exempt`,
    :func:`acute_tests`, :func:`thin_blockers` and the cone of :func:`thin_cone`."""
    return not (mesh or noise > NOISE_QUIET)


def otsu_splits(mesh: bool, noise: float) -> bool:
    """Whether Otsu's split raises the threshold above ``R_MIN``: on meshes, and on
    clouds whose noise ratio ``noise`` (the lower median of :func:`noise_ratios`, as
    :func:`noise_scale_factor` takes it) exceeds ``NOISE_QUIET``. On a cloud without
    noise the floor alone (measured: thin walls 1 / 2 / 3
    spacings F1 0.736 / 0.675 / 0.896 -> 0.744 / 0.711 / 0.913, no condition lower)."""
    return not quiet_cloud(mesh, noise)


def thin_blockers(candidates: np.ndarray, mesh: bool, noise: float) -> np.ndarray | None:
    """:func:`thin`'s ``between``: on a cloud whose noise ratio ``noise`` (as
    :func:`otsu_splits` takes it) is at most ``NOISE_QUIET``, the points that are not
    ``candidates`` (m,) bool (at every scale); None (no blocking) on meshes and noisier
    clouds. The two rims of a wall 2-3 spacings thick then do not thin each other away:
    the end face's middle, between them, is not a candidate, or ranks below both (a
    valley of the score, which :func:`thin` also reads as a parting)."""
    if not quiet_cloud(mesh, noise):
        return None
    return ~np.asarray(candidates, bool)


def thin_cone(mesh: bool, noise: float) -> float:
    """:func:`thin`'s ``cone_cos``: ``THIN_CONE_COS_NOISY`` on a cloud whose noise ratio
    ``noise`` (as :func:`otsu_splits` takes it) exceeds ``NOISE_QUIET``,
    ``THIN_CONE_COS`` on meshes and quiet clouds. Noise tilts the offsets between a
    line's own points, which then count as across the line and thin it to gaps
    (measured: thickness on the scan 0.79 -> 0.82, at noise 50 %
    0.78 -> 0.83)."""
    return THIN_CONE_COS if mesh or quiet_cloud(mesh, noise) else THIN_CONE_COS_NOISY


def ranking_smoothed(mesh: bool, noise: float) -> bool:
    """Whether thinning ranks by :func:`smoothed_ranking`: on a cloud whose noise ratio
    ``noise`` (as :func:`otsu_splits` takes it) grew the scales to the cap
    (``noise_factor(noise) == NOISE_MAX_FACTOR``). Beyond it the larger scales no longer
    dilute the noise of the score, and single points lifted 1-2 spacings beside a line
    outrank the line's own (measured: noise 50 % F1 0.752 ->
    0.813, thickness 0.72 -> 0.78)."""
    return not mesh and noise_factor(noise) == NOISE_MAX_FACTOR


def smoothed_ranking(score: np.ndarray, compare: Neighbourhood, window: int) -> np.ndarray:
    """The score averaged over the first ``window`` entries of each non-empty row of
    ``compare`` (the point itself first), added in list order to 0.0 and divided by
    their number; the score itself on the empty rows.

    Parameters
    ----------
    score : (m,) float64
    compare : Neighbourhood
        Thinning's CSR lists (the candidates' nearest).
    window : int

    Returns
    -------
    (m,) float64
    """
    score = np.asarray(score, np.float64)
    out = score.copy()
    indptr = np.asarray(compare.indptr, np.int64)
    indices = np.asarray(compare.indices, np.int64)
    rows = np.flatnonzero(np.diff(indptr) > 0)
    if len(rows) == 0:
        return out
    take = np.minimum(np.diff(indptr)[rows], window)
    acc = np.zeros(len(rows))
    for c in range(int(take.max())):
        live = take > c
        acc[live] += score[indices[indptr[rows[live]] + c]]
    out[rows] = acc / take
    return out


def support_free_score(mesh: bool, noise: float) -> float | None:
    """The score below which :func:`supported` keeps a point without support:
    ``SUPPORT_FREE_SCORE`` on a cloud whose noise ratio ``noise`` (as :func:`otsu_splits`
    takes it) is at most ``NOISE_QUIET``; None (no such score) on meshes and noisier
    clouds."""
    return SUPPORT_FREE_SCORE if quiet_cloud(mesh, noise) else None


def support_exempt(score: np.ndarray, mesh: bool, noise: float) -> np.ndarray:
    """The points that :func:`supported` keeps without support: those whose ``score``
    (m,) is below :func:`support_free_score` (none on meshes and noisier clouds).
    Returns (m,) bool."""
    score = np.asarray(score, np.float64)
    free = support_free_score(mesh, noise)
    if free is None:
        return np.zeros(len(score), bool)
    return score < free


def acute_tests(score: np.ndarray, mask: np.ndarray, mesh: bool, noise: float) -> np.ndarray:
    """The points :func:`acute_tips` tests: on a cloud whose noise ratio ``noise`` (as
    :func:`otsu_splits` takes it) is at most ``NOISE_QUIET``, those not in ``mask`` (m,)
    bool (the candidates at every scale) whose ``score`` (m,) lies in ``[ACUTE_SCORE,
    ACUTE_SCORE_MAX)``; none on meshes and noisier clouds. Returns (t,) int64,
    increasing."""
    if not quiet_cloud(mesh, noise):
        return np.zeros(0, np.int64)
    score = np.asarray(score, np.float64)
    test = ~np.asarray(mask, bool) & (score >= ACUTE_SCORE) & (score < ACUTE_SCORE_MAX)
    return np.flatnonzero(test)


def acute_tips(
    points: np.ndarray, mask: np.ndarray, rows: np.ndarray, lists: Neighbourhood
) -> np.ndarray:
    """Whether each of ``rows`` lies between two points of ``mask`` in its list.

    Parameters
    ----------
    points : (m, 3) float64
    mask : (m,) bool
        Candidates at every scale.
    rows : (t,) int
        The points tested (:func:`acute_tests`), increasing.
    lists : Neighbourhood
        CSR lists of at least the ``rows`` (the thinning's ``thin_knn`` nearest).

    Returns
    -------
    (t,) bool
        For ``i = rows[a]``: some ``j != l`` of ``lists[i]``, both in ``mask`` and not
        ``i``, with ``(p_j - p_i) . (p_l - p_i) < 0`` (components ``x, y, z``, products
        added in that order, strict: ``i`` lies inside the ball on ``p_j p_l`` as a
        diameter). Such an ``i`` joins the candidates: at an acute edge the candidates
        lie on the two faces beside the tip, ahead of and behind it along the edge, and
        the tip has the higher score (thinning keeps it: one line, not two beside it).
    """
    rows = np.asarray(rows, np.int64)
    mask = np.asarray(mask, bool)
    out = np.zeros(len(rows), bool)
    if len(rows) == 0:
        return out
    owner, nb = _rows(lists, rows)
    use = mask[nb] & (nb != rows[owner])
    owner, nb = owner[use], nb[use]
    q = points[nb] - points[rows[owner]]
    sizes = np.bincount(owner, minlength=len(rows))
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    first = np.repeat(np.arange(len(owner)), sizes[owner])
    second = _expand(starts[owner], sizes[owner])
    a, b = q[first], q[second]
    dot = a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]
    out[owner[first[dot < 0]]] = True
    return out


@dataclass
class RelativeRule:
    """Per-scale rule of robust mode for :func:`meshlab_sharp.multiscale.run_scales`.

    Called as ``rule(i, scale, pdis)`` for the i-th scale (the compiled pass, which does
    this arithmetic itself, hands its score to ``rule.from_pass`` instead): returns
    the relative distances (m,) and the threshold; it also accumulates ``score``, the mean over the
    scales of ``o / l`` (:func:`local_scale`: the centroid's distance relative to the
    local scale), the ranking used by :func:`thin`. Not ``r``: at an acute edge the
    normal turns, the projected distance peaks beside the edge, the centroid's distance
    at the edge.

    Parameters
    ----------
    points : (m, 3) float64
    lists : callable
        ``lists(scale) -> Neighbourhood``, the neighbourhoods of that scale (called in
        increasing order of scale).
    n_scales : int
    sheet : (float, int, float, float, float, float) or None
        :func:`sheet_parameters` when ``lists`` leave out the other sheets
        (:class:`SheetNeighbourhoods`): the compiled pass over a cloud then does too.
    otsu : bool, default True
        :func:`robust_threshold`'s ``otsu`` (:func:`otsu_splits`).
    """

    points: np.ndarray
    lists: object
    n_scales: int
    sheet: _kernels.SheetParameters | None = None
    otsu: bool = True

    def __post_init__(self) -> None:
        self.score = np.zeros(len(self.points))

    def __call__(self, i: int, scale: int, pdis: np.ndarray) -> tuple[np.ndarray, float]:
        """Relative distances (m,) and threshold of the i-th scale, ``scale``."""
        ell, offset = local_scale(self.points, self.lists(scale))  # type: ignore[operator]
        r = relative_distances(np.asarray(pdis, np.float64), ell)
        self.score += relative_distances(offset, ell) / self.n_scales
        return r, robust_threshold(r, self.otsu)

    def from_pass(self, score: np.ndarray) -> tuple[bool, float]:
        """Take the final ``score`` (m,) of the compiled pass (over a cloud or a mesh's
        rings), which computed it and every scale's relative distances with this rule's
        arithmetic (:class:`meshlab_sharp._kernels.ScalePass`); returns how
        :func:`robust_threshold` thresholds them, ``(otsu, floor)``, for
        :func:`meshlab_sharp._kernels.scale_vote` (the same threshold)."""
        self.score = score
        return self.otsu, R_MIN


#: Fewest feature points in one thread's part of the line directions (below it the
#: threads' start costs more than they save).
PART_MIN = 2048


def _in_parts(rows: np.ndarray, work: Callable[[np.ndarray], None], workers: int) -> None:
    """``work(part)`` for consecutive parts of ``rows`` (about one per worker, none
    under ``PART_MIN`` rows) on ``workers`` threads (numpy releases the GIL in the
    arithmetic, the gathers and ``eigh``). Each row's answer depends on that row alone,
    so the parts give the answers of one call over all the rows, bit for bit."""
    w = _kernels._workers(workers)
    size = max(PART_MIN, -(-len(rows) // w))

    def task(a: int, b: int) -> int:
        work(rows[a:b])
        return 0

    _kernels._run_chunks(len(rows), w, task, chunk=size)


def line_directions(
    points: np.ndarray, mask: np.ndarray, direction: Neighbourhood, workers: int = 1
) -> np.ndarray:
    """Direction of the line of features through each feature point.

    Parameters
    ----------
    points : (m, 3) float64
    mask : (m,) bool
        Feature points.
    direction : Neighbourhood
        CSR lists (the largest scale; each point's own index included).
    workers : int, default 1
        Threads (-1: one per core), the feature points in parts (:func:`_in_parts`).

    Returns
    -------
    (m, 3) float64
        For a feature point ``i``: the unit eigenvector of the largest eigenvalue of
        ``C = sum_j (q_j - qbar)(q_j - qbar)^T`` over the feature points ``j`` of
        ``direction[i]`` (``i`` included), ``q_j = p_j - p_i``, ``qbar`` their mean
        (its sign is arbitrary). Zero rows for the other points.
    """
    mask = np.asarray(mask, bool)
    e = np.zeros((len(points), 3))

    def part(cand: np.ndarray) -> None:
        e[cand] = _line_directions_of(points, mask, direction, cand)

    _in_parts(np.flatnonzero(mask), part, workers)
    return e


def _line_directions_of(
    points: np.ndarray, mask: np.ndarray, direction: Neighbourhood, cand: np.ndarray
) -> np.ndarray:
    """:func:`line_directions` of the feature points ``cand`` (c,): (c, 3) float64."""
    owner, members = _rows(direction, cand)
    use = mask[members]
    owner, members = owner[use], members[use]
    q = points[members] - points[cand[owner]]
    sizes = np.bincount(owner, minlength=len(cand))
    ptr = np.concatenate([[0], np.cumsum(sizes)])
    qsum = _segment_sums(q, ptr)
    outer = _segment_sums(q[:, :, None] * q[:, None, :], ptr)
    safe = np.maximum(sizes.astype(np.float64), 1.0)[:, None]
    qbar = qsum / safe
    cov = outer - safe[:, :, None] * qbar[:, :, None] * qbar[:, None, :]
    _, vecs = np.linalg.eigh(cov)
    return vecs[:, :, 2]


def _feature_pairs(
    points: np.ndarray, mask: np.ndarray, e: np.ndarray, lists: Neighbourhood, cone_cos: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (i, j) of features, ``j != i`` in ``lists[i]``: the position of ``i`` among
    the features, ``i``, ``j`` and whether ``d = p_j - p_i`` lies across the line
    through ``i`` (``|d . e_i| < cone_cos * |d|``)."""
    cand = np.flatnonzero(mask)
    owner, nb = _rows(lists, cand)
    ci = cand[owner]
    use = mask[nb] & (nb != ci)
    owner, nb, ci = owner[use], nb[use], ci[use]
    d = points[nb] - points[ci]
    along = np.abs((d * e[ci]).sum(axis=1))
    across = along < cone_cos * np.sqrt((d * d).sum(axis=1))
    return owner, ci, nb, across


def supported(
    points: np.ndarray,
    mask: np.ndarray,
    e: np.ndarray,
    around: Neighbourhood,
    minimum: int = SUPPORT_MIN,
    *,
    cone_cos: float = THIN_CONE_COS,
    exempt: np.ndarray | None = None,
) -> np.ndarray:
    """Features with at least ``minimum`` other features along their line.

    Parameters
    ----------
    points : (m, 3) float64
    mask : (m,) bool
        Features before the test.
    e : (m, 3) float64
        :func:`line_directions` of ``mask``.
    around : Neighbourhood
        CSR lists (each point's own index included; it is not counted).
    minimum : int, default SUPPORT_MIN (2)
    cone_cos : float, default THIN_CONE_COS (0.5)
    exempt : (m,) bool, optional
        Features kept whatever their support (:func:`support_exempt`); default none.

    Returns
    -------
    (m,) bool
        ``mask[i]`` and at least ``minimum`` features ``j != i`` of ``around[i]`` with
        ``d = p_j - p_i`` along the line: ``|d . e_i| >= cone_cos * |d|``, or
        ``mask[i]`` and ``exempt[i]``.
    """
    mask = np.asarray(mask, bool)
    cand = np.flatnonzero(mask)
    if len(cand) == 0:
        return mask.copy()
    owner, _, _, across = _feature_pairs(points, mask, e, around, cone_cos)
    count = np.bincount(owner[~across], minlength=len(cand))
    weak = count < minimum
    if exempt is not None:
        weak &= ~np.asarray(exempt, bool)[cand]
    out = mask.copy()
    out[cand[weak]] = False
    return out


def thin(
    points: np.ndarray,
    mask: np.ndarray,
    score: np.ndarray,
    e: np.ndarray,
    compare: Neighbourhood,
    *,
    cone_cos: float = THIN_CONE_COS,
    between: np.ndarray | None = None,
) -> np.ndarray:
    """Non-maximum suppression of feature points across the feature line.

    A feature point ``i`` is dropped when some feature point ``j != i`` of
    ``compare[i]`` with ``d = p_j - p_i`` lies across the line through ``i``
    (``|d . e_i| < cone_cos * |d|``) and ``score[j] > score[i]``, unless (with
    ``between``) a point ``m`` of ``compare[i]`` with ``between[m]`` or ``score[m] <
    score[i]`` (a valley between two ridges) lies between them: ``(p_m - p_i) . (p_m -
    p_j) < 0``. Every decision uses the mask before thinning.

    Parameters
    ----------
    points : (m, 3) float64
    mask : (m,) bool
        Feature points before thinning.
    score : (m,) float64
        Ranking (:class:`RelativeRule`'s ``score``).
    e : (m, 3) float64
        Line directions (:func:`line_directions`).
    compare : Neighbourhood
        CSR lists for the comparison (``THIN_KNN`` nearest or the ``THIN_RING``-ring).
    cone_cos : float, default THIN_CONE_COS (0.5)
    between : (m,) bool, optional
        The points that part two features whatever their score (:func:`thin_blockers`);
        default none, and then no blocking at all.

    Returns
    -------
    (m,) bool
        The thinned mask (a subset of ``mask``).
    """
    mask = np.asarray(mask, bool)
    cand = np.flatnonzero(mask)
    if len(cand) == 0:
        return mask.copy()
    owner, ci, nb, across = _feature_pairs(points, mask, e, compare, cone_cos)
    beaten = across & (score[nb] > score[ci])
    if between is not None:
        pair = np.flatnonzero(beaten)
        at, m = _rows(compare, ci[pair])
        use = np.asarray(between, bool)[m] | (score[m] < score[ci[pair[at]]])
        at, m = at[use], m[use]
        a = points[m] - points[ci[pair[at]]]
        b = points[m] - points[nb[pair[at]]]
        dot = a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]
        beaten[pair[np.unique(at[dot < 0])]] = False
    suppressed = np.bincount(owner[beaten], minlength=len(cand)) > 0
    out = mask.copy()
    out[cand[suppressed]] = False
    return out


class RobustSetup:
    """What robust mode adds around :func:`meshlab_sharp.multiscale.run_scales`.

    Parameters
    ----------
    points : (m, 3) float64
        Cleaned points.
    faces : (f, 3) int or None
        Cleaned triangles of a mesh; None for a cloud.
    neighbourhoods : KnnNeighbourhoods or RingNeighbourhoods
        Those of ``points`` (built by the pipeline).
    scales : tuple of int
        Increasing scales.
    workers : int, default -1
        Threads for a kNN query when isolated points are left out, and for the line
        directions.
    weighting : {"gaussian", "none"}, default "gaussian"
    keep_normals : bool, default False
        How :func:`meshlab_sharp.multiscale.run_scales` will be called (the compiled
        pass that finds the isolated points and the noise also computes what it needs).
    sharp_edges : (m,) bool, optional
        A mesh's :func:`meshlab_sharp.creases.sharp_vertices` mask when the caller has
        found it already (``detect`` finds it on a thread beside the adjacency); None:
        found here.

    Attributes
    ----------
    keep : (p,) int64
        Indices (into ``points``) of the points processed: all for a mesh, the
        non-isolated ones for a cloud.
    points, neighbourhoods
        The points processed and their neighbourhoods (rebuilt without the isolated
        points when there are any).
    rule : RelativeRule
        The per-scale rule to pass to ``run_scales``.
    fused : ScalePass or None
        The compiled pass over ``points`` at ``scales`` to pass to ``run_scales``, when
        the set-up's search already made it (compiled backend, a cloud whose noise did
        not grow the scales); None otherwise, and once :meth:`finish` starts (its
        per-scale arrays, read by ``run_scales``, are released before support and
        thinning).
    sharp_edges : (m,) bool or None
        A mesh's vertices on its own sharp edges
        (:func:`meshlab_sharp.creases.sharp_vertices`): the ``sharp_edges`` given, or
        found here before the ring pass's arrays exist; None for a cloud.
    """

    def __init__(
        self,
        points: np.ndarray,
        faces: np.ndarray | None,
        neighbourhoods: KnnNeighbourhoods | RingNeighbourhoods,
        scales: tuple[int, ...],
        *,
        workers: int = -1,
        weighting: Weighting = DEFAULT_WEIGHTING,
        keep_normals: bool = False,
        sharp_edges: np.ndarray | None = None,
    ) -> None:
        self.n = len(points)
        #: A mesh's set-up (the faces themselves are not kept: 48 bytes a vertex).
        self.mesh = faces is not None
        self.workers = workers
        self.scales = tuple(scales)
        self.keep = np.arange(self.n, dtype=np.int64)
        self.points = points
        self.neighbourhoods = neighbourhoods
        self.weighting = weighting
        self.keep_normals = keep_normals
        self.fused: _kernels.ScalePass | None = None
        #: How much the noise grew the scales (1: not at all).
        self.growth = 1.0
        #: The cloud's noise ratio (the lower median of :func:`noise_ratios`; 0 on a mesh).
        self.noise = 0.0
        #: The neighbourhoods the scales use: ``neighbourhoods`` (meshes; clouds with
        #: the compiled pass, which leaves the other sheets out itself), or their
        #: :class:`SheetNeighbourhoods` (clouds, numpy).
        self.scale_neighbourhoods: KnnNeighbourhoods | RingNeighbourhoods | SheetNeighbourhoods
        self.scale_neighbourhoods = neighbourhoods
        sheet = None
        if faces is None:
            assert isinstance(neighbourhoods, KnnNeighbourhoods)
            sheet = sheet_parameters()
            top = max(self.scales)
            k0 = min(NOISE_KNN, top)
            compiled = neighbourhoods.tree is not None
            if compiled:
                self.fused = self._pass(k0, sheet)
                assert self.fused.stats is not None
                isolated = _isolated_from_stats(points, self.fused.stats, workers)
            else:
                isolated = isolated_points(neighbourhoods.indices)
            if isolated.any():
                self.fused = None  # freed before the pass over the points kept
                self.keep = np.flatnonzero(~isolated)
                self.points = np.ascontiguousarray(points[self.keep])
                self.neighbourhoods = build_neighbourhoods(
                    self.points, None, self.scales, workers=workers
                )
                if compiled:
                    self.fused = self._pass(k0, sheet)
            del isolated
            if self.fused is not None and self.fused.stats is not None:
                self.noise = _pass_noise_median(self.fused.stats.noise, workers)
                self.fused.stats = None  # read: its (n,) arrays are not kept
                self.scale_neighbourhoods = self.neighbourhoods
            else:
                self.scale_neighbourhoods = self._sheets()
                self.noise = _noise_median(
                    noise_ratios_lists(self.points, self.scale_neighbourhoods.first(k0))
                )
            factor = min(noise_factor(self.noise), len(self.points) / top)
            if factor > 1.0:
                self.growth = factor
                self.scales = grown_scales(self.scales, factor)
                self.neighbourhoods = build_neighbourhoods(
                    self.points, None, self.scales, workers=workers
                )
                self.fused = None
                self.scale_neighbourhoods = self.neighbourhoods if compiled else self._sheets()
        if faces is None:
            self.sharp_edges = None
        elif sharp_edges is None:
            self.sharp_edges = sharp_vertices(points, faces)[0]
        else:
            self.sharp_edges = np.asarray(sharp_edges, bool)
        otsu = otsu_splits(faces is not None, self.noise)
        # the lists' own method, not one of self: a rule that referred back to this
        # setup made a reference cycle, so the arrays of every call (the kd-tree, the
        # pass's outputs: about 55 bytes a point) stayed until the garbage collector ran
        lists = self.scale_neighbourhoods.at
        self.rule = RelativeRule(self.points, lists, len(self.scales), sheet, otsu)

    def _sheets(self) -> SheetNeighbourhoods:
        """:class:`SheetNeighbourhoods` of ``neighbourhoods`` (numpy kNN lists)."""
        assert isinstance(self.neighbourhoods, KnnNeighbourhoods)
        return SheetNeighbourhoods(self.points, self.neighbourhoods, self.weighting)

    def _pass(self, noise_k: int, sheet: _kernels.SheetParameters) -> _kernels.ScalePass:
        """The compiled pass at ``scales`` over ``points`` (whose kd-tree
        ``neighbourhoods`` holds): projected distances, local scales, and the isolated
        points' and the noise's statistics from the same search. It is the pass
        ``run_scales`` needs when it finds no isolated points and no noise to grow the
        scales for (``fused``)."""
        assert isinstance(self.neighbourhoods, KnnNeighbourhoods)
        assert self.neighbourhoods.tree is not None
        return _kernels.cloud_projected_distances(
            self.neighbourhoods.tree,
            self.scales,
            self.weighting,
            keep_normals=self.keep_normals,
            relative=True,
            noise_k=noise_k,
            sheet=sheet,
            workers=self.neighbourhoods.workers,
            tree_order=True,  # read by scale_vote, isolated_from_stats and a median only
        )

    def _compiled(self) -> bool:
        """Whether :meth:`finish` runs its steps in C: the neighbourhoods are the compiled
        backend's (a cloud's kd-tree, a mesh's adjacency)."""
        lists = self.neighbourhoods
        if isinstance(lists, KnnNeighbourhoods):
            return lists.tree is not None
        return lists.adjacency is not None

    def _candidate_lists(self, rows: np.ndarray, ks: tuple[int, ...]) -> list[Neighbourhood]:
        """The kNN lists at each of ``ks`` (at most ``k_max``) for the points ``rows``
        (increasing) only, the other rows empty: what support and thinning read (numpy)."""
        assert isinstance(self.neighbourhoods, KnnNeighbourhoods)
        table = np.asarray(self.neighbourhoods.indices)[rows, : max(ks)]
        before = np.zeros(len(self.points) + 1, dtype=np.int64)  # rows before each point
        before[np.asarray(rows, dtype=np.int64) + 1] = 1
        np.cumsum(before, out=before)
        return [
            Neighbourhood(before * k, np.ascontiguousarray(table[:, :k]).reshape(-1)) for k in ks
        ]

    def _ring_rows(self, rows: np.ndarray, rings: tuple[int, ...]) -> list[Neighbourhood]:
        """The k-rings, k in ``rings`` (increasing), of the vertices ``rows`` only (the
        other rows empty), each listed as ``RingNeighbourhoods.at(k)`` lists it (a row
        depends only on its vertex: :func:`meshlab_sharp.neighbourhoods.grow_rings`)."""
        assert isinstance(self.neighbourhoods, RingNeighbourhoods)
        grown = grow_rings(self.neighbourhoods.lists(), rows)
        listed = dict(zip(range(1, max(rings) + 1), grown, strict=False))
        out = []
        for k in rings:
            indptr = np.zeros(self.n + 1, dtype=np.int64)  # the sizes, summed in place
            indptr[np.asarray(rows, dtype=np.int64) + 1] = listed[k].sizes
            np.cumsum(indptr, out=indptr)
            out.append(Neighbourhood(indptr, listed[k].indices))
        return out

    def _list_sizes(self) -> tuple[int, int, int]:
        """The sizes of each candidate's support, comparison and direction lists: the
        SUPPORT_KNN, thin_knn and k_max nearest (clouds), the THIN_RING-ring twice and
        the largest ring (meshes)."""
        top = max(self.scales)
        if self.mesh:
            return min(THIN_RING, top), min(THIN_RING, top), top
        return min(SUPPORT_KNN, top), min(thin_knn(self.growth), top), top

    def finish(self, mask: np.ndarray, strength: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Acute tips (clouds without noise), support, thinning and (meshes) the sharp
        mesh edges, on all cleaned points: in C with the compiled backend
        (:meth:`_finish_compiled`), in numpy otherwise (:meth:`_finish_numpy`), the same
        masks.

        Parameters
        ----------
        mask : (p,) bool
            Candidates at every scale, per processed point (:func:`acute_tips` adds
            the tips of acute edges on a cloud without noise).
        strength : (p,) float64
            Fraction of scales at which each processed point was a candidate.

        Returns
        -------
        mask, strength : (m,) bool, (m,) float64
            Per cleaned point (isolated points: False, 0). On a mesh, vertices of a
            sharp edge (:func:`meshlab_sharp.creases.sharp_vertices`) are features with
            strength 1.
        """
        self.fused = None
        if mask.any():
            mask = self._finish_compiled(mask) if self._compiled() else self._finish_numpy(mask)
        if self.sharp_edges is not None:
            mask = mask | self.sharp_edges
            strength = np.where(self.sharp_edges, 1.0, strength)
        return self.expand(mask, False), self.expand(strength, 0.0)

    def _finish_numpy(self, mask: np.ndarray) -> np.ndarray:
        """:meth:`finish`'s acute tips, support and thinning of ``mask`` (p,) bool in
        numpy (the reference): the thinned mask (p,) bool."""
        mesh = self.mesh
        around_k, compare_k, top = self._list_sizes()
        tests = acute_tests(self.rule.score, mask, mesh, self.noise)
        if len(tests):
            (near,) = self._candidate_lists(tests, (compare_k,))
            mask = mask.copy()
            mask[tests[acute_tips(self.points, mask, tests, near)]] = True
        if mesh:
            around, direction = self._ring_rows(np.flatnonzero(mask), (around_k, top))
            compare = around
        else:
            around, compare, direction = self._candidate_lists(
                np.flatnonzero(mask), (around_k, compare_k, top)
            )
        e = line_directions(self.points, mask, direction, self.workers)
        free = support_exempt(self.rule.score, mesh, self.noise)
        block = thin_blockers(mask, mesh, self.noise)
        rank = self.rule.score
        if ranking_smoothed(mesh, self.noise):
            rank = smoothed_ranking(rank, compare, THIN_KNN)
        mask = supported(
            self.points, mask, e, around, SUPPORT_MIN, cone_cos=THIN_CONE_COS, exempt=free
        )
        return thin(
            self.points, mask, rank, e, compare, cone_cos=thin_cone(mesh, self.noise), between=block
        )

    def _finish_compiled(self, mask: np.ndarray) -> np.ndarray:
        """:meth:`_finish_numpy` in C (:func:`meshlab_sharp._kernels.acute_tips` and
        :func:`~meshlab_sharp._kernels.support_and_thin`), the candidates taken in tree
        order (clouds; each step independent per candidate, the order changes nothing)
        with their lists from the kd-tree (one table of the k_max nearest of the
        candidates and the points tested as tips, read at every k) or the adjacency (the
        largest ring, its THIN_RING-ring a prefix): the same mask."""
        mesh = self.mesh
        around_k, compare_k, top = self._list_sizes()
        lists = self.neighbourhoods
        if isinstance(lists, KnnNeighbourhoods):
            assert lists.tree is not None
            tests = acute_tests(self.rule.score, mask, mesh, self.noise)
            todo = mask
            if len(tests):
                todo = mask.copy()
                todo[tests] = True
            # one search for the candidates and the points tested as acute tips, in tree
            # order (no inverse of the tree's order, the rows of a leaf searched together)
            rows, table = _kernels.cloud_knn_of_mask(lists.tree, todo, top, lists.workers)
            del todo
            slots = None  # every row of the table
            if len(tests):
                tested = np.flatnonzero(~mask[rows])
                near = _kernels.CandidateLists.knn(table, compare_k, tested)
                tips = _kernels.acute_tips(self.points, mask, rows[tested], near, self.workers)
                mask = mask.copy()
                mask[rows[tested[tips]]] = True
                slots = np.flatnonzero(mask[rows])
                rows = rows[slots]
            around, compare, direction = (
                _kernels.CandidateLists.knn(table, k, slots) for k in (around_k, compare_k, top)
            )
        else:
            assert lists.adjacency is not None
            rows = np.flatnonzero(mask)
            members = _kernels.ring_members(lists.adjacency, rows, (around_k, top), self.workers)
            around, direction = _kernels.CandidateLists.rings(members)
            compare = around
        rules = _kernels.FinishRules(
            support_cone=THIN_CONE_COS,
            minimum=SUPPORT_MIN,
            free_below=support_free_score(mesh, self.noise),
            thin_cone=thin_cone(mesh, self.noise),
            window=THIN_KNN if ranking_smoothed(mesh, self.noise) else 0,
            between=thin_blockers(mask, mesh, self.noise),
        )
        return _kernels.support_and_thin(
            self.points,
            mask,
            self.rule.score,
            rows,
            (direction, around, compare),
            rules,
            self.workers,
        )

    def expand(self, values: np.ndarray, fill: object) -> np.ndarray:
        """Per-processed-point values (p, ...) to all cleaned points (m, ...), ``fill``
        for the isolated ones."""
        if len(self.keep) == self.n:
            return values
        out = np.full((self.n,) + values.shape[1:], fill, dtype=values.dtype)
        out[self.keep] = values
        return out
