"""Cleaning merges duplicates and drops unreferenced vertices; results stay in input order."""

from __future__ import annotations

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp.cleaning import clean
from meshlab_sharp.io import as_geometry


def test_duplicates_take_the_result_of_their_first_occurrence():
    points = shapes.cube_grid_points(15)
    rng = np.random.default_rng(0)
    dup_of = rng.choice(len(points), 200, replace=False)
    with_dups = np.concatenate([points, points[dup_of]])
    order = rng.permutation(len(with_dups))
    noisy_input = with_dups[order]

    result = meshlab_sharp.detect(noisy_input)
    assert len(result.mask) == len(noisy_input)
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(noisy_input))
    assert result.n_clean == len(points)
    assert result.kept.all()


def test_unreferenced_vertices_are_dropped_and_never_features():
    vertices, faces = shapes.cube_grid_mesh(3)
    # Two isolated vertices, and one that duplicates the corner (1, 1, 1), put first so
    # that it is the first occurrence the corner's faces are merged into.
    extra = np.array([[5.0, 5.0, 5.0], [1.0, 1.0, 1.0], [-7.0, 0.0, 0.0]])
    all_vertices = np.concatenate([extra, vertices])
    all_faces = faces + len(extra)
    result = meshlab_sharp.detect(all_vertices, all_faces)
    assert len(result.mask) == len(all_vertices)
    np.testing.assert_array_equal(result.kept[:3], [False, True, False])
    assert result.kept[3:].all()
    np.testing.assert_array_equal(result.mask[:3], [False, True, False])
    np.testing.assert_array_equal(result.strength[[0, 2]], 0.0)
    np.testing.assert_array_equal(result.mask[3:], shapes.on_cube_edges(vertices))
    assert result.n_clean == len(vertices)


def test_clean_maps_both_ways():
    v = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [5, 5, 5], [0, 0, 1], [0, 0, 0]], float
    )
    f = np.array([[0, 1, 2], [3, 2, 5], [0, 1, 3], [6, 2, 5]])
    c = clean(as_geometry(v, f))
    np.testing.assert_array_equal(c.to_input, [0, 1, 2, 5])
    np.testing.assert_array_equal(c.from_input, [0, 1, 2, 1, -1, 3, 0])
    np.testing.assert_array_equal(c.vertices, v[[0, 1, 2, 5]])
    # The face (0, 1, 3) has zero area once 3 is merged into 1.
    assert len(c.faces) == 3
    assert set(map(tuple, np.sort(c.faces, axis=1))) == {(0, 1, 2), (1, 2, 3), (0, 2, 3)}


def test_collinear_faces_are_dropped():
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 1, 3]])
    c = clean(as_geometry(v, f))
    assert len(c.faces) == 1
    np.testing.assert_array_equal(c.from_input, [0, 1, -1, 2])


@pytest.mark.parametrize("mode", ["paper", "robust"])
@pytest.mark.parametrize("kind", ["cloud", "mesh", "mesh with duplicates"])
def test_the_callers_arrays_are_never_written(kind: str, mode: str) -> None:
    """``detect`` shares float64 / int64 input arrays without copying them (no copy of
    n x 3 values): no step may write to them, also when cleaning merges duplicates and
    drops unreferenced vertices. Read-only arrays prove it: a write would raise."""
    if kind == "cloud":
        vertices, faces = shapes.noisy_box_points(3000, 0.1), None
    else:
        vertices, faces = shapes.cube_grid_mesh(3)
        if kind == "mesh with duplicates":
            vertices = np.concatenate([vertices[:5], vertices, [[9.0, 9.0, 9.0]]])
            faces = faces + 5
    before = (vertices.copy(), None if faces is None else faces.copy())
    vertices.flags.writeable = False
    if faces is not None:
        faces.flags.writeable = False
    result = meshlab_sharp.detect(vertices, faces, mode=mode, curves=True)
    assert result.mask.any()
    np.testing.assert_array_equal(vertices, before[0])
    if faces is not None:
        np.testing.assert_array_equal(faces, before[1])


@pytest.mark.parametrize("backend", ["numpy", "compiled"])
def test_to_input_order_is_a_gather_through_from_input(backend: str) -> None:
    """``to_input_order`` is ``values[from_input]`` (``fill`` where dropped): with nothing
    merged or dropped, ``values`` itself; with merges, with drops, a new array."""
    vertices, faces = shapes.cube_grid_mesh(4)
    extra = np.array([[5.0, 5.0, 5.0], [1.0, 1.0, 1.0]])  # isolated; a corner's duplicate
    cases = {
        "as is": (vertices, None),
        "merged": (np.concatenate([vertices, vertices[:7]]), None),
        "dropped": (np.concatenate([extra, vertices]), faces + len(extra)),
    }
    for name, (v, f) in cases.items():
        c = clean(as_geometry(v, f), backend=backend)
        values = np.arange(len(c.vertices), dtype=np.float64) * 0.5
        expected = np.where(c.from_input >= 0, values[c.from_input], -1.0)
        got = c.to_input_order(values, -1.0)
        assert got.tobytes() == expected.tobytes(), name
        assert (got is values) == (name == "as is"), name
