"""Inputs whose sharp features are known exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp.reference import detect as reference_sequence
from meshlab_sharp.reference import robust as reference_robust


@pytest.mark.parametrize("m", [15, 21])
def test_cube_points_give_exactly_the_12_edges(m):
    points = shapes.cube_grid_points(m)
    result = meshlab_sharp.detect(points)
    expected = shapes.on_cube_edges(points)
    assert expected.sum() == 12 * (m - 2) + 8
    np.testing.assert_array_equal(result.mask, expected)
    assert result.kind == "points"
    assert result.scales == meshlab_sharp.DEFAULT_KNN_SCALES


def test_cube_mesh_gives_exactly_the_12_edges():
    vertices, faces = shapes.cube_grid_mesh(4)
    result = meshlab_sharp.detect(vertices, faces)
    expected = shapes.on_cube_edges(vertices)
    assert expected.sum() == 12 * 15 + 8
    np.testing.assert_array_equal(result.mask, expected)
    assert result.kind == "mesh"
    assert result.scales == meshlab_sharp.DEFAULT_RING_SCALES
    np.testing.assert_array_equal(result.strength[expected], 1.0)


def test_cube_mesh_as_points_gives_the_edges_too():
    vertices, faces = shapes.cube_grid_mesh(4)
    result = meshlab_sharp.detect(vertices, faces, as_points=True)
    assert result.kind == "points"
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(vertices))


@pytest.mark.parametrize("tilt", [False, True])
def test_flat_square_has_no_features(tilt):
    points = shapes.flat_square(30)
    if tilt:
        points = points @ shapes.random_rotation(7).T + [3.0, -2.0, 5.0]
    result = meshlab_sharp.detect(points)
    assert result.n_features == 0
    assert not result.strength.any()
    np.testing.assert_array_equal(result.candidate_counts, 0)


def test_flat_square_mesh_has_no_features():
    points = shapes.flat_square(12)
    i, j = np.meshgrid(np.arange(11), np.arange(11), indexing="ij")
    a = (i * 12 + j).ravel()
    faces = np.concatenate([np.c_[a, a + 1, a + 12], np.c_[a + 1, a + 13, a + 12]])
    result = meshlab_sharp.detect(points, faces)
    assert result.kind == "mesh"
    assert result.n_features == 0


def test_strength_is_the_fraction_of_scales():
    points = shapes.random_box_points(1500, seed=2)
    robust = meshlab_sharp.detect(points, return_details=True)
    votes = (robust.distances >= robust.thresholds[:, None]).sum(axis=0)
    np.testing.assert_allclose(robust.strength, votes / len(robust.scales))
    # robust mode: support and thinning keep a subset of the candidates at every scale
    # and, on a cloud without noise, of the acute tips (reference.robust.acute_tips:
    # points between two such candidates, which may be candidates at fewer scales; here 6 of 191)
    assert robust.n_features > 0
    partial = robust.mask & (votes < len(robust.scales))
    assert 0 < partial.sum() <= 0.05 * robust.n_features
    with pytest.MonkeyPatch.context() as patch:
        # no tips: the rules' numpy reference, its constant raised, in the Python-driven
        # sequence (the library's constants are compiled in)
        patch.setattr(reference_sequence, "RULES", reference_robust)
        patch.setattr(reference_robust, "ACUTE_SCORE", math.inf)
        plain = meshlab_sharp.detect(points, return_details=True, backend="numpy")
    assert plain.n_features > 0
    assert (votes[plain.mask] == len(plain.scales)).all()
    result = meshlab_sharp.detect(points, return_details=True, mode="paper")
    votes = (result.distances >= result.thresholds[:, None]).sum(axis=0)
    np.testing.assert_allclose(result.strength, votes / len(result.scales))
    np.testing.assert_array_equal(result.mask, votes == len(result.scales))
    np.testing.assert_array_equal(
        result.candidate_counts, (result.distances >= result.thresholds[:, None]).sum(axis=1)
    )
    assert result.normals.shape == (8, 1500, 3)
    np.testing.assert_allclose(np.linalg.norm(result.normals, axis=2), 1.0)


def test_custom_scales_and_weighting_are_used():
    points = shapes.random_box_points(800, seed=4)
    result = meshlab_sharp.detect(points, scales=[20, 10, 10], weighting="none")
    assert result.scales == (10, 20)
    assert result.weighting == "none"
    assert len(result.thresholds) == 2


def test_both_backends_give_the_cube_edges():
    points = shapes.cube_grid_points(15)
    fast = meshlab_sharp.detect(points, backend="compiled")
    reference = meshlab_sharp.detect(points, backend="numpy")
    np.testing.assert_array_equal(fast.mask, shapes.on_cube_edges(points))
    np.testing.assert_array_equal(reference.mask, fast.mask)
    np.testing.assert_array_equal(reference.thresholds, fast.thresholds)
    with pytest.raises(meshlab_sharp.InputError, match="unknown backend"):
        meshlab_sharp.detect(points, backend="gpu")
