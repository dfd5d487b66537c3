"""Robust mode's steps that tests/test_robust.py does not pin one by one: isolation,
the local scale and centroid distance, relative distances, the floor and the score
(exact known answers)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp import _kernels, robust
from meshlab_sharp._kernels import RobustPlan
from meshlab_sharp.neighbourhoods import KnnNeighbourhoods, Neighbourhood
from meshlab_sharp.reference import detect as reference_sequence
from meshlab_sharp.reference import robust as reference
from meshlab_sharp.reference.detect import RelativeRule
from meshlab_sharp.threshold import BINS, histogram


def _plan(mesh: bool, noise: float) -> RobustPlan:
    """Robust mode's plan for an input of noise ratio ``noise`` (10,000 points, the
    default scales)."""
    return reference_sequence.robust_plan(noise, 10_000, (12, 16, 20, 24, 28, 32, 36, 40), mesh)


def _csr(lists: list[list[int]]) -> Neighbourhood:
    indptr = np.r_[0, np.cumsum([len(x) for x in lists])].astype(np.int64)
    return Neighbourhood(indptr, np.concatenate(lists).astype(np.int64))


def test_isolated_points_are_not_among_their_nearest_neighbours_lists():
    points = np.zeros((5, 3))  # the second rule finds none: every distance is 0
    # 2 columns: (0, 1) and (2, 3) are mutual nearest neighbours, 4's nearest is 3
    indices = np.array([[0, 1], [1, 0], [2, 3], [3, 2], [4, 3]])
    np.testing.assert_array_equal(reference.isolated_points(points, indices), [0, 0, 0, 0, 1])
    # 3 columns: 3's list reaches 4, nobody is isolated
    indices = np.array([[0, 1, 2], [1, 0, 2], [2, 3, 1], [3, 2, 4], [4, 3, 2]])
    assert not reference.isolated_points(points, indices).any()
    assert reference.isolated_points(points[:3], np.zeros((3, 1), int)).tolist() == [False] * 3


def _lists(points: np.ndarray, k: int) -> np.ndarray:
    d2 = ((points[:, None] - points[None]) ** 2).sum(-1)
    return np.lexsort((np.broadcast_to(np.arange(len(points)), d2.shape), d2))[:, :k]


@pytest.mark.parametrize("size", [1, 2, 3])
def test_a_stray_cluster_is_isolated_when_its_third_neighbour_is_far(size):
    # a 12 x 12 grid of spacing 1 and a cluster of `size` points 0.5 apart at height h
    # over its middle: the cluster's third neighbour lies about h away, the third
    # neighbour of its k-th neighbour (on the grid) 1 away: less than 5 times farther at
    # h = 4.5, more at 5.5; a lone point is isolated by the first rule at any height
    xy = np.stack(np.meshgrid(np.arange(12.0), np.arange(12.0)), -1).reshape(-1, 2)
    grid = np.c_[xy, np.zeros(144)]
    k = 20
    for h in (4.5, 5.5, 20.0):
        cluster = [5.3, 5.6, h] + np.array([[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]])[:size]
        points = np.vstack([grid, cluster])
        found = reference.isolated_points(points, _lists(points, k))
        assert not found[:144].any()
        assert found[144:].tolist() == [size == 1 or h > 5] * size, (h, found[144:])
    # the first rule alone leaves pairs and triples in: each is among the others' nearest
    points = np.vstack([grid, [5.3, 5.6, 20.0] + 0.5 * np.eye(3)[:size]])
    indices = _lists(points, k)
    lone = ~(indices[indices[:, 1]] == np.arange(len(points))[:, None]).any(axis=1)
    assert lone[144:].all() == (size == 1)


def test_local_scale_and_centroid_distance():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 4]])
    ell, offset = reference_sequence.local_scale(
        points, _csr([[0, 1, 2], [1], [2, 0], [3, 0, 1, 2]])
    )
    # point 0: distances 0, 1, 2, centroid offset (1, 2, 0) / 3
    assert ell[0] == 1.0 and offset[0] == math.sqrt(5.0) / 3.0
    assert ell[1] == 0.0 and offset[1] == 0.0
    assert ell[2] == 1.0 and offset[2] == 1.0
    np.testing.assert_allclose(ell[3], (0 + math.sqrt(17) + math.sqrt(20) + 4) / 4, rtol=1e-15)


def test_relative_distances_are_clipped_and_zero_without_a_scale():
    r = reference_sequence.relative_distances(
        np.array([0.5, 3.0, 1.0, 0.0]), np.array([1.0, 2.0, 0.0, 0.0])
    )
    np.testing.assert_array_equal(r, [0.5, 1.0, 0.0, 0.0])


def test_the_floor_is_r_on_a_fold_of_the_crease_angle():
    assert robust.R_MIN == (2 / math.pi) * math.sin(math.pi / 18) == 0.11054786333836651
    # a disc sampled with equal areas, folded by 20 degrees along its diameter: the
    # centroid offset across the bisecting plane relative to the mean distance
    rings, sectors = 400, 400
    rad = np.sqrt((np.arange(rings) + 0.5) / rings)
    ang = 2 * np.pi * (np.arange(sectors) + 0.5) / sectors
    x = np.outer(rad, np.cos(ang)).ravel()
    y = np.outer(rad, np.sin(ang)).ravel()
    tilt = np.radians(robust.CREASE_ANGLE / 2)
    points = np.c_[
        np.r_[0.0, x], np.r_[0.0, y * np.cos(tilt)], np.r_[0.0, np.abs(y) * np.sin(tilt)]
    ]
    n = len(points)  # only the disc's centre (point 0) has a neighbourhood: all points
    ell, _ = reference_sequence.local_scale(
        points, Neighbourhood(np.r_[0, np.full(n, n)], np.arange(n))
    )
    pdis = abs(points[:, 2].mean())
    assert abs(pdis / ell[0] - robust.R_MIN) < 1e-5  # a 0.2-degree change: 1e-3


def test_threshold_is_otsu_with_a_floor():
    low = np.r_[np.zeros(50), np.full(50, 0.05)]  # Otsu: 1 / 256 (the first maximum)
    assert reference_sequence.robust_threshold(low) == robust.R_MIN
    split = np.r_[np.full(50, 0.5), np.full(50, 0.9)]  # bins 128 and 230
    assert reference_sequence.robust_threshold(split) == 129 / 256
    assert reference_sequence.robust_threshold(np.full(10, 0.3)) == 1.0  # nothing to split
    # the floor alone (a cloud without noise): Otsu's split and its "nothing to split"
    # do not raise it
    assert reference_sequence.robust_threshold(split, otsu=False) == robust.R_MIN
    assert reference_sequence.robust_threshold(np.full(10, 0.3), otsu=False) == robust.R_MIN


def test_otsu_splits_on_meshes_and_on_clouds_with_noise():
    assert robust.NOISE_QUIET == 0.05
    assert _plan(True, 0.0).otsu and _plan(True, 0.3).otsu
    assert not _plan(False, 0.0).otsu
    assert not _plan(False, 0.05).otsu
    assert _plan(False, 0.05 + 1e-12).otsu


def test_weak_candidates_of_a_cloud_without_noise_need_no_support():
    assert robust.SUPPORT_FREE_SCORE == 0.22
    score = np.array([0.0, 0.2199, 0.22, 0.9])
    exempt = reference_sequence.support_exempt
    np.testing.assert_array_equal(exempt(score, _plan(False, 0.05)), [1, 1, 0, 0])
    assert not exempt(score, _plan(False, 0.05 + 1e-12)).any()  # noisy cloud
    assert not exempt(score, _plan(True, 0.0)).any()  # mesh
    # a lone feature (no other feature along its line) stays only where exempt
    pts = np.array([[0.0, 0, 0], [0, 1, 0], [0, 0, 3]])
    mask = np.array([True, True, False])
    e = np.tile([1.0, 0.0, 0.0], (3, 1))
    around = _csr([[0, 1, 2], [1, 0, 2], [2, 0]])
    exempt = np.array([True, False, True])
    out = reference.supported(pts, mask, e, around, 2, exempt=exempt)
    np.testing.assert_array_equal(out, [True, False, False])


def test_a_cloud_without_noise_is_thresholded_at_the_floor_a_noisy_one_by_otsu():
    clean = meshlab_sharp.detect(shapes.random_box_points(800, seed=2), mode="robust")
    assert (clean.thresholds == robust.R_MIN).all()
    # noise of 1 % of the spacing (uniform samples): nu 0.03, the floor; 3 %: nu 0.09,
    # Otsu, the scales not grown (nu below NOISE_TOLERATED)
    for sigma, quiet in ((0.01, True), (0.03, False)):
        noisy = meshlab_sharp.detect(shapes.noisy_box_points(800, sigma), mode="robust")
        assert noisy.scales == meshlab_sharp.DEFAULT_KNN_SCALES
        assert (noisy.thresholds == robust.R_MIN).all() == quiet, sigma


def test_score_is_the_mean_centroid_distance_over_the_scales():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 4]])
    lists = {2: _csr([[0, 1], [1, 0], [2, 0], [3, 0]]), 4: _csr([[0, 1, 2, 3]] * 4)}
    rule = RelativeRule(points, lists.__getitem__, 2)
    for i, k in enumerate((2, 4)):
        r, t = rule(i, k, np.zeros(4))
        assert (r == 0).all() and t == 1.0
    ell2, o2 = reference_sequence.local_scale(points, lists[2])
    ell4, o4 = reference_sequence.local_scale(points, lists[4])
    np.testing.assert_array_equal(
        rule.score, np.minimum(o2 / ell2, 1) / 2 + np.minimum(o4 / ell4, 1) / 2
    )


def _two_sheets(own: int, other: list[float], per_level: int = 9) -> tuple[np.ndarray, np.ndarray]:
    """Point 0 at the origin, ``own`` more points of its sheet (z = 0) on a unit grid,
    ``per_level`` points at each height of ``other``: (points, one list (1, n))."""
    grid = [(x, y) for r in range(4) for x in range(-r, r + 1) for y in range(-r, r + 1)]
    grid = sorted(set(grid), key=lambda p: (p[0] ** 2 + p[1] ** 2, p))
    pts = [(0.0, 0.0, 0.0)] + [(float(x), float(y), 0.0) for x, y in grid[1 : own + 1]]
    for z in other:
        pts += [(float(x) + 0.5, float(y) + 0.5, z) for x, y in grid[:per_level]]
    points = np.array(pts)
    return points, np.arange(len(points))[None, :]


def _mask(points: np.ndarray, lists: np.ndarray) -> np.ndarray:
    return reference_sequence.sheet_mask(points, lists, np.array([[0.0, 0.0, 1.0]]))[0]


def test_sheet_mask_drops_the_other_side_of_a_thin_wall():
    # 12 points on the own sheet, 9 one spacing above: a = (4 * 1 + 2 * sqrt 2) / 6
    points, lists = _two_sheets(12, [1.0])
    keep = _mask(points, lists)
    np.testing.assert_array_equal(keep, points[:, 2] == 0.0)
    # below the point as well, and with a normal of either sign
    points[13:, 2] = -1.0
    np.testing.assert_array_equal(_mask(points, lists), points[:, 2] == 0.0)
    flipped = reference_sequence.sheet_mask(points, lists, np.array([[0.0, 0.0, -1.0]]))[0]
    np.testing.assert_array_equal(flipped, points[:, 2] == 0.0)


def test_sheet_mask_keeps_what_is_not_one_separate_sheet():
    a = (4 + 2 * math.sqrt(2)) / 6  # the spacing read from the 6 nearest of the grid
    # a step of exactly SHEET_GAP * a is no gap (a gap is wider)
    points, lists = _two_sheets(12, [robust.SHEET_GAP * a])
    assert _mask(points, lists).all()
    points, lists = _two_sheets(12, [robust.SHEET_GAP * a * 1.001])
    assert not _mask(points, lists).all()
    # fewer than SHEET_MIN (6) points beyond the gap: the tail of the noise
    points, lists = _two_sheets(12, [1.0], per_level=robust.SHEET_MIN - 1)
    assert _mask(points, lists).all()
    points, lists = _two_sheets(12, [1.0], per_level=robust.SHEET_MIN)
    assert not _mask(points, lists).all()
    # two gaps: everything beyond the first is dropped (a rib standing on the far side
    # of a floor one spacing thick adds gaps of its own above that side)
    points, lists = _two_sheets(12, [1.0, 2.0], per_level=6)
    np.testing.assert_array_equal(_mask(points, lists), points[:, 2] == 0.0)
    # ... as long as the own rule holds: 12 beyond the first gap need 6 kept
    points, lists = _two_sheets(5, [1.0, 2.0], per_level=6)
    np.testing.assert_array_equal(_mask(points, lists), points[:, 2] == 0.0)
    points, lists = _two_sheets(4, [1.0, 2.0], per_level=6)
    assert _mask(points, lists).all()
    # more than 1 / SHEET_OWN (2) times as many beyond the gap as kept: the point is an
    # edge or a corner of the surface
    points, lists = _two_sheets(3, [1.0], per_level=9)
    assert _mask(points, lists).all()
    points, lists = _two_sheets(4, [1.0], per_level=9)
    np.testing.assert_array_equal(_mask(points, lists), points[:, 2] == 0.0)


def _rim(bridge: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """A wall two spacings thick near its rim: :func:`_two_sheets` with the other side at
    z = -2, and the end face joining them as points at the heights ``bridge``, 4
    spacings aside (outside the point's column)."""
    points, _ = _two_sheets(12, [-2.0])
    end = np.array([(4.0, 0.0, z) for z in bridge])
    points = np.vstack([points, end])
    return points, np.arange(len(points))[None, :]


def test_sheet_mask_finds_the_other_side_in_the_column_where_the_end_face_joins_them():
    a = (4 + 2 * math.sqrt(2)) / 6
    # rule 1 sees steps of 0.4 < SHEET_GAP * a (0.455) all the way down: no gap
    points, lists = _rim([-0.4, -0.8, -1.2, -1.6])
    assert reference_sequence.sheet_mask(
        points, lists, np.array([[0.0, 0.0, 1.0]]), (0.4, 6, 0.5, 0.0, 0.0, 0.0, 0.0, 1.0)
    )[0].all()
    # rule 2: in the column (the 4 points below within SHEET_COLUMN * a = 1.25 of the
    # axis) a step of 2 > SHEET_COLUMN_GAP * a; cut half way, at -1
    np.testing.assert_array_equal(_mask(points, lists), points[:, 2] >= -1.0)
    # the points left out span 0.8 spacings (-2 to -1.2); 1.6 > SHEET_FAR_SPAN * a
    # (1.42): not one parallel sheet, every point kept
    # (rules 1 and 2 alone: the second pass, tested below, runs where a height exceeds
    # SHEET_TRIM * a, as -2.8 does)
    points, lists = _rim([-0.4, -0.8, -1.2, -1.6, -2.4, -2.8])
    assert robust.SHEET_FAR_SPAN * a < 1.6
    rules_only = robust.sheet_parameters()[:6] + (0.0, 1.0)
    assert reference_sequence.sheet_mask(points, lists, np.array([[0.0, 0.0, 1.0]]), rules_only)[
        0
    ].all()
    # the column: the other side's nearest lie 0.71 from the axis; a column narrower than
    # that sees no other side
    points, lists = _rim([-0.4, -0.8, -1.2, -1.6])
    narrow = (0.4, 6, 0.5, 0.7 / a, robust.SHEET_COLUMN_GAP, robust.SHEET_FAR_SPAN, 0.0, 1.0)
    assert reference_sequence.sheet_mask(points, lists, np.array([[0.0, 0.0, 1.0]]), narrow)[
        0
    ].all()
    # a step of exactly SHEET_COLUMN_GAP * a is no gap
    exact = (0.4, 6, 0.5, robust.SHEET_COLUMN, 2.0 / a, robust.SHEET_FAR_SPAN, 0.0, 1.0)
    assert reference_sequence.sheet_mask(points, lists, np.array([[0.0, 0.0, 1.0]]), exact)[0].all()


def test_sheet_mask_tries_again_along_the_plane_of_the_nearer_heights():
    # a floor one spacing thick (two 5 x 5 grids, z = 0 and z = 1) with a rib's points
    # above it, and a normal tilted by 8 degrees (as the rib tilts the PCA normal):
    # each grid's heights spread over the gap between them, no rule finds a gap
    grid = sorted(
        [(x, y) for x in range(-2, 3) for y in range(-2, 3)],
        key=lambda p: (p[0] ** 2 + p[1] ** 2, p),
    )
    floor = [(float(x), float(y), z) for z in (0.0, 1.0) for x, y in grid]
    rib = [(0.0, 0.0, z) for z in (2.0, 2.5, 3.0)]
    t = math.radians(8.0)
    normal = np.array([[math.sin(t), 0.0, math.cos(t)]])
    points = np.array(floor + rib)
    lists = np.arange(len(points))[None, :]
    rules_only = robust.sheet_parameters()[:6] + (0.0, 1.0)
    assert reference_sequence.sheet_mask(points, lists, normal, rules_only)[0].all()
    # the rib's points lie higher than SHEET_TRIM * a (a = (5 + sqrt 2) / 6): the plane
    # of the others is the floor's, along which the other side lies beyond a gap
    np.testing.assert_array_equal(
        reference_sequence.sheet_mask(points, lists, normal)[0], points[:, 2] == 0.0
    )
    # ... only where its normal turns from the given one by at most about 10 degrees
    # (SHEET_TRIM_COS): here by 8, more than 7
    turned = robust.sheet_parameters()[:7] + (math.cos(math.radians(7.0)),)
    assert reference_sequence.sheet_mask(points, lists, normal, turned)[0].all()
    assert math.cos(math.radians(8.5)) > robust.SHEET_TRIM_COS
    # without the rib every height is within SHEET_TRIM * a: no second pass
    floor_only = np.array(floor)
    assert reference_sequence.sheet_mask(floor_only, np.arange(50)[None, :], normal)[0].all()
    assert robust.SHEET_TRIM * (5 + math.sqrt(2)) / 6 < 2.0 * math.cos(t)


def test_sheet_neighbourhoods_keep_the_prefixes_of_the_kept_points():
    # a 5 x 5 grid and, one spacing above, a 4 x 4 grid centred on the same axis: the
    # PCA normal of all 41 points is the z axis
    own = [(float(x), float(y), 0.0) for x in range(-2, 3) for y in range(-2, 3)]
    other = [(x + 0.5, y + 0.5, 1.0) for x in range(-2, 2) for y in range(-2, 2)]
    points = np.array(own + other)
    base = KnnNeighbourhoods(points, len(points), backend="numpy")
    sheets = reference.SheetNeighbourhoods(points, base, "gaussian", robust.sheet_parameters())
    centre = 12  # the point (0, 0, 0)
    mine = set(np.flatnonzero(points[:, 2] == 0.0))
    row = base.indices[centre]
    assert not sheets.keep[centre].all()
    at = sheets.at(10)
    got = at.indices[at.indptr[centre] : at.indptr[centre + 1]].tolist()
    assert got == [j for j in row[:10] if j in mine]
    first = sheets.first(7)
    got = first.indices[first.indptr[centre] : first.indptr[centre + 1]].tolist()
    assert got == [j for j in row if j in mine][:7]


def test_thinning_list_grows_with_the_scales():
    assert reference.thin_knn(1.0) == robust.THIN_KNN == 12
    assert reference.thin_knn(1.8) == 22  # 21.6, rounded half up as the scales are
    assert reference.thin_knn(3.0) == 36
    assert reference.thin_knn(1.125) == 14  # 13.5 exactly: half up


def test_thinning_ranks_by_the_mean_score_where_the_noise_grew_the_scales_to_the_cap():
    # the cap is reached at nu = 0.15 * sqrt(3) = 0.2598...: below it, and on meshes, the
    # score itself
    assert _plan(False, 0.27).ranking_smoothed
    assert not _plan(False, 0.25).ranking_smoothed
    assert not _plan(True, 0.5).ranking_smoothed
    score = np.array([0.9, 0.1, 0.2, 0.6, 0.3])
    compare = _csr([[0, 1, 2, 3], [1, 0], [], [3, 4, 0], []])
    rank = reference.smoothed_ranking(score, compare, 3)
    # rows: the mean of their first 3 entries (the point itself first); empty: the score
    np.testing.assert_array_equal(rank, [(0.9 + 0.1 + 0.2) / 3, (0.1 + 0.9) / 2, 0.2, 0.6, 0.3])
    # a point lifted beside a line outranks the line's point (0.9 > 0.6), but not its mean
    pts = np.array([[0.0, 0, 0], [0, 1, 0], [1, 0, 0], [-1, 0, 0], [1, 1, 0], [-1, 1, 0]])
    score = np.array([0.6, 0.9, 0.6, 0.6, 0.0, 0.0])
    mask = np.array([True, True, False, False, False, False])
    e = np.tile([1.0, 0.0, 0.0], (6, 1))
    compare = _csr([[0, 1, 2, 3], [1, 0, 4, 5], [], [], [], []])
    assert reference.thin(pts, mask, score, e, compare).tolist() == [False, True] + [False] * 4
    rank = reference.smoothed_ranking(score, compare, 4)
    assert reference.thin(pts, mask, rank, e, compare).tolist() == [True, False] + [False] * 4


def test_thinning_is_blocked_by_a_non_candidate_or_a_valley_between_on_a_quiet_cloud():
    # two parallel lines along x (the rims of a wall), 1 apart in y; feature 0 (score
    # 0.5) is beaten across its line by feature 1 (0.9) unless point 2, no candidate,
    # lies between them ((p_2 - p_0) . (p_2 - p_1) < 0); point 3 lies beyond 1
    pts = np.array([[0.0, 0, 0], [0, 1, 0], [0, 0.5, 0.1], [0, 2, 0]])
    mask = np.array([True, True, False, False])
    score = np.array([0.5, 0.9, 0.0, 0.0])
    e = np.tile([1.0, 0.0, 0.0], (4, 1))
    compare = _csr([[0, 1, 2], [1, 0], [2], [3]])
    assert reference.thin(pts, mask, score, e, compare).tolist() == [False, True, False, False]
    blockers = reference_sequence.thin_blockers
    between = blockers(np.array([True, True, False, False]), _plan(False, 0.0))
    np.testing.assert_array_equal(between, [False, False, True, True])
    kept = reference.thin(pts, mask, score, e, compare, between=between)
    assert kept.tolist() == [True, True, False, False]
    beyond = _csr([[0, 1, 3], [1, 0], [2], [3]])  # (p_3 - p_0) . (p_3 - p_1) = 2 > 0
    out = reference.thin(pts, mask, score, e, beyond, between=between)
    assert out.tolist() == [False, True, False, False]
    # a candidate between blocks only when it ranks below the beaten point (a valley)
    valley = blockers(np.array([True, True, True, False]), _plan(False, 0.0))
    for middle, blocked in ((0.49, True), (0.5, False), (0.7, False)):
        got = reference.thin(
            pts, mask, np.array([0.5, 0.9, middle, 0.0]), e, compare, between=valley
        )
        assert got.tolist() == [blocked, True, False, False]
    # meshes and clouds with noise: no blocking
    assert blockers(mask, _plan(True, 0.0)) is None
    assert blockers(mask, _plan(False, 0.05 + 1e-12)) is None
    assert blockers(mask, _plan(False, 0.05)) is not None


def test_thinning_cone_is_wider_on_a_noisy_cloud():
    assert _plan(False, 0.05).thin_cone == robust.THIN_CONE_COS == 0.5
    assert _plan(False, 0.05 + 1e-12).thin_cone == robust.THIN_CONE_COS_NOISY == 0.45
    assert _plan(True, 0.5).thin_cone == robust.THIN_CONE_COS  # meshes: never
    # feature 0 (score 0.5) and feature 1 (0.9) at 62 degrees from the line along x
    # (cos 0.469): across in the 60-degree cone, so 1 beats 0; along the line in the
    # noisy cone (about 63 degrees); at 64 degrees (cos 0.438) across in both
    mask = np.array([True, True])
    score = np.array([0.5, 0.9])
    e = np.tile([1.0, 0.0, 0.0], (2, 1))
    compare = _csr([[0, 1], [1, 0]])
    for degrees, cone, kept in ((62, 0.5, False), (62, 0.45, True), (64, 0.45, False)):
        a = math.radians(degrees)
        pts = np.array([[0.0, 0, 0], [math.cos(a), math.sin(a), 0]])
        got = reference.thin(pts, mask, score, e, compare, cone_cos=cone, side=math.inf)
        assert got.tolist() == [kept, True], (degrees, cone)


def test_thinning_drops_a_point_beside_a_higher_ranked_one_of_its_band():
    assert _plan(False, 0.05).thin_side == _plan(True, 0.5).thin_side == robust.THIN_SIDE
    assert _plan(False, 0.05 + 1e-12).thin_side == robust.THIN_SIDE_NOISY
    assert (robust.THIN_SIDE, robust.THIN_SIDE_NOISY) == (0.7, 0.65)
    # feature 0 (score 0.5) on a line along x, its list reaching 2 (point 2); feature 1
    # (0.9) ahead along the line (inside the cone) and 1.35 to its side: beaten beyond
    # 0.65 * 2 = 1.3, kept within 0.7 * 2 = 1.4
    pts = np.array([[0.0, 0, 0], [1.5, 1.35, 0], [-2.0, 0, 0]])
    mask = np.array([True, True, False])
    score = np.array([0.5, 0.9, 0.0])
    e = np.tile([1.0, 0.0, 0.0], (3, 1))
    compare = _csr([[0, 1, 2], [1, 0], [2]])
    for side, kept in ((robust.THIN_SIDE, True), (robust.THIN_SIDE_NOISY, False)):
        got = reference.thin(pts, mask, score, e, compare, side=side)
        assert got.tolist() == [kept, True, False], side
        if _kernels.available():  # ms_thin: the same
            table = _kernels.CandidateLists.knn(np.array([[0, 1, 2], [1, 0, 2]]), 3)
            rules = _kernels.FinishRules(0.5, 2, None, 0.5, side, 0, None)
            rows = np.array([0, 1])
            ours = _kernels.thin_candidates(pts, mask, rows, e[:2], table, score, rules, 1)
            assert ours.tolist() == got.tolist(), side


def test_acute_tests_are_the_non_candidates_scoring_in_the_band_on_a_cloud_without_noise():
    assert (robust.ACUTE_SCORE, robust.ACUTE_SCORE_MAX) == (0.5, 0.8)
    score = np.array([0.4999, 0.5, 0.7999, 0.8, 0.6, 0.95])
    mask = np.array([False, False, False, False, True, False])
    # candidates (4) are not tested; the band is [0.5, 0.8)
    assert reference_sequence.acute_tests(score, mask, False, 0.05).tolist() == [1, 2]
    assert reference_sequence.acute_tests(score, mask, False, 0.05 + 1e-12).tolist() == []  # noisy
    assert reference_sequence.acute_tests(score, mask, True, 0.0).tolist() == []  # mesh


def test_a_point_between_two_candidates_is_an_acute_tip():
    # a 45-degree wedge along z, its tip 0 at the origin: the candidates lie on the two
    # faces, a spacing behind the tip (x = -c, y = +-s); 1 and 2 one spacing apart
    # along the edge on either side of 0, 3 level with 2 on the other face
    s = math.sin(math.radians(22.5))
    c = math.cos(math.radians(22.5))
    pts = np.array([[0.0, 0, 0], [-c, s, 1], [-c, -s, -1], [-c, s, -1], [0, 0, -1]])
    rows = np.array([0])
    everything = _csr([[0, 1, 2, 3, 4], [], [], [], []])
    # (p_1 - p_0) . (p_2 - p_0) = c^2 - s^2 - 1 < 0: 0 lies between 1 and 2
    mask = np.array([False, True, True, False, False])
    assert reference.acute_tips(pts, mask, rows, everything).tolist() == [True]
    # 2 and 3 lie on the same side (c^2 - s^2 + 1 > 0): not between
    mask = np.array([False, False, True, True, False])
    assert reference.acute_tips(pts, mask, rows, everything).tolist() == [False]
    # only candidates in the list count
    mask = np.array([False, True, True, False, False])
    assert reference.acute_tips(pts, mask, rows, _csr([[0, 1, 3], [], [], [], []])).tolist() == [
        False
    ]
    # a dot product of exactly 0 (at right angles) is not between (strict)
    right = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    lists = _csr([[0, 1, 2], [], []])
    assert reference.acute_tips(right, np.array([False, True, True]), rows, lists).tolist() == [
        False
    ]
    # no points tested: an empty answer
    assert reference.acute_tips(pts, mask, np.array([], np.int64), everything).size == 0


def test_flat_edges_left_out_are_numpys_zero_angles():
    """The compiled sharp edges count the edges whose dot product is >= 1 instead of
    listing them, as angles of exactly +0 (``crease_threshold(..., zeros=...)``): what
    ``np.arccos(np.clip(dot, -1, 1))`` gives them, sign included, alone and among other
    values (NumPy's SIMD loops included); just below 1 the angle is positive."""
    rng = np.random.default_rng(11)
    flat = np.array([1.0, np.nextafter(1.0, 2.0), 1.5, np.inf])
    for dot in (flat, rng.permutation(np.r_[np.tile(flat, 500), rng.uniform(-1.2, 1.0, 3000)])):
        angles = np.arccos(np.clip(dot, -1.0, 1.0))
        at_one = angles[dot >= 1.0]
        assert len(at_one) and (at_one == 0.0).all() and not np.signbit(at_one).any()
        assert (angles[~(dot >= 1.0)] > 0.0).all()
    assert np.arccos(np.nextafter(1.0, 0.0)) > 0.0


def _histograms() -> list[np.ndarray]:
    """Counts of every shape the noise floor meets: empty, one point, one bin, the last
    bin, an even total whose lower median ends a bin, and random ones."""
    bins = BINS
    out = [np.zeros(bins, np.int64), np.eye(1, bins, 7, np.int64)[0]]
    out.append(np.eye(1, bins, bins - 1, np.int64)[0] * 5)
    even = np.zeros(bins, np.int64)
    even[[3, 9]] = 2  # ranks 0-1 in bin 3, 2-3 in bin 9: the lower median (rank 1), bin 3
    out.append(even)
    rng = np.random.default_rng(4)
    out += [rng.integers(0, 50, bins) * (rng.random(bins) < p) for p in (0.05, 0.5, 1.0)]
    return out


def test_the_noise_floor_kernel_is_the_reference_bit_for_bit():
    """ms_noise_floor and ms_scale_floor give the numpy reference's value exactly, on
    histograms and on those of values (bins as Otsu's), on every scale and noise."""
    rng = np.random.default_rng(5)
    values = (np.zeros(0), rng.random(1001) ** 3, np.r_[np.zeros(10), np.ones(11)])
    for counts in _histograms() + [histogram(v) for v in values]:
        assert _kernels.noise_floor(counts) == reference.noise_floor(counts)
        for last, mesh, noise in itertools.product((False, True), (False, True), (0.0, 0.2)):
            expected = reference.scale_floor(counts, last, mesh, noise)
            assert _kernels.scale_floor(counts, last, mesh, noise) == expected
    with pytest.raises(ValueError, match="one count per histogram bin"):
        _kernels.noise_floor(np.zeros(3, np.int64))


def test_the_noise_floor_is_three_lower_medians_of_the_largest_noisy_scale_capped():
    assert robust.NOISE_FLOOR == 3.0
    counts = np.zeros(BINS, np.int64)
    counts[[5, 10, 30]] = [4, 1, 4]  # 9 values: the lower median (rank 4) in bin 10
    assert reference.noise_floor(counts) == 3.0 * 11 / 256
    assert reference.noise_floor(np.zeros(BINS, np.int64)) == 0.0
    noisy = robust.NOISE_QUIET + 1e-12
    for backend in ("compiled", "numpy"):
        assert reference_sequence.scale_floor(counts, True, False, noisy, backend) == 3.0 * 11 / 256
        # other scales, quiet clouds and meshes: R_MIN alone
        assert reference_sequence.scale_floor(counts, False, False, noisy, backend) == robust.R_MIN
        assert (
            reference_sequence.scale_floor(counts, True, False, robust.NOISE_QUIET, backend)
            == robust.R_MIN
        )
        assert reference_sequence.scale_floor(counts, True, True, noisy, backend) == robust.R_MIN
    low = np.zeros(BINS, np.int64)
    low[2] = 9  # 3 * 3 / 256 < R_MIN: the floor stays R_MIN
    assert reference_sequence.scale_floor(low, True, False, noisy) == robust.R_MIN
    high = np.zeros(BINS, np.int64)
    high[100] = 9  # 3 * 101 / 256 > NOISE_FLOOR_MAX: the floor is the cap
    assert robust.NOISE_FLOOR_MAX == 0.22
    assert reference.noise_floor(high) == _kernels.noise_floor(high) == 0.22
    assert reference_sequence.scale_floor(high, True, False, noisy) == 0.22


@pytest.mark.parametrize("backend", ["compiled", "numpy"])
def test_a_noisy_sphere_has_no_features_and_a_noisy_box_keeps_its_edges(backend):
    """Noise of 25 % of the spacing: the sphere's points pass R_MIN at every scale
    (about 10 % flagged without the noise floor), the largest scale's floor drops them;
    the box, whose edges raise Otsu's split above the floor, keeps its 12 edges."""
    sphere = meshlab_sharp.detect(shapes.noisy_sphere_points(6000, 0.25), backend=backend)
    assert sphere.thresholds[-1] > robust.R_MIN
    assert sphere.mask.mean() <= 0.002
    points = shapes.noisy_box_points(6000, 0.25, seed=0)
    box = meshlab_sharp.detect(points, backend=backend)
    half = np.array([1.0, 0.7, 0.5])
    on_face = np.abs(np.abs(points) - half) < 0.05  # (n, 3): near each face pair
    near_edge = on_face.sum(axis=1) >= 2
    assert (box.mask & ~near_edge).sum() <= 0.07 * box.mask.sum()
    for a in range(3):  # the 4 edges along each axis: each one's length mostly covered
        b, c = [x for x in range(3) if x != a]
        for sb in (-1, 1):
            for sc in (-1, 1):
                edge = box.mask & on_face[:, b] & on_face[:, c]
                edge &= (np.sign(points[:, b]) == sb) & (np.sign(points[:, c]) == sc)
                along = np.sort(points[edge, a])
                gaps = np.diff(np.r_[-half[a], along, half[a]])
                assert gaps.max() < 0.4 * half[a], (a, sb, sc)
