"""Robust mode: the projected-distance method where the paper's reading fails.

``detect(..., mode="robust")`` changes these things of the paper's method (measured
choices, see ``docs/method.md``; the arithmetic the plugin shares is pinned down in
``docs/contributing.md``):

1. **Isolated points are left out** (point clouds): point ``i`` is isolated when it is
   not among the ``k_max`` nearest neighbours of its own nearest neighbour, or when its
   ``ISOLATED_NTH``-th nearest lies more than ``ISOLATED_SPREAD`` times farther than the
   ``ISOLATED_REF``-th nearest of its ``k_max``-th neighbour (a stray pair or triple off
   the surface: its first neighbours are each other and points far away, while its
   ``k_max``-th lies on the sampled surface). Detection runs on the other points;
   isolated points are never features.
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
   ``THIN_CONE_COS_NOISY``: noise tilts a line's own offsets) or beside it (farther from
   the line than ``THIN_SIDE``, on noisy clouds ``THIN_SIDE_NOISY``, times the distance
   to the last of the list, whatever the angle: :func:`thin_side`), ranks higher (mean
   over the scales of the centroid's distance relative to ``l``, which peaks on acute
   edges where ``r`` does not): non-maximum suppression
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
from .reference import robust as reference
from .reference.robust import (
    SUPPORT_MIN,
    THIN_CONE_COS,
    SheetNeighbourhoods,
    acute_tips,
    isolated_points,
    line_directions,
    noise_ratios,
    noise_ratios_lists,
    smoothed_ranking,
    supported,
    thin,
)
from .threshold import histogram, otsu_threshold

__all__ = [
    "ACUTE_SCORE",
    "ACUTE_SCORE_MAX",
    "CREASE_ANGLE",
    "ISOLATED_NTH",
    "ISOLATED_REF",
    "ISOLATED_SPREAD",
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
    "THIN_SIDE",
    "THIN_SIDE_NOISY",
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
    "scale_floor",
    "sheet_mask",
    "sheet_parameters",
    "support_exempt",
    "support_free_score",
    "supported",
    "thin",
    "thin_blockers",
    "thin_cone",
    "thin_knn",
    "thin_side",
]

#: Relative projected distance at a point on a straight edge turning by CREASE_ANGLE,
#: with a disc-shaped neighbourhood: ``(2 / pi) * sin(CREASE_ANGLE / 2)`` = 0.1105.
R_MIN = _header.real("R_MIN")
#: ... and by more than about 63 degrees on a noisy cloud (:func:`thin_cone`).
THIN_CONE_COS_NOISY = _header.real("THIN_CONE_COS_NOISY")
#: Thinning's side rule (:func:`thin_side`): a fraction of the comparison list's reach.
THIN_SIDE = _header.real("THIN_SIDE")
THIN_SIDE_NOISY = _header.real("THIN_SIDE_NOISY")
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
#: On a cloud noisier than ``NOISE_QUIET``, the largest scale's threshold is at least
#: this many times the median of its relative distances (:func:`scale_floor`). The noise
#: that lifts a point's ``r`` lifts it at every scale, and where a part has few edges
#: Otsu's split lies below ``R_MIN``: 15 % of the points of a noisy cylinder (a CAD end
#: mill with noise of 25 % of the spacing) passed the floor at every scale. The median
#: is that of the flat points' noise; three times it is about its 95th percentile.
NOISE_FLOOR = _header.real("NOISE_FLOOR")
#: ... but never above this, about the ``r`` of an edge turning by 40 degrees: where the
#: largest scale spans much of a small cloud (1,500 points, k = 110), most points see an
#: edge, the median is no longer the flat points' noise and 3 times it (0.57) dropped
#: 90 % of a noisy box's edge points.
NOISE_FLOOR_MAX = _header.real("NOISE_FLOOR_MAX")
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
#: Isolation's second rule: ``i`` is isolated when its ISOLATED_NTH-th nearest (column
#: ISOLATED_NTH of its kNN list, the point itself in column 0) lies more than
#: ISOLATED_SPREAD times farther than the ISOLATED_REF-th nearest of its ``k_max``-th
#: neighbour. The first rule leaves a stray pair or triple in (each is among the others'
#: nearest); its third neighbour lies 5-20 spacings away, while its ``k_max``-th
#: neighbour lies on the surface, whose 10th nearest is about 2 spacings away (a
#: neighbour farther out than the third: its distance varies less from point to point,
#: which matters on randomly sampled surfaces). Points over the spread (20,000 points;
#: docs/method.md, step 1): none on the clean, noisy, thin-walled and
#: density-gradient parts and on 20,000 uniform random samples of a part; 0-5 per
#: simulated scan; 80 % of stray points 5-20 spacings off a box in clusters of 2-3, 92 %
#: of single ones. The third nearest against the kmax-th neighbour's third, spread 5:
#: 6-13 of the uniform samples, 68 % / 82 % of the strays.
ISOLATED_NTH = _header.integer("ISOLATED_NTH")
ISOLATED_REF = _header.integer("ISOLATED_REF")
ISOLATED_SPREAD = _header.real("ISOLATED_SPREAD")


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


#: Where robust mode's rules on the noise are defined: the native library
#: (``ms_noise_factor``, ``ms_quiet_cloud``, ... in ``native/src/stages.c``), or, in an
#: install without it, the numpy reference's statement of the same rules.
_RULES = _kernels if _kernels.available() else reference


def noise_factor(nu: float) -> float:
    """The scales' growth for the median noise ratio ``nu``:
    ``min(max(1, (nu / NOISE_TOLERATED)**2), NOISE_MAX_FACTOR)`` (``ms_noise_factor``)."""
    return _RULES.noise_factor(nu)


def grown_scales(scales: tuple[int, ...], factor: float) -> tuple[int, ...]:
    """The scales times ``factor``, rounded half up (``ms_grown_scale``)."""
    return tuple(_RULES.grown_scale(k, factor) for k in scales)


def thin_knn(growth: float) -> int:
    """Thinning's comparison list (clouds): ``THIN_KNN`` grown with the scales
    (``growth`` the factor the noise grew them by, 1 when it did not), rounded half
    up: the band of points that noise lifts beside a line widens with the noise
    (``ms_thin_knn``)."""
    return _RULES.thin_knn(growth)


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
    """The neighbours on each point's own sheet, (n, k) bool
    (:func:`meshlab_sharp.reference.robust.sheet_mask`, where the rules are written out),
    with ``parameters`` or, by default, :func:`sheet_parameters`."""
    chosen = sheet_parameters() if parameters is None else parameters
    return reference.sheet_mask(points, indices, normals, chosen)


def _isolated_from_stats(
    points: np.ndarray, stats: _kernels.CloudStats, workers: int = -1
) -> np.ndarray:
    """:func:`isolated_points` from the pass's :class:`~meshlab_sharp._kernels.CloudStats` at
    ``k_max`` (no kNN table): ``i`` is among the k_max nearest of ``j = near[i]`` when
    ``(|p_i - p_j|^2, i)`` does not come after ``j``'s k_max-th neighbour in the
    lists' order (squared distance, then index), and the second rule (ISOLATED_SPREAD).
    (n,) bool, computed in C (:func:`meshlab_sharp._kernels.isolated_from_stats`)."""
    return _kernels.isolated_from_stats(points, stats, ISOLATED_SPREAD, workers)


def local_scale(
    points: np.ndarray, neighbourhood: Neighbourhood, *, backend: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Mean distance from each point to its neighbourhood ``l`` (m,) and its centroid's
    distance ``o`` (m,), as :func:`meshlab_sharp.reference.robust.local_scale` defines
    them, with ``backend`` (default :func:`meshlab_sharp._kernels.default_backend`; both
    give the same bits). ``points`` (m, 3) float64; ``neighbourhood`` CSR lists, each
    point's own index included."""
    if _kernels.resolve(backend) == "compiled":
        return _kernels.local_scale_csr(points, neighbourhood.indptr, neighbourhood.indices)
    return reference.local_scale(points, neighbourhood)


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


