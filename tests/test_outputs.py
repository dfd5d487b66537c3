"""What the outputs keep: the input's vertex properties in the PLY, LAS/LAZ output with
every LAS attribute, the feature colouring switched off; read back with pymeshlab,
laspy and the package's own PLY reader."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pymeshlab
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp.io.las import FEATURE_CLASS, STRENGTH_DIMENSION, write_las
from meshlab_sharp.io.ply import read_ply_properties

laspy = pytest.importorskip("laspy")


def _cli(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
        check=False,
    )


def _ply_with_attributes(path: Path, binary: bool) -> dict[str, np.ndarray]:
    """The cube cloud with normals, RGB and a float scalar field; returns the columns."""
    points = shapes.cube_grid_points(9)
    n = len(points)
    columns = {
        "x": points[:, 0].astype("f4"),
        "y": points[:, 1].astype("f4"),
        "z": points[:, 2].astype("f4"),
        "nx": np.zeros(n, "f4"),
        "ny": np.full(n, 0.6, "f4"),
        "nz": np.full(n, 0.8, "f4"),
        "red": (np.arange(n) % 256).astype("u1"),
        "green": np.full(n, 7, "u1"),
        "blue": (255 - np.arange(n) % 256).astype("u1"),
        "intensity": (np.arange(n) * 0.25).astype("f4"),
    }
    types = {"f4": "float", "u1": "uchar"}
    header = (
        f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\nelement vertex {n}\n"
        + "".join(f"property {types[v.dtype.str[1:]]} {k}\n" for k, v in columns.items())
        + "end_header\n"
    )
    table = np.empty(n, [(k, v.dtype.newbyteorder("<")) for k, v in columns.items()])
    for k, v in columns.items():
        table[k] = v
    with open(path, "wb") as fh:
        fh.write(header.encode())
        if binary:
            fh.write(table.tobytes())
        else:
            for row in table:
                fh.write((" ".join(repr(v.item()) for v in row) + "\n").encode())
    return columns


@pytest.mark.slow
@pytest.mark.parametrize("binary", [True, False])
def test_every_input_property_survives_and_no_colour_keeps_the_colours(tmp_path, binary):
    src = tmp_path / "scan.ply"
    columns = _ply_with_attributes(src, binary)
    before = src.read_bytes()
    coloured, plain = tmp_path / "coloured.ply", tmp_path / "plain.ply"
    assert _cli("detect", src, "-q", "-o", coloured, cwd=tmp_path).returncode == 0
    proc = _cli("detect", src, "-q", "-o", plain, "--no-colour", "--ascii", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert src.read_bytes() == before
    expected = meshlab_sharp.detect(np.column_stack([columns[a] for a in "xyz"]))
    for out in (coloured, plain):
        kept = read_ply_properties(out, str(out))
        for name in ("nx", "ny", "nz", "intensity"):
            np.testing.assert_array_equal(kept[name], columns[name])
            assert kept[name].dtype == columns[name].dtype
        np.testing.assert_array_equal(kept["quality"], expected.strength)
        np.testing.assert_array_equal(kept["flags"] & 0x20 > 0, expected.mask)
    plain_props = read_ply_properties(plain, "plain")
    for c in ("red", "green", "blue"):
        np.testing.assert_array_equal(plain_props[c], columns[c])
    assert "alpha" not in plain_props
    painted = read_ply_properties(coloured, "coloured")
    assert expected.mask.any()
    assert (painted["red"][expected.mask] == 229).all()
    assert (painted["green"][expected.mask] == 12).all()
    # MeshLab reads the kept normals and the selection
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(plain))
    mesh = ms.current_mesh()
    np.testing.assert_allclose(
        mesh.vertex_normal_matrix()[:, 1:], [[0.6, 0.8]] * len(mask_of(mesh))
    )
    np.testing.assert_array_equal(mask_of(mesh), expected.mask)


def mask_of(mesh: pymeshlab.Mesh) -> np.ndarray:
    """The vertex selection MeshLab read."""
    return mesh.vertex_selection_array()


def test_a_plain_input_gives_the_bytes_meshlab_writes(tmp_path):
    """No input property: the PLY is the one pymeshlab's writer makes (a mesh: 0x10
    only on the vertices no face uses)."""
    rng = np.random.default_rng(1)
    v = rng.random((10, 3))
    f = np.array([[0, 1, 2], [2, 3, 4]])
    s = np.linspace(0, 1, 10)
    m = np.arange(10) % 2 == 0
    for faces in (f, None):
        ours, theirs = tmp_path / "ours.ply", tmp_path / "theirs.ply"
        meshlab_sharp.save_features_ply(ours, v, faces, s, m)
        ms = meshlab_sharp.io.feature_meshset(v, faces, s, m)
        ms.save_current_mesh(
            str(theirs),
            binary=True,
            save_vertex_quality=True,
            save_vertex_flag=True,
            save_vertex_color=True,
            save_vertex_normal=False,
            save_face_color=False,
        )
        assert ours.read_bytes() == theirs.read_bytes()


def test_detect_meshset_colorize_false_keeps_the_colours():
    v, f = shapes.cube_grid_mesh(4)
    colours = np.tile([0.2, 0.4, 0.6, 1.0], (len(v), 1))
    for colorize in (False, True):
        ms = pymeshlab.MeshSet()
        ms.add_mesh(
            pymeshlab.Mesh(vertex_matrix=v, face_matrix=f.astype(np.int32), v_color_matrix=colours)
        )
        result = meshlab_sharp.detect_meshset(ms, colorize=colorize)
        got = ms.current_mesh().vertex_color_matrix()
        assert result.mask.any() and not result.mask.all()
        if colorize:
            np.testing.assert_allclose(
                got[result.mask][:, :3],
                [[230 / 255, 13 / 255, 13 / 255]] * int(result.mask.sum()),
                atol=1e-6,
            )
        else:
            np.testing.assert_allclose(got, colours, atol=1e-6)


def test_detect_meshset_colorize_paints_the_selection_red():
    """Robust mode thins candidates of strength 1 out of the selection: red is the
    selection, not the strength."""
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=shapes.box_cylinder_points(3000, seed=11)))
    result = meshlab_sharp.detect_meshset(ms, colorize=True)
    assert ((result.strength >= 1) & ~result.mask).sum() > 100  # thinned, strength 1
    colour = ms.current_mesh().vertex_color_matrix()
    red = (colour[:, 0] > 0.85) & (colour[:, 1] < 0.2) & (colour[:, 2] < 0.2)
    np.testing.assert_array_equal(red, result.mask)
    np.testing.assert_array_equal(ms.current_mesh().vertex_selection_array(), result.mask)


def _las_scan(src: Path) -> laspy.LasData:
    """The cube cloud as a LAS/LAZ scan (point format 3) with intensity, class 2, GPS
    time and 16-bit red; written to ``src``, returned as written."""
    points = shapes.cube_grid_points(9) * 10.0 + [500.0, 200.0, 30.0]
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.full(3, 1e-3)
    header.offsets = points.min(axis=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    n = len(points)
    las.intensity = np.arange(n, dtype=np.uint16) * 3
    las.classification = np.full(n, 2, np.uint8)
    las.gps_time = np.arange(n) * 0.5
    las.red = np.arange(n, dtype=np.uint16) * 100
    las.write(str(src))
    return las


@pytest.mark.slow
@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_output_keeps_every_point_and_attribute(tmp_path, suffix):
    src = tmp_path / f"scan{suffix}"
    las = _las_scan(src)
    n = len(las.points)
    before = src.read_bytes()
    out = tmp_path / f"features{suffix}"
    proc = _cli("detect", src, "-q", "-o", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert src.read_bytes() == before
    back = laspy.read(str(out))
    expected = meshlab_sharp.detect(np.column_stack([las.x, las.y, las.z]))
    assert len(back.points) == n
    np.testing.assert_array_equal(back.x, las.x)
    np.testing.assert_array_equal(back.intensity, las.intensity)
    np.testing.assert_array_equal(back.gps_time, las.gps_time)
    np.testing.assert_array_equal(back.red, las.red)
    features = np.asarray(back.classification) == FEATURE_CLASS
    np.testing.assert_array_equal(features, expected.mask)
    assert (np.asarray(back.classification)[~features] == 2).all()
    np.testing.assert_allclose(back[STRENGTH_DIMENSION], expected.strength, rtol=1e-6)


@pytest.mark.slow
def test_las_output_of_a_point_list_input(tmp_path):
    points = shapes.cube_grid_points(9)
    src = tmp_path / "c.xyz"
    np.savetxt(src, points)
    out = tmp_path / "c.las"
    assert _cli("detect", src, "-q", "-o", out, cwd=tmp_path).returncode == 0
    back = laspy.read(str(out))
    np.testing.assert_allclose(np.column_stack([back.x, back.y, back.z]), points, atol=1e-8)
    expected = meshlab_sharp.detect(points)
    np.testing.assert_array_equal(np.asarray(back.classification) == FEATURE_CLASS, expected.mask)
    # the LAS writer of the tests' inputs still writes what it did
    write_las(tmp_path / "plain.las", points)
    assert len(laspy.read(str(tmp_path / "plain.las")).points) == len(points)


def test_an_unknown_output_format_is_one_line(tmp_path):
    src = tmp_path / "c.xyz"
    np.savetxt(src, shapes.cube_grid_points(5))
    proc = _cli("detect", src, "-o", tmp_path / "c.e57x", cwd=tmp_path)
    assert proc.returncode == 1
    assert proc.stderr == (
        f"meshlab-sharp: error: {tmp_path / 'c.e57x'}: the output must be a .ply, .las or "
        ".laz file\n"
    )


def test_las_output_is_refused_out_of_core_before_any_work(tmp_path):
    src = tmp_path / "c.xyz"
    np.savetxt(src, shapes.cube_grid_points(5))
    proc = _cli("detect", src, "--max-memory", "1GB", "-o", tmp_path / "c.las", cwd=tmp_path)
    assert (proc.returncode, proc.stdout) == (1, "")
    assert proc.stderr == (
        "meshlab-sharp: error: a LAS/LAZ output is not available with --max-memory/--dask\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.xyz"]


def test_las_output_without_laspy_fails_before_any_work(tmp_path):
    """laspy hidden by a package of the same name that cannot be imported."""
    blocker = tmp_path / "site" / "laspy"
    blocker.mkdir(parents=True)
    (blocker / "__init__.py").write_text("raise ImportError('hidden for the test')\n")
    src = tmp_path / "c.xyz"
    np.savetxt(src, shapes.cube_grid_points(5))
    root = Path(__file__).resolve().parent.parent
    proc = subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", "detect", str(src), "-o", "c.laz"],
        env={**os.environ, "PYTHONPATH": f"{tmp_path / 'site'}{os.pathsep}{root}"},
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert (proc.returncode, proc.stdout) == (1, "")
    assert proc.stderr == (
        "meshlab-sharp: error: writing LAS/LAZ needs laspy: pip install 'meshlab-sharp[las]'\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.xyz", "site"]


def test_a_bad_extra_property_is_one_line_before_detection(tmp_path, capsys):
    from meshlab_sharp.cli import main

    src = tmp_path / "bad.ply"
    src.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nproperty uchar red\nend_header\n"
        "0 0 0 1\n1 0 0 300\n0 1 0 3\n0 0 1 4\n"
    )
    assert main(["detect", str(src), "-q"]) == 1
    assert capsys.readouterr().err == (
        f"meshlab-sharp: error: {src}: line 10: the vertex property 'red' is not a uint8 value\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.ply"]


def test_attributes_of_types_ply_lacks_are_written_in_one_it_has(tmp_path):
    out = tmp_path / "a.ply"
    labels = np.array([0, 1, 2**40, 3, 4], np.int64)
    meshlab_sharp.save_features_ply(
        out,
        np.eye(5, 3),
        None,
        np.zeros(5),
        np.zeros(5, bool),
        attributes={"label": labels, "ok": np.ones(5, bool), "half": np.full(5, 0.5, np.float16)},
    )
    kept = read_ply_properties(out, "a")
    np.testing.assert_array_equal(kept["label"], labels.astype(np.float64))
    assert kept["ok"].dtype == np.uint8 and kept["half"].dtype == np.float64
    assert list(kept) == [
        "label",
        "ok",
        "half",
        "flags",
        *("red", "green", "blue", "alpha"),
        "quality",
    ]


@pytest.mark.slow
def test_a_ply_output_of_a_las_input_keeps_its_attributes(tmp_path):
    src = tmp_path / "scan.laz"
    las = _las_scan(src)
    out = tmp_path / "scan_sharp.ply"
    assert _cli("detect", src, "-q", "--no-colour", cwd=tmp_path).returncode == 0
    kept = read_ply_properties(out, "out")
    np.testing.assert_array_equal(kept["intensity"], las.intensity)
    np.testing.assert_array_equal(kept["gps_time"], las.gps_time)
    np.testing.assert_array_equal(kept["classification"], las.classification)
    np.testing.assert_array_equal(kept["red"], (np.asarray(las.red) >> 8).astype(np.uint8))
    assert kept["red"].dtype == np.uint8 and "X" not in kept
    expected = meshlab_sharp.detect(np.column_stack([las.x, las.y, las.z]))
    np.testing.assert_array_equal(kept["flags"] & 0x20 > 0, expected.mask)
