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
3b. **Acute tips** (``ms_acute_tips``): on a cloud thresholded at the floor alone, a
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
   to the last of the list, whatever the angle: ``ms_robust_plan``), ranks higher (mean
   over the scales of the centroid's distance relative to ``l``, which peaks on acute
   edges where ``r`` does not): non-maximum suppression
   across the line, so lines stay one point wide; comparing only within about 1.9
   spacings keeps most of two parallel lines (the rims of a thin wall) apart, and on
   a cloud thresholded at the floor alone a point that is not a candidate, or ranks
   below the point (a valley of the ranking), lying between the two (the middle of a
   wall's end face) keeps both (``ms_robust_plan``). Where the noise grew the scales
   to the cap, the ranking is the mean over the ``THIN_KNN`` nearest (points lifted by
   the noise beside a line do not outrank it). On a cloud, a point still kept is
   then dropped when it lies more than ``LINE_OFFSET`` (0.6) local units (the mean
   distance to its ``LINE_UNIT`` nearest) beside the line through the higher-ranked
   points kept among its comparison list, those lying on one line (their mean squared
   distance to it below ``LINE_SPREAD`` units squared): the second row of the band,
   which its own tilted direction keeps out of the cone; blocked as thinning is, and
   not where the ranking is smoothed (``ms_line_test``).
6. **Meshes: the mesh's own sharp edges** (:mod:`meshlab_sharp.creases`): vertices on
   an edge whose two faces turn by more than ``CREASE_ANGLE`` (more on a noisy mesh)
   are features too. On a CAD tessellation they are all of them. A mesh's rings (its
   neighbourhoods at every step) are listed breadth-first
   (:class:`meshlab_sharp.neighbourhoods.RingNeighbourhoods`), the order in which the
   sums over them are taken.
"""

from __future__ import annotations

from . import _header, _kernels
from .creases import CREASE_ANGLE
from .reference.robust import (
    SUPPORT_MIN,
    THIN_CONE_COS,
    noise_ratios,
)

__all__ = [
    "ACUTE_SCORE",
    "ACUTE_SCORE_MAX",
    "CREASE_ANGLE",
    "ISOLATED_NTH",
    "ISOLATED_REF",
    "ISOLATED_SPREAD",
    "LINE_MIN",
    "LINE_OFFSET",
    "LINE_REACH",
    "LINE_SPREAD",
    "LINE_UNIT",
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
    "line_rules",
    "noise_ratios",
    "sheet_parameters",
]

#: Relative projected distance at a point on a straight edge turning by CREASE_ANGLE,
#: with a disc-shaped neighbourhood: ``(2 / pi) * sin(CREASE_ANGLE / 2)`` = 0.1105.
R_MIN = _header.real("R_MIN")
#: ... and by more than about 63 degrees on a noisy cloud (``ms_robust_plan``).
THIN_CONE_COS_NOISY = _header.real("THIN_CONE_COS_NOISY")
#: Thinning's side rule, a fraction of the comparison list's reach: on meshes and quiet
#: clouds, and on noisy clouds (``ms_robust_plan``).
THIN_SIDE = _header.real("THIN_SIDE")
THIN_SIDE_NOISY = _header.real("THIN_SIDE_NOISY")
#: Thinning's line test (``ms_line_test``): the offset beside the line of the
#: higher-ranked features that drops a cloud's feature point, the spread of those
#: features that still reads as one line, both in local units (the mean distance to
#: the LINE_UNIT nearest), and how many of them make a line.
LINE_OFFSET = _header.real("LINE_OFFSET")
LINE_SPREAD = _header.real("LINE_SPREAD")
LINE_MIN = _header.integer("LINE_MIN")
LINE_UNIT = _header.integer("LINE_UNIT")
#: ... and how far ahead and behind the point's foot some of them lie, in units.
LINE_REACH = _header.real("LINE_REACH")
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
#: ... except, on a cloud thresholded at the floor alone (``ms_robust_plan``), the
#: candidates whose score (``RelativeRule``'s, the mean ``o / l``) is below
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
#: too (``ms_acute_tips``): the tip of an acute edge, where the PCA normal turns
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
#: thresholded at the floor alone (``ms_robust_plan``). Measured on the evaluation's
#: clouds (20,000 points): 0-0.003 clean, 0-0.01 thin walls, 0.004-0.018 smooth
#: controls, 0.09-0.096 with normal noise of 10 % of the spacing, 0.068-0.115 on the
#: simulated scans; a third of ``NOISE_TOLERATED`` lies between.
NOISE_QUIET = _header.real("NOISE_QUIET")
#: On a cloud noisier than ``NOISE_QUIET``, the largest scale's threshold is at least
#: this many times the median of its relative distances (``ms_scale_floor``). The noise
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


def line_rules() -> _kernels.LineRules:
    """Thinning's line test's rules as the module holds them now: ``LINE_OFFSET``,
    ``LINE_SPREAD``, ``LINE_REACH``, ``LINE_MIN`` and ``LINE_UNIT``."""
    return _kernels.LineRules(LINE_OFFSET, LINE_SPREAD, LINE_REACH, LINE_MIN, LINE_UNIT)