def robust_threshold(r: np.ndarray, otsu: bool = True, floor: float = R_MIN) -> float:
    """Otsu's threshold of relative distances on [0, 1], never below ``floor``.

    Parameters
    ----------
    r : (m,) float64
        Relative projected distances in [0, 1] (isolated points left out).
    otsu : bool, default True
        False on a cloud without noise (:func:`otsu_splits`): the floor alone.
    floor : float, default R_MIN
        :func:`scale_floor`.

    Returns
    -------
    float
        ``max(otsu_threshold(r), floor)``, or ``floor`` when not ``otsu`` (then no
        histogram is made); candidates are ``r >= T``.
    """
    return max(otsu_threshold(r), floor) if otsu else floor


def scale_floor(
    counts: np.ndarray, last: bool, mesh: bool, noise: float, backend: str | None = None
) -> float:
    """The floor of a scale's threshold: ``R_MIN``, and on the largest scale (``last``)
    of a cloud whose noise ratio ``noise`` exceeds ``NOISE_QUIET``, at least
    ``NOISE_FLOOR`` times the median of its relative distances (at most
    ``NOISE_FLOOR_MAX``), read from their histogram ``counts`` (B,) int
    (``ms_noise_floor``; the numpy reference with ``backend="numpy"``). Measured on the
    CAD parts with noise of 25 % of the spacing (50,000 points): the end mill 0.258 ->
    0.942, filleted parts 4.19 / 4.43 % flagged -> 0.66 / 2.78 %; parts with many edges
    keep Otsu's split, which lies higher."""
    rules = reference if backend == "numpy" else _RULES
    return rules.scale_floor(counts, last, mesh, noise)


