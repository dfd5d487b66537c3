"""The command line end to end: PLY in; PLY, indices and JSON out; read back with pymeshlab."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pymeshlab
import pytest
import shapes
from files import write_ply

import meshlab_sharp
from meshlab_sharp.cli import main, parse_scales
from meshlab_sharp.io import mesh_arrays
from meshlab_sharp.io.writers import _umask


def _read_back(path):
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    m = ms.current_mesh()
    out = (m.vertex_scalar_array(), m.vertex_selection_array(), m.vertex_color_matrix())
    vertices, faces = mesh_arrays(ms)
    return (vertices, faces, *out)


def test_detect_writes_ply_indices_and_report(tmp_path, capsys):
    vertices, faces = shapes.cube_grid_mesh(3)
    src = write_ply(tmp_path / "cube.ply", vertices, faces, binary=True)
    before = src.read_bytes()
    code = main(
        [
            "detect",
            str(src),
            "--indices",
            str(tmp_path / "cube.txt"),
            "--report",
            str(tmp_path / "cube.json"),
        ]
    )
    assert code == 0
    assert src.read_bytes() == before
    mode = (tmp_path / "cube_sharp.ply").stat().st_mode & 0o777
    assert mode == 0o666 & ~_umask()
    out = capsys.readouterr().out
    assert "sharp features" in out
    expected = shapes.on_cube_edges(vertices, tol=1e-6)

    v, f, quality, selection, colors = _read_back(tmp_path / "cube_sharp.ply")
    np.testing.assert_allclose(v, vertices.astype(np.float32))
    np.testing.assert_array_equal(f, faces)
    np.testing.assert_array_equal(selection, expected)
    np.testing.assert_array_equal(quality[expected], 1.0)
    assert (quality[~expected] < 1.0).all()
    assert (colors[expected, 0] > 0.8).all() and (colors[expected, 1] < 0.2).all()

    indices = np.loadtxt(tmp_path / "cube.txt", dtype=int)
    np.testing.assert_array_equal(indices, np.flatnonzero(expected))

    report = json.loads((tmp_path / "cube.json").read_text())
    assert report["kind"] == "mesh"
    assert report["n_input"] == len(vertices)
    assert report["n_features"] == int(expected.sum())
    assert [s["scale"] for s in report["scales"]] == [1, 2, 3, 4]
    assert all(0 < s["threshold"] <= 1 for s in report["scales"])
    assert report["options"] == {"scales": [1, 2, 3, 4], "weighting": "gaussian"}
    assert {"load", "clean", "save", "total"} <= set(report["timings_s"])


def test_output_is_not_overwritten_without_force(tmp_path, capsys):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    assert main(["detect", str(src), "-q"]) == 0
    first = (tmp_path / "c_sharp.ply").read_bytes()
    assert main(["detect", str(src), "-q", "--ascii"]) == 1
    assert "exists; use --force" in capsys.readouterr().err
    assert (tmp_path / "c_sharp.ply").read_bytes() == first
    assert main(["detect", str(src), "-q", "--ascii", "--force"]) == 0
    assert (tmp_path / "c_sharp.ply").read_bytes() != first


def test_refuses_to_overwrite_the_input(tmp_path, capsys):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    before = src.read_bytes()
    assert main(["detect", str(src), "-o", str(src), "--force"]) == 1
    assert "overwrite the input" in capsys.readouterr().err
    assert src.read_bytes() == before


def test_as_points_keeps_the_faces_in_the_output(tmp_path):
    vertices, faces = shapes.cube_grid_mesh(3)
    src = write_ply(tmp_path / "m.ply", vertices, faces)
    report = tmp_path / "r.json"
    assert main(["detect", str(src), "--as-points", "--report", str(report), "-q"]) == 0
    assert json.loads(report.read_text())["kind"] == "points"
    _, f, *_ = _read_back(tmp_path / "m_sharp.ply")
    np.testing.assert_array_equal(f, faces)


def test_scales_option(tmp_path):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(11))
    report = tmp_path / "r.json"
    assert main(["detect", str(src), "--scales", "10:30:10", "--report", str(report), "-q"]) == 0
    assert json.loads(report.read_text())["options"]["scales"] == [10, 20, 30]


def test_parse_scales():
    assert parse_scales("12:40:4") == [12, 16, 20, 24, 28, 32, 36, 40]
    assert parse_scales("1:4") == [1, 2, 3, 4]
    assert parse_scales("12, 20,28") == [12, 20, 28]


def test_installed_script_runs(tmp_path):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    proc = subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", "detect", str(src)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "92 sharp features" in proc.stdout  # 12 * 7 + 8 edge points
    assert proc.stderr == ""  # no progress bar when stderr is not a terminal


def test_detect_meshset_writes_quality_and_selection():
    vertices, faces = shapes.cube_grid_mesh(3)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32)))
    result = meshlab_sharp.detect_meshset(ms, colorize=True)
    expected = shapes.on_cube_edges(vertices)
    np.testing.assert_array_equal(result.mask, expected)
    m = ms.current_mesh()
    np.testing.assert_array_equal(m.vertex_selection_array(), expected)
    np.testing.assert_allclose(m.vertex_scalar_array(), result.strength)
    np.testing.assert_array_equal(m.vertex_matrix(), vertices)
    red = m.vertex_color_matrix()[:, 0] > 0.85
    np.testing.assert_array_equal(red & (m.vertex_color_matrix()[:, 1] < 0.2), expected)
    # A MeshLab filter can go on from the quality.
    ms.compute_selection_by_scalar_per_vertex(minq=0.5, maxq=1.0)
    assert ms.current_mesh().vertex_selection_array().sum() >= expected.sum()
    # Running twice on the same mesh works (pymeshlab cannot overwrite attributes).
    again = meshlab_sharp.detect_meshset(ms)
    np.testing.assert_array_equal(again.mask, expected)
    np.testing.assert_array_equal(ms.current_mesh().vertex_selection_array(), expected)


def test_detect_meshset_on_an_empty_meshset():
    with pytest.raises(meshlab_sharp.InputError, match="no mesh"):
        meshlab_sharp.detect_meshset(pymeshlab.MeshSet())
