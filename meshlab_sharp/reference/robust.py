"""Robust mode's per-point measures and finishing steps, the numpy reference: isolated
points, the noise ratio, the sheet filter, the local scale, the line directions,
support, thinning, acute tips and the smoothed ranking. The compiled kernels
(:mod:`meshlab_sharp._kernels`: the cloud pass's statistics, ``local_scale_csr``, ``acute_tips`` and
``support_and_thin``) give the same bits; :mod:`meshlab_sharp.robust` runs one or the
other, and the out-of-core tiles (:mod:`meshlab_sharp.tiles.steps`) run these per tile.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from .. import _header, _kernels
from .._kernels import RobustPlan
from .neighbourhoods import Neighbourhood, squared_distances
from .normals import Weighting, largest_eigenvectors, smallest_eigenvectors
from .projected_distance import projected_distances

#: Thinning compares a point with candidate neighbours whose offset makes more than
#: 60 degrees with the line direction: ``|d . e| < THIN_CONE_COS * |d|``.
THIN_CONE_COS = _header.real("THIN_CONE_COS")
#: Support: a feature needs at least SUPPORT_MIN other features along its line among
#: its support list (:data:`meshlab_sharp.robust.SUPPORT_KNN` nearest, or a mesh's
#: ``THIN_RING``-ring).
SUPPORT_MIN = _header.integer("SUPPORT_MIN")
#: Isolation's second rule (:func:`isolated_points`; meshlab_sharp.robust says why).
ISOLATED_NTH = _header.integer("ISOLATED_NTH")
ISOLATED_REF = _header.integer("ISOLATED_REF")
ISOLATED_SPREAD = _header.real("ISOLATED_SPREAD")
#: Robust mode's rules on the cloud's noise ratio (meshlab_sharp.robust says why).
NOISE_TOLERATED = _header.real("NOISE_TOLERATED")
NOISE_MAX_FACTOR = _header.real("NOISE_MAX_FACTOR")
NOISE_QUIET = _header.real("NOISE_QUIET")
#: The threshold floor (meshlab_sharp.robust says why).
R_MIN = _header.real("R_MIN")
THIN_CONE_COS_NOISY = _header.real("THIN_CONE_COS_NOISY")
THIN_KNN = _header.integer("THIN_KNN")
THIN_RING = _header.integer("THIN_RING")
SUPPORT_KNN = _header.integer("SUPPORT_KNN")
#: Thinning's side rule (:func:`thin`), a fraction of the comparison list's reach: on
#: meshes and quiet clouds, and on noisy clouds (:func:`thin_side`).
THIN_SIDE = _header.real("THIN_SIDE")
THIN_SIDE_NOISY = _header.real("THIN_SIDE_NOISY")
SUPPORT_FREE_SCORE = _header.real("SUPPORT_FREE_SCORE")
#: Thinning's line test (:func:`line_test`; meshlab_sharp.robust says why).
LINE_OFFSET = _header.real("LINE_OFFSET")
LINE_SPREAD = _header.real("LINE_SPREAD")
LINE_MIN = _header.integer("LINE_MIN")
LINE_UNIT = _header.integer("LINE_UNIT")
LINE_REACH = _header.real("LINE_REACH")
ACUTE_SCORE = _header.real("ACUTE_SCORE")
ACUTE_SCORE_MAX = _header.real("ACUTE_SCORE_MAX")
#: Fewest feature points in one thread's part of the line directions (below it the
#: threads' start costs more than they save).
PART_MIN = 2048


def isolated_points(
    points: np.ndarray,
    indices: np.ndarray,
    *,
    nth: int = ISOLATED_NTH,
    ref: int = ISOLATED_REF,
    spread: float = ISOLATED_SPREAD,
) -> np.ndarray:
    """Points that are not among the k nearest neighbours of their nearest neighbour, or
    whose first few neighbours lie far beyond the spacing of the surface around them (a
    stray pair or triple off the surface).

    Parameters
    ----------
    points : (n, 3) float64
    indices : (n, k) int
        k-nearest-neighbour indices of the distinct ``points``, each row sorted by
        (squared distance, index) with the point itself first (column 0) and its nearest
        neighbour in column 1. ``k >= 2``.
    nth, ref : int
        Columns of the two distances compared (capped at ``k - 1``).
    spread : float
        How many times farther than the surface's spacing the ``nth`` neighbour may lie.

    Returns
    -------
    (n,) bool
        True for isolated points (outliers): ``i`` does not occur in
        ``indices[indices[i, 1]]``, or ``d_nth_i > spread**2 * d_ref_j`` with ``d_nth``
        and ``d_ref`` the squared distances to the neighbours in columns
        ``min(nth, k - 1)`` and ``min(ref, k - 1)``, and ``j = indices[i, k - 1]``.
    """
    idx = np.asarray(indices)
    n = len(idx)
    if n == 0 or idx.shape[1] < 2:
        return np.zeros(n, bool)
    nearest = idx[:, 1]
    lone = ~(idx[nearest] == np.arange(n)[:, None]).any(axis=1)
    p = np.asarray(points, dtype=np.float64)
    last = idx.shape[1] - 1
    d_nth = squared_distances(p, p[idx[:, min(nth, last)]])
    d_ref = squared_distances(p, p[idx[:, min(ref, last)]])
    return lone | (d_nth > spread * spread * d_ref[idx[:, -1]])


def noise_floor(counts: np.ndarray) -> float:
    """Robust mode's noise floor of a histogram's counts (``threshold.BINS``,) int:
    ``min(NOISE_FLOOR * (b + 1) / BINS, NOISE_FLOOR_MAX)``, ``b`` the bin of the lower
    median (the first bin whose cumulative count exceeds ``(total - 1) // 2``); 0.0 when
    every count is 0 (``ms_noise_floor``, :func:`meshlab_sharp.reference.detect.scale_floor`)."""
    counts = np.asarray(counts, np.int64)
    total = int(counts.sum())
    if total == 0:
        return 0.0
    rank = (total - 1) // 2  # the lower median's, from 0
    b = min(int(np.searchsorted(np.cumsum(counts), rank, side="right")), len(counts) - 1)
    floor = _header.real("NOISE_FLOOR") * float(b + 1) / float(len(counts))
    return min(floor, _header.real("NOISE_FLOOR_MAX"))


def noise_ratios(points: np.ndarray, indices: np.ndarray, k: int) -> np.ndarray:
    """``|d . n_i| / |d|`` of every point, ``d = p_{N(i)[1]} - p_i`` (the nearest
    neighbour's offset across the plane of the ``k`` nearest, relative to its distance;
    0 when ``d = 0``). ``points`` (n, 3), ``indices`` (n, >= k) as
    :func:`meshlab_sharp.reference.detect.noise_scale_factor`; returns (n,) float64."""
    idx = np.asarray(indices)[:, :k]
    return _plane_ratios(points[idx] - points[:, None, :])


def _plane_ratios(q: np.ndarray) -> np.ndarray:
    """:func:`noise_ratios` from the offsets q (n, k, 3) of each point's list."""
    c = q.mean(axis=1)
    r = q - c[:, None, :]
    cov = np.einsum("nka,nkb->nab", r, r)
    normal = smallest_eigenvectors(cov)
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


def local_scale(points: np.ndarray, neighbourhood: Neighbourhood) -> tuple[np.ndarray, np.ndarray]:
    """Mean distance from each point to its neighbourhood, and its centroid's distance.
    The sums are numpy's ``add.reduceat`` (the first term plus the pairwise sum of the
    others), which the compiled :func:`meshlab_sharp._kernels.local_scale_csr`
    reproduces.

    Parameters
    ----------
    points : (m, 3) float64
    neighbourhood : Neighbourhood
        CSR lists (``indptr`` (m + 1,), ``indices``); each point's own index included.

    Returns
    -------
    scale : (m,) float64
        ``l_i = (1 / |N(i)|) * sum_{j in N(i)} |p_j - p_i|`` (0 for an empty list).
    offset : (m,) float64
        ``o_i = |(1 / |N(i)|) * sum_{j in N(i)} (p_j - p_i)|``, the distance from
        ``p_i`` to the centroid (0 for an empty list); ``o_i <= l_i``.
    """
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
        The points tested (:func:`meshlab_sharp.reference.detect.acute_tests`), increasing.
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
    return _fitted_lines(q, owner, len(cand))[3]


def _fitted_lines(
    q: np.ndarray, owner: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The line through each of ``n`` groups of offsets ``q`` (k, 3) (group ``owner``,
    increasing): the groups' sizes (n,), CSR pointers (n + 1,), means ``qbar`` (n, 3) and
    the unit eigenvectors ``e`` (n, 3) of the largest eigenvalues of ``C = sum q q^T -
    |Q| qbar qbar^T`` (numpy's sums in add.reduceat's order)."""
    sizes = np.bincount(owner, minlength=n)
    ptr = np.concatenate([[0], np.cumsum(sizes)])
    qsum = _segment_sums(q, ptr)
    outer = _segment_sums(q[:, :, None] * q[:, None, :], ptr)
    safe = np.maximum(sizes.astype(np.float64), 1.0)[:, None]
    qbar = qsum / safe
    cov = outer - safe[:, :, None] * qbar[:, :, None] * qbar[:, None, :]
    return sizes, ptr, qbar, largest_eigenvectors(cov)


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


def _beside(
    points: np.ndarray,
    ci: np.ndarray,
    nb: np.ndarray,
    e: np.ndarray,
    lists: Neighbourhood,
    side: float,
) -> np.ndarray:
    """Whether ``d = p_j - p_i`` of each pair (``i = ci``, ``j = nb``) lies to the side of
    the line through ``i`` by more than ``side`` times the reach of ``lists[i]`` (the
    distance to its farthest member ``l``): ``|d|^2 - (d . e_i)^2 > (side * side) *
    |p_l - p_i|^2``, each sum over x, y, z in that order (``ms_thin``'s)."""
    indptr = np.asarray(lists.indptr, np.int64)
    members = np.asarray(lists.indices, np.int64)
    owner = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    r = points[members] - points[owner]
    far2 = np.zeros(len(indptr) - 1)
    np.maximum.at(far2, owner, r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1] + r[:, 2] * r[:, 2])
    reach2 = far2[ci]
    d = points[nb] - points[ci]
    along = d[:, 0] * e[ci, 0] + d[:, 1] * e[ci, 1] + d[:, 2] * e[ci, 2]
    d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    with np.errstate(invalid="ignore"):  # side = inf (no side rule) times reach 0: NaN, False
        return d2 - along * along > side * side * reach2


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
        Features kept whatever their support
        (:func:`meshlab_sharp.reference.detect.support_exempt`); default none.

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
    side: float = THIN_SIDE,
    between: np.ndarray | None = None,
) -> np.ndarray:
    """Non-maximum suppression of feature points across the feature line.

    A feature point ``i`` is dropped when some feature point ``j != i`` of
    ``compare[i]`` with ``d = p_j - p_i`` lies across the line through ``i``
    (``|d . e_i| < cone_cos * |d|``) or beside it (:func:`_beside`: farther from the line
    than ``side`` times the distance to the list's farthest member) and ``score[j] >
    score[i]``, unless (with
    ``between``) a point ``m`` of ``compare[i]`` with ``between[m]`` or ``score[m] <
    score[i]`` (a valley between two ridges) lies between them: ``(p_m - p_i) . (p_m -
    p_j) < 0``. Every decision uses the mask before thinning.

    Parameters
    ----------
    points : (m, 3) float64
    mask : (m,) bool
        Feature points before thinning.
    score : (m,) float64
        Ranking (:class:`meshlab_sharp.reference.detect.RelativeRule`'s ``score``).
    e : (m, 3) float64
        Line directions (:func:`line_directions`).
    compare : Neighbourhood
        CSR lists for the comparison (:mod:`meshlab_sharp.robust`'s ``THIN_KNN``
        nearest or ``THIN_RING``-ring).
    cone_cos : float, default THIN_CONE_COS (0.5)
    side : float, default THIN_SIDE (0.7)
        The plan's ``thin_side`` (:func:`thin_side`).
    between : (m,) bool, optional
        The points that part two features whatever their score
        (:func:`meshlab_sharp.reference.detect.thin_blockers`); default none, and then no blocking
        at all.

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
    beaten = (across | _beside(points, ci, nb, e, compare, side)) & (score[nb] > score[ci])
    if between is not None:
        pair = np.flatnonzero(beaten)
        beaten[pair[_parted(points, compare, ci[pair], points[nb[pair]], score, between)]] = False
    suppressed = np.bincount(owner[beaten], minlength=len(cand)) > 0
    out = mask.copy()
    out[cand[suppressed]] = False
    return out


def _parted(
    points: np.ndarray,
    compare: Neighbourhood,
    i: np.ndarray,
    target: np.ndarray,
    rank: np.ndarray,
    between: np.ndarray,
) -> np.ndarray:
    """Thinning's blocking (the library's ``parted``): for each point ``i`` (k,) and
    point ``target`` (k, 3), whether a point ``m`` of ``compare[i]`` with ``between[m]``
    or ``rank[m] < rank[i]`` lies between them, ``(p_m - p_i) . (p_m - target) < 0``:
    (k,) bool."""
    at, m = _rows(compare, i)
    use = np.asarray(between, bool)[m] | (rank[m] < rank[i[at]])
    at, m = at[use], m[use]
    a = points[m] - points[i[at]]
    b = points[m] - target[at]
    dot = a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]
    parted = np.zeros(len(i), bool)
    parted[at[dot < 0]] = True
    return parted


def line_test(
    points: np.ndarray,
    mask: np.ndarray,
    rank: np.ndarray,
    compare: Neighbourhood,
    *,
    offset: float | None = None,
    spread: float | None = None,
    between: np.ndarray | None = None,
) -> np.ndarray:
    """Thinning's line test: feature points beside the line of their stronger neighbours.

    For a feature point ``i``, the features ``j != i`` of ``compare[i]`` with ``rank[j] >
    rank[i]`` (``q_j = p_j - p_i``, list order; at least ``LINE_MIN``) give ``qbar`` and
    the line direction ``e`` as :func:`line_directions` forms them. ``i`` is dropped when
    the mean of ``|r_j|^2 - (r_j . e)^2`` (``r_j = q_j - qbar``) is below ``(spread *
    u)^2`` (the features lie on one line) and ``g = qbar - (qbar . e) e``, the offset from
    ``p_i`` to its foot on the line, has ``|g|^2 > (offset * u)^2``; ``u`` is the mean of
    ``|q|`` over the ``min(LINE_UNIT, len - 1)`` members of ``compare[i]`` after ``i``
    (its first), added in order to 0.0; and the foot ``p_i + g`` lies among the features'
    along the line (some ``r_j . e`` above ``-(qbar . e) + LINE_REACH * u``, some below
    ``-(qbar . e) - LINE_REACH * u``: nothing is extrapolated past a line's end, and the
    bent row of a corner's other edges makes no line). With ``between``, a point ``m`` of
    ``compare[i]`` with ``between[m]`` or ``rank[m] < rank[i]`` and ``(p_m - p_i) . (p_m -
    (p_i + g)) < 0`` keeps ``i`` (as :func:`thin`'s blocking). Every decision uses
    ``mask``.

    Parameters
    ----------
    points : (m, 3) float64
    mask : (m,) bool
        Feature points after :func:`thin`.
    rank : (m,) float64
        Thinning's ranking.
    compare : Neighbourhood
        CSR lists (each point first in its own), thinning's.
    offset, spread : float, optional
        Default ``LINE_OFFSET``, ``LINE_SPREAD`` (read at the call).
    between : (m,) bool, optional
        Thinning's blockers; default none.

    Returns
    -------
    (m,) bool
        The tested mask (a subset of ``mask``).
    """
    mask = np.asarray(mask, bool)
    cand = np.flatnonzero(mask)
    out = mask.copy()
    if len(cand) == 0:
        return out
    owner, nb = _rows(compare, cand)
    ci = cand[owner]
    use = mask[nb] & (nb != ci) & (rank[nb] > rank[ci])
    o, j = owner[use], nb[use]
    q = points[j] - points[cand[o]]
    sizes, ptr, qbar, e = _fitted_lines(q, o, len(cand))
    r = q - qbar[o]
    along = r[:, 0] * e[o, 0] + r[:, 1] * e[o, 1] + r[:, 2] * e[o, 2]
    w = r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1] + r[:, 2] * r[:, 2] - along * along
    scatter = _segment_sums(w, ptr) / np.maximum(sizes, 1)
    u = _list_unit(points, compare, cand)
    # i's foot lies among theirs along the line, some reach ahead and some behind
    at = qbar[:, 0] * e[:, 0] + qbar[:, 1] * e[:, 1] + qbar[:, 2] * e[:, 2]
    reach = LINE_REACH * u
    ahead = np.zeros(len(cand), bool)
    behind = np.zeros(len(cand), bool)
    np.logical_or.at(ahead, o, along > -at[o] + reach[o])
    np.logical_or.at(behind, o, along < -at[o] - reach[o])
    g = qbar - at[:, None] * e
    off2 = g[:, 0] * g[:, 0] + g[:, 1] * g[:, 1] + g[:, 2] * g[:, 2]
    far = (LINE_OFFSET if offset is None else offset) * u
    thin_ = (LINE_SPREAD if spread is None else spread) * u
    drop = (sizes >= LINE_MIN) & (off2 > far * far) & (scatter < thin_ * thin_) & ahead & behind
    if between is not None and drop.any():  # thinning's blocking, towards the foot p_i + g
        slot = np.flatnonzero(drop)
        i = cand[slot]
        drop[slot[_parted(points, compare, i, points[i] + g[slot], rank, between)]] = False
    out[cand[drop]] = False
    return out


def _list_unit(points: np.ndarray, lists: Neighbourhood, rows: np.ndarray) -> np.ndarray:
    """The local unit of each of ``rows`` (c,): the mean distance from the point to the
    next ``min(LINE_UNIT, len - 1)`` members of its list (itself first), added in order
    to 0.0 (0 for a list of one): (c,) float64."""
    indptr = np.asarray(lists.indptr, np.int64)
    indices = np.asarray(lists.indices, np.int64)
    start = indptr[rows]
    take = np.clip(indptr[rows + 1] - start - 1, 0, LINE_UNIT)
    acc = np.zeros(len(rows))
    for t in range(1, LINE_UNIT + 1):
        has = take >= t
        d = points[indices[start[has] + t]] - points[rows[has]]
        acc[has] += np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    return np.where(take > 0, acc / np.maximum(take, 1), 0.0)


#: Rows per block of :func:`sheet_mask` (bounds its (rows, k, 3) temporaries).
_SHEET_BLOCK = 32768


def sheet_mask(
    points: np.ndarray,
    indices: np.ndarray,
    normals: np.ndarray,
    parameters: _kernels.SheetParameters,
) -> np.ndarray:
    """The neighbours on each point's own sheet.

    Parameters
    ----------
    points : (n, 3) float64
    indices : (n, k) int
        kNN lists sorted by distance, the point itself first.
    normals : (n, 3) float64
        Unit normal of each list (the weighted PCA normal of its ``k`` points).
    parameters : (gap, minimum, own, column, column_gap, far_span, trim, trim_cos)
        :func:`meshlab_sharp.robust.sheet_parameters` (0.4, 6, 0.5, 1.1, 0.75, 1.25,
        1.3, 0.985) in robust mode.

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
    gap, minimum, own, column, column_gap, far_span, trim, trim_cos = parameters

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
            normal = smallest_eigenvectors(np.einsum("rka,rkb->rab", r, r))
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


class KnnLists(Protocol):
    """k-nearest-neighbour lists at several scales, as
    :class:`meshlab_sharp.neighbourhoods.KnnNeighbourhoods` holds them."""

    k_max: int
    workers: int

    @property
    def indices(self) -> np.ndarray:
        """(n, k_max) neighbour indices, rows sorted by (squared distance, index)."""

    def at(self, k: int) -> Neighbourhood:
        """The k-nearest neighbourhoods, ``k <= k_max``."""


class SheetNeighbourhoods:
    """kNN neighbourhoods less the neighbours on other sheets (:func:`sheet_mask`).

    Parameters
    ----------
    points : (n, 3) float64
    base : KnnLists
        The lists at the largest scale ``k_max``
        (:class:`meshlab_sharp.neighbourhoods.KnnNeighbourhoods`).
    weighting : {"gaussian", "none"}
        Weighting of the PCA normal of each ``k_max``-list (paper mode's normal at the
        largest scale).
    parameters : (gap, minimum, own, column, column_gap, far_span, trim, trim_cos)
        :func:`sheet_mask`'s.

    Attributes
    ----------
    keep : (n, k_max) bool
        :func:`sheet_mask` of ``base``'s lists.
    """

    def __init__(
        self,
        points: np.ndarray,
        base: KnnLists,
        weighting: Weighting,
        parameters: _kernels.SheetParameters,
    ) -> None:
        self.base = base
        self.k_max = base.k_max
        self.tree = None
        self.workers = base.workers
        self._idx = np.asarray(base.indices, np.int64)
        _, normals = projected_distances(points, base.at(base.k_max), weighting=weighting)
        self.keep = sheet_mask(points, self._idx, normals, parameters)

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


# The rules on the noise ratio, as the native library states them (native/src/stages.c,
# ms_noise_factor ... ms_stage_acute_tests): meshlab_sharp.robust runs these where the
# library is not built.


def noise_factor(noise: float) -> float:
    """``min(max(1, (noise / NOISE_TOLERATED)**2), NOISE_MAX_FACTOR)``."""
    ratio = noise / NOISE_TOLERATED
    return min(max(1.0, ratio * ratio), NOISE_MAX_FACTOR)


def grown_scale(k: int, factor: float) -> int:
    """``k * factor`` rounded half up."""
    return math.floor(k * factor + 0.5)


def thin_knn(growth: float) -> int:
    """``THIN_KNN`` grown by ``growth``, rounded half up."""
    return grown_scale(THIN_KNN, growth)


def quiet_cloud(mesh: bool, noise: float) -> bool:
    """A cloud whose noise ratio is at most ``NOISE_QUIET``."""
    return not (mesh or noise > NOISE_QUIET)


def otsu_splits(mesh: bool, noise: float) -> bool:
    """Not :func:`quiet_cloud`."""
    return not quiet_cloud(mesh, noise)


def scale_floor(counts: np.ndarray | None, last: bool, mesh: bool, noise: float) -> float:
    """``R_MIN``; on the largest scale (``last``) of a cloud that is not quiet, at least
    :func:`noise_floor` of that scale's histogram ``counts`` (B,) int."""
    if not last or mesh or quiet_cloud(mesh, noise):
        return R_MIN
    return max(R_MIN, noise_floor(counts))


def thin_cone(mesh: bool, noise: float) -> float:
    """``THIN_CONE_COS_NOISY`` on a noisy cloud, else ``THIN_CONE_COS``."""
    return THIN_CONE_COS if mesh or quiet_cloud(mesh, noise) else THIN_CONE_COS_NOISY


def thin_side(mesh: bool, noise: float) -> float:
    """``THIN_SIDE_NOISY`` on a noisy cloud, else ``THIN_SIDE``."""
    return THIN_SIDE if mesh or quiet_cloud(mesh, noise) else THIN_SIDE_NOISY


def ranking_smoothed(mesh: bool, noise: float) -> bool:
    """A cloud whose noise grew the scales to the cap."""
    return not mesh and noise_factor(noise) == NOISE_MAX_FACTOR


def support_free_score(mesh: bool, noise: float) -> float | None:
    """``SUPPORT_FREE_SCORE`` on a quiet cloud, else None."""
    return SUPPORT_FREE_SCORE if quiet_cloud(mesh, noise) else None


def stage_acute_tests(score: np.ndarray, mask: np.ndarray, mesh: bool, noise: float) -> np.ndarray:
    """On a quiet cloud the points not in ``mask`` whose ``score`` lies in
    ``[ACUTE_SCORE, ACUTE_SCORE_MAX)``, (t,) int64 increasing; none otherwise."""
    if not quiet_cloud(mesh, noise):
        return np.zeros(0, np.int64)
    score = np.asarray(score, np.float64)
    test = ~np.asarray(mask, bool) & (score >= ACUTE_SCORE) & (score < ACUTE_SCORE_MAX)
    return np.flatnonzero(test)


def stage_curved(
    first: np.ndarray, last: np.ndarray, s_first: int, s_last: int, mask: np.ndarray
) -> np.ndarray:
    """``mask`` (m,) bool less the points on a curved surface: those whose relative
    distance grows from ``first`` (m,), at the smallest ring ``s_first``, to ``last``
    (m,), at the largest ``s_last``, at least as the square root of the ring,
    ``first * first * s_last < last * last * s_first``. A crease is a wedge, the same
    at every size, so its relative distance does not grow with the ring; a smooth
    surface's grows in proportion to the ring's radius (the sagitta over the radius),
    which on a mesh is in proportion to the ring. The square root is the geometric
    middle of the two. Returns (m,) bool."""
    first = np.asarray(first, np.float64)
    last = np.asarray(last, np.float64)
    curved = first * first * float(s_last) < last * last * float(s_first)
    return np.asarray(mask, bool) & ~curved


def robust_plan(noise: float, n_kept: int, scales: Sequence[int], mesh: bool) -> RobustPlan:
    """Robust mode's decisions once the first pass has measured the noise ratio ``noise``
    of an input (``mesh`` or a cloud of ``n_kept`` points, isolated ones left out) at the
    increasing ``scales``, as the rules above take them (the library's ``ms_robust_plan``
    gives the same :class:`~meshlab_sharp._kernels.RobustPlan`)."""
    top = max(scales)
    growth = 1.0
    if not mesh:  # the largest grown scale stays within the cloud
        growth = min(noise_factor(noise), n_kept / top)
    grown = growth > 1.0
    if grown:
        scales = tuple(grown_scale(k, growth) for k in scales)
        top = max(scales)
    quiet = quiet_cloud(mesh, noise)
    support_k = THIN_RING if mesh else SUPPORT_KNN
    compare_k = THIN_RING if mesh else thin_knn(growth)
    return RobustPlan(
        mesh=bool(mesh),
        noise=float(noise),
        scales=tuple(int(k) for k in scales),
        growth=float(growth),
        grown=grown,
        otsu=otsu_splits(mesh, noise),
        noise_floor=not mesh and not quiet,
        acute_tests=quiet,
        support_knn=min(support_k, top),
        compare_knn=min(compare_k, top),
        ranking_smoothed=ranking_smoothed(mesh, noise),
        free_below=support_free_score(mesh, noise),
        thin_cone=thin_cone(mesh, noise),
        thin_side=thin_side(mesh, noise),
        thin_between=quiet,
        curved_dropped=bool(mesh),
        thin_line=not mesh and not ranking_smoothed(mesh, noise),
    )