def quiet_cloud(mesh: bool, noise: float) -> bool:
    """Whether the input is a cloud without noise: not a mesh, and its noise ratio
    ``noise`` (the lower median of :func:`noise_ratios`, as :func:`noise_scale_factor`
    takes it) not above ``NOISE_QUIET``. The one test behind every rule kept for such
    clouds: the floor alone (:func:`otsu_splits`), :func:`support_exempt`,
    :func:`acute_tests`, :func:`thin_blockers` and the cone of :func:`thin_cone`
    (``ms_quiet_cloud``)."""
    return _RULES.quiet_cloud(mesh, noise)


def otsu_splits(mesh: bool, noise: float) -> bool:
    """Whether Otsu's split raises the threshold above ``R_MIN``: on meshes, and on
    clouds whose noise ratio ``noise`` (the lower median of :func:`noise_ratios`, as
    :func:`noise_scale_factor` takes it) exceeds ``NOISE_QUIET``. On a cloud without
    noise the floor alone (measured: thin walls 1 / 2 / 3
    spacings F1 0.736 / 0.675 / 0.896 -> 0.744 / 0.711 / 0.913, no condition lower)
    (``ms_otsu_splits``)."""
    return _RULES.otsu_splits(mesh, noise)


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
    0.78 -> 0.83) (``ms_thin_cone``)."""
    return _RULES.thin_cone(mesh, noise)


def thin_side(mesh: bool, noise: float) -> float:
    """:func:`thin`'s ``side``: ``THIN_SIDE_NOISY`` on a cloud whose noise ratio ``noise``
    (as :func:`otsu_splits` takes it) exceeds ``NOISE_QUIET``, ``THIN_SIDE`` on meshes and
    quiet clouds. Noise scatters the band of candidates along an edge, and the cone keeps a
    second point of it 1-1.5 spacings off the edge wherever its offset to the first runs
    along the line. Smaller fractions thin more: at 0.45 the evaluation's clean clouds
    gained 0.015 F1 (CAD parts, 50,000 points: 0.011), but the rims of walls 2 spacings
    thick (about 1.3 spacings apart in their bands) thinned each other (F1 -0.020), and
    on a noisy cloud below 0.65 a line thins to gaps (``ms_thin_side``)."""
    return _RULES.thin_side(mesh, noise)


def ranking_smoothed(mesh: bool, noise: float) -> bool:
    """Whether thinning ranks by :func:`smoothed_ranking`: on a cloud whose noise ratio
    ``noise`` (as :func:`otsu_splits` takes it) grew the scales to the cap
    (``noise_factor(noise) == NOISE_MAX_FACTOR``). Beyond it the larger scales no longer
    dilute the noise of the score, and single points lifted 1-2 spacings beside a line
    outrank the line's own (measured: noise 50 % F1 0.752 ->
    0.813, thickness 0.72 -> 0.78) (``ms_ranking_smoothed``)."""
    return _RULES.ranking_smoothed(mesh, noise)


def support_free_score(mesh: bool, noise: float) -> float | None:
    """The score below which :func:`supported` keeps a point without support:
    ``SUPPORT_FREE_SCORE`` on a cloud whose noise ratio ``noise`` (as :func:`otsu_splits`
    takes it) is at most ``NOISE_QUIET``; None (no such score) on meshes and noisier
    clouds (``ms_support_free_score``)."""
    return _RULES.support_free_score(mesh, noise)


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
    return _RULES.stage_acute_tests(score, mask, mesh, noise)


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
    noise : float, default 0.0
        The cloud's noise ratio, read by :func:`scale_floor` (0 on a mesh).
    backend : {"compiled", "numpy"}, optional
        :func:`local_scale`'s; default :func:`meshlab_sharp._kernels.default_backend`.
    """

    points: np.ndarray
    lists: object
    n_scales: int
    sheet: _kernels.SheetParameters | None = None
    otsu: bool = True
    noise: float = 0.0
    backend: str | None = None

    def __post_init__(self) -> None:
        self.score = np.zeros(len(self.points))

    def __call__(self, i: int, scale: int, pdis: np.ndarray) -> tuple[np.ndarray, float]:
        """Relative distances (m,) and threshold of the i-th scale, ``scale``."""
        lists = self.lists(scale)  # type: ignore[operator]
        ell, offset = local_scale(self.points, lists, backend=self.backend)
        r = relative_distances(np.asarray(pdis, np.float64), ell)
        self.score += relative_distances(offset, ell) / self.n_scales
        return r, robust_threshold(r, self.otsu, self.floor(i, r))

    def floor(self, i: int, r: np.ndarray) -> float:
        """:func:`scale_floor` of the i-th scale's relative distances ``r`` (m,)."""
        last = i == self.n_scales - 1
        counts = histogram(r) if last else None  # read on the largest scale only
        return scale_floor(counts, last, False, self.noise, self.backend)

    def from_pass(self, score: np.ndarray, i: int, r: np.ndarray) -> tuple[bool, float]:
        """Take the final ``score`` (m,) of the compiled pass (over a cloud or a mesh's
        rings), which computed it and every scale's relative distances with this rule's
        arithmetic (:class:`meshlab_sharp._kernels.ScalePass`); returns how
        :func:`robust_threshold` thresholds the i-th scale's, ``r`` (m,), ``(otsu,
        floor)``, for :func:`meshlab_sharp._kernels.scale_vote` (the same threshold)."""
        self.score = score
        return self.otsu, self.floor(i, r)


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
        #: The neighbourhoods' backend, which every step of the set-up and of
        #: :meth:`finish` runs with.
        self.backend = neighbourhoods.backend
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
                isolated = isolated_points(
                    points,
                    neighbourhoods.indices,
                    nth=ISOLATED_NTH,
                    ref=ISOLATED_REF,
                    spread=ISOLATED_SPREAD,
                )
            if isolated.any():
                self.fused = None  # freed before the pass over the points kept
                self.keep = np.flatnonzero(~isolated)
                self.points = np.ascontiguousarray(points[self.keep])
                self.neighbourhoods = build_neighbourhoods(
                    self.points, None, self.scales, workers=workers, backend=self.backend
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
                    self.points, None, self.scales, workers=workers, backend=self.backend
                )
                self.fused = None
                self.scale_neighbourhoods = self.neighbourhoods if compiled else self._sheets()
        if faces is None:
            self.sharp_edges = None
        elif sharp_edges is None:
            self.sharp_edges = sharp_vertices(points, faces, backend=self.backend)[0]
        else:
            self.sharp_edges = np.asarray(sharp_edges, bool)
        otsu = otsu_splits(faces is not None, self.noise)
        # the lists' own method, not one of self: a rule that referred back to this
        # setup made a reference cycle, so the arrays of every call (the kd-tree, the
        # pass's outputs: about 55 bytes a point) stayed until the garbage collector ran
        lists = self.scale_neighbourhoods.at
        self.rule = RelativeRule(
            self.points, lists, len(self.scales), sheet, otsu, self.noise, backend=self.backend
        )

    def _sheets(self) -> SheetNeighbourhoods:
        """:class:`SheetNeighbourhoods` of ``neighbourhoods`` (numpy kNN lists)."""
        assert isinstance(self.neighbourhoods, KnnNeighbourhoods)
        return SheetNeighbourhoods(
            self.points, self.neighbourhoods, self.weighting, sheet_parameters()
        )

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
            isolated=(ISOLATED_NTH, ISOLATED_REF),
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
            self.points,
            mask,
            rank,
            e,
            compare,
            cone_cos=thin_cone(mesh, self.noise),
            side=thin_side(mesh, self.noise),
            between=block,
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
            thin_side=thin_side(mesh, self.noise),
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
