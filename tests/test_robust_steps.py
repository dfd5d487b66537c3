"""Robust mode's steps that tests/test_robust.py does not pin one by one: isolation,
the local scale and centroid distance, relative distances, the floor and the score
(exact known answers)."""

from __future__ import annotations

import math

import numpy as np

from meshlab_sharp import robust
from meshlab_sharp.neighbourhoods import Neighbourhood


def _csr(lists: list[list[int]]) -> Neighbourhood:
    indptr = np.r_[0, np.cumsum([len(x) for x in lists])].astype(np.int64)
    return Neighbourhood(indptr, np.concatenate(lists).astype(np.int64))


def test_isolated_points_are_not_among_their_nearest_neighbours_lists():
    # 2 columns: (0, 1) and (2, 3) are mutual nearest neighbours, 4's nearest is 3
    indices = np.array([[0, 1], [1, 0], [2, 3], [3, 2], [4, 3]])
    np.testing.assert_array_equal(robust.isolated_points(indices), [0, 0, 0, 0, 1])
    # 3 columns: 3's list reaches 4, nobody is isolated
    indices = np.array([[0, 1, 2], [1, 0, 2], [2, 3, 1], [3, 2, 4], [4, 3, 2]])
    assert not robust.isolated_points(indices).any()
    assert robust.isolated_points(np.zeros((3, 1), int)).tolist() == [False] * 3


def test_local_scale_and_centroid_distance():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 4]])
    ell, offset = robust.local_scale(points, _csr([[0, 1, 2], [1], [2, 0], [3, 0, 1, 2]]))
    # point 0: distances 0, 1, 2, centroid offset (1, 2, 0) / 3
    assert ell[0] == 1.0 and offset[0] == math.sqrt(5.0) / 3.0
    assert ell[1] == 0.0 and offset[1] == 0.0
    assert ell[2] == 1.0 and offset[2] == 1.0
    np.testing.assert_allclose(ell[3], (0 + math.sqrt(17) + math.sqrt(20) + 4) / 4, rtol=1e-15)


def test_relative_distances_are_clipped_and_zero_without_a_scale():
    r = robust.relative_distances(np.array([0.5, 3.0, 1.0, 0.0]), np.array([1.0, 2.0, 0.0, 0.0]))
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
    ell, _ = robust.local_scale(points, Neighbourhood(np.r_[0, np.full(n, n)], np.arange(n)))
    pdis = abs(points[:, 2].mean())
    assert abs(pdis / ell[0] - robust.R_MIN) < 1e-5  # a 0.2-degree change: 1e-3


def test_threshold_is_otsu_with_a_floor():
    low = np.r_[np.zeros(50), np.full(50, 0.05)]  # Otsu: 1 / 256 (the first maximum)
    assert robust.robust_threshold(low) == robust.R_MIN
    split = np.r_[np.full(50, 0.5), np.full(50, 0.9)]  # bins 128 and 230
    assert robust.robust_threshold(split) == 129 / 256
    assert robust.robust_threshold(np.full(10, 0.3)) == 1.0  # nothing to split


def test_score_is_the_mean_centroid_distance_over_the_scales():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 4]])
    lists = {2: _csr([[0, 1], [1, 0], [2, 0], [3, 0]]), 4: _csr([[0, 1, 2, 3]] * 4)}
    rule = robust.RelativeRule(points, lists.__getitem__, 2)
    for i, k in enumerate((2, 4)):
        r, t = rule(i, k, np.zeros(4))
        assert (r == 0).all() and t == 1.0
    ell2, o2 = robust.local_scale(points, lists[2])
    ell4, o4 = robust.local_scale(points, lists[4])
    np.testing.assert_array_equal(
        rule.score, np.minimum(o2 / ell2, 1) / 2 + np.minimum(o4 / ell4, 1) / 2
    )
