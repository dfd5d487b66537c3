"""Every format users bring is read through pymeshlab and gives the same answer."""

from __future__ import annotations

import numpy as np
import pymeshlab
import pytest
import shapes
from files import write_xyz

import meshlab_sharp

MESH_FORMATS = ["ply", "obj", "off", "stl"]


@pytest.fixture(scope="module")
def cube_mesh():
    return shapes.cube_grid_mesh(3)


@pytest.mark.parametrize("ext", MESH_FORMATS)
def test_mesh_formats(tmp_path, cube_mesh, ext):
    vertices, faces = cube_mesh
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32)))
    path = tmp_path / f"cube.{ext}"
    ms.save_current_mesh(str(path))
    result = meshlab_sharp.detect(path)
    loaded = meshlab_sharp.load(path)
    assert result.kind == "mesh"
    # STL stores triangles only: pymeshlab re-merges its corners, so compare by position.
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(loaded.vertices, tol=1e-6))
    assert result.n_features == 12 * 7 + 8


@pytest.mark.parametrize("ext", ["xyz", "pts", "asc", "txt"])
def test_point_list_formats(tmp_path, ext):
    points = shapes.cube_grid_points(9)
    path = write_xyz(tmp_path / f"cube.{ext}", points)
    result = meshlab_sharp.detect(path)
    assert result.kind == "points"
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(points))


def test_comma_separated_txt(tmp_path):
    points = shapes.cube_grid_points(9)
    path = tmp_path / "cube.txt"
    path.write_text("".join(f"{x},{y},{z}\n" for x, y, z in points))
    result = meshlab_sharp.detect(path)
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(points))


def test_pts_with_a_count_header(tmp_path):
    points = shapes.cube_grid_points(9)
    path = tmp_path / "cube.pts"
    path.write_text(f"{len(points)}\n" + "".join(f"{x} {y} {z}\n" for x, y, z in points))
    result = meshlab_sharp.detect(path)
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(points))


def test_binary_and_ascii_ply_agree(tmp_path):
    points = shapes.random_box_points(1500, seed=9)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=points))
    ms.save_current_mesh(str(tmp_path / "a.ply"), binary=False)
    ms.save_current_mesh(str(tmp_path / "b.ply"), binary=True)
    a = meshlab_sharp.detect(tmp_path / "a.ply")
    b = meshlab_sharp.detect(tmp_path / "b.ply")
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_array_equal(a.thresholds, b.thresholds)
