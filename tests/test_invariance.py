"""Rotation, uniform scaling, translation and point order do not change the answer."""

from __future__ import annotations

import numpy as np
import pytest
import shapes

import meshlab_sharp


@pytest.fixture(scope="module")
def reference():
    points = shapes.box_cylinder_points(3000, seed=11)
    return points, meshlab_sharp.detect(points, return_details=True)


def _assert_same_features(result, reference_result, perm=None):
    mask = result.mask if perm is None else result.mask[np.argsort(perm)]
    ref = reference_result
    np.testing.assert_array_equal(result.thresholds, ref.thresholds)
    # ALGORITHM.md: only points within 1e-9 of a threshold may differ.
    near = (np.abs(ref.distances - ref.thresholds[:, None]) < 1e-9).any(axis=0)
    np.testing.assert_array_equal(mask[~near], ref.mask[~near])
    assert ref.n_features > 100


@pytest.mark.parametrize(
    "transform",
    ["rotation", "scale", "translation", "all"],
)
def test_rigid_and_scale_invariance(reference, transform):
    points, ref = reference
    rot = shapes.random_rotation(3)
    moved = {
        "rotation": points @ rot.T,
        "scale": points * 7.25,
        "translation": points + [120.0, -45.5, 3.0],
        "all": (points @ rot.T) * 0.04 + [-3.0, 8.0, 1.0],
    }[transform]
    _assert_same_features(meshlab_sharp.detect(moved), ref)


def test_point_order_does_not_matter(reference):
    points, ref = reference
    perm = np.random.default_rng(5).permutation(len(points))
    _assert_same_features(meshlab_sharp.detect(points[perm]), ref, perm)


def test_mesh_vertex_order_does_not_matter():
    vertices, faces = shapes.cube_grid_mesh(3)
    perm = np.random.default_rng(1).permutation(len(vertices))
    inverse = np.argsort(perm)
    shuffled = meshlab_sharp.detect(vertices[perm], inverse[faces])
    plain = meshlab_sharp.detect(vertices, faces)
    np.testing.assert_array_equal(shuffled.mask[inverse], plain.mask)
    np.testing.assert_array_equal(shuffled.thresholds, plain.thresholds)
