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


def _pymeshlab_arrays(path):
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    m = ms.current_mesh()
    return m.vertex_matrix(), m.face_matrix()


@pytest.mark.parametrize(
    "ext, options",
    [
        ("ply", {"binary": True}),
        ("ply", {"binary": False}),
        ("obj", {}),
        ("off", {}),
        ("stl", {"binary": True}),
        ("stl", {"binary": False}),
    ],
)
def test_readers_agree_with_pymeshlab_on_valid_files(tmp_path, cube_mesh, ext, options):
    """The numpy readers give exactly what pymeshlab reads from a file pymeshlab wrote."""
    vertices, faces = cube_mesh
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32)))
    path = tmp_path / f"cube.{ext}"
    ms.save_current_mesh(str(path), **options)
    expected_v, expected_f = _pymeshlab_arrays(path)
    loaded = meshlab_sharp.load(path)
    np.testing.assert_array_equal(loaded.faces, expected_f)
    if ext == "stl" and not options["binary"]:  # ASCII STL: float32 text, parsed as float32
        np.testing.assert_allclose(loaded.vertices, expected_v, rtol=0, atol=1e-6)
    else:
        np.testing.assert_array_equal(loaded.vertices, expected_v)


def test_big_endian_ply(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]])
    head = (
        "ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty double x\n"
        "property double y\nproperty double z\nelement face 1\n"
        "property list uchar uint vertex_indices\nend_header\n"
    )
    body = v.astype(">f8").tobytes() + b"\x04" + np.array([0, 1, 3, 2], ">u4").tobytes()
    (tmp_path / "be.ply").write_bytes(head.encode() + body)
    loaded = meshlab_sharp.load(tmp_path / "be.ply")
    np.testing.assert_array_equal(loaded.vertices, v)
    np.testing.assert_array_equal(loaded.faces, [[0, 1, 3], [0, 3, 2]])  # a fan


def test_obj_relative_indices_polygons_and_slashes(tmp_path):
    text = (
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
        "f -4/1/1 -3/1/1 -2/1/1 -1/1/1\n"  # a quad, relative
        "v 2 0 0\nf 2//1 5//1 3//1\n"
    )
    (tmp_path / "m.obj").write_text(text)
    loaded = meshlab_sharp.load(tmp_path / "m.obj")
    assert len(loaded.vertices) == 5
    np.testing.assert_array_equal(loaded.faces, [[0, 1, 2], [0, 2, 3], [1, 4, 2]])


def test_off_faces_across_lines_and_colours(tmp_path):
    text = (
        "COFF\n# a comment\n4 2 0\n0 0 0 255 0 0 255\n1 0 0 255 0 0 255\n"
        "0 1 0 255 0 0 255\n1 1 0 255 0 0 255\n"
        "3 0\n 1 2\n"  # continues on the next line
        "3 1 3 2 0.5 0.5 0.5 1\n"  # a colour after the indices
    )
    (tmp_path / "m.off").write_text(text)
    loaded = meshlab_sharp.load(tmp_path / "m.off")
    np.testing.assert_array_equal(loaded.faces, [[0, 1, 2], [1, 3, 2]])


def test_leica_pts_with_intensity_and_colour(tmp_path):
    points = shapes.cube_grid_points(9)
    rows = "".join(f"{x} {y} {z} -1204 120 80 255\n" for x, y, z in points)
    (tmp_path / "scan.pts").write_text(f"{len(points)}\n{rows}")
    result = meshlab_sharp.detect(tmp_path / "scan.pts")
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(points))


def test_comma_separated_xyz_with_crlf_and_a_header_comment(tmp_path):
    points = shapes.cube_grid_points(9)
    rows = "".join(f"{x}, {y}, {z}\r\n" for x, y, z in points)
    (tmp_path / "scan.xyz").write_text("//X,Y,Z\r\n" + rows, newline="")
    loaded = meshlab_sharp.load(tmp_path / "scan.xyz")
    np.testing.assert_array_equal(loaded.vertices, points)


def test_a_huge_file_is_refused_from_its_head(tmp_path):
    """Checks that can fail early read a bounded head: a 1 GiB sparse file with a bad
    start (or a count its size cannot hold) is refused without reading it."""
    import tracemalloc

    cases = {
        "garbage.xyz": b"\x00\x01binary",
        "garbage.obj": b"\x7fELF",
        "huge.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 999999999999\n"
        b"property float x\nproperty float y\nproperty float z\nend_header\n",
        "wrong-size.stl": bytes(80) + np.uint32(7).tobytes(),
    }
    for name, head in cases.items():
        path = tmp_path / name
        with path.open("wb") as fh:
            fh.write(head)
            fh.truncate(1 << 30)
        tracemalloc.start()
        with pytest.raises(meshlab_sharp.InputError):
            meshlab_sharp.load(path)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < 8 << 20, (name, peak)


def test_point_list_with_old_mac_line_ends(tmp_path):
    points = shapes.cube_grid_points(5)
    (tmp_path / "cr.xyz").write_bytes("".join(f"{x} {y} {z}\r" for x, y, z in points).encode())
    np.testing.assert_array_equal(meshlab_sharp.load(tmp_path / "cr.xyz").vertices, points)


def test_decimals_are_parsed_exactly_as_python_does():
    """The numpy fast path for short decimals and the general parser agree with float()
    to the bit, signed zeros and 15-, 16- and 17-digit mantissas included."""
    from meshlab_sharp.io.text import numbers, tokenize

    rng = np.random.default_rng(3)
    words = ["0", "-0", "+0", "5.", ".5", "-.5", "123456789012345", "1234567890123456"]
    words += ["0.30000000000000004", "1e5", "-2.5E-3", "9" * 40, "0.1", "1e-320"]
    for _ in range(20000):
        digits = "".join(rng.choice(list("0123456789"), rng.integers(1, 19)))
        cut = int(rng.integers(0, len(digits) + 1))
        word = digits[:cut] + "." + digits[cut:] if digits[:cut] or digits[cut:] else digits
        words.append(str(rng.choice(["", "-", "+"])) + word)
    tokens = tokenize(" ".join(words).encode())
    parsed = numbers(tokens, np.arange(len(words)), np.float64, "test")
    expected = np.array([float(w) for w in words])
    np.testing.assert_array_equal(parsed.view(np.int64), expected.view(np.int64))
