"""Readers refuse what they cannot read faithfully, and say the same in every path.

A file read "successfully" but differently from what it holds is worse than an error:
duplicate PLY properties, list properties on vertices, counts that disagree with the
data (in memory and out of core alike), decimal commas in point lists, a mesh sample
sent out of core, a truncated 3DS file. PLY triangle strips are read as MeshLab reads
them (checked against pymeshlab), and refused where MeshLab refuses or would read
outside its vertices.
"""

from __future__ import annotations

import re
import struct
import warnings
from pathlib import Path

import malformed
import numpy as np
import pymeshlab
import pytest
import shapes
from files import write_ply
from test_output_claims import one_error_line, run_detect

import meshlab_sharp
from meshlab_sharp.cli import main
from meshlab_sharp.errors import InputError, InputWarning
from meshlab_sharp.io import load
from meshlab_sharp.io.stream import open_points

MESH = shapes.cube_grid_mesh(3)
CLOUD = shapes.cube_grid_points(9)
FORMATS = ["ascii", "binary_little_endian", "binary_big_endian"]


def _streamed(path: Path, *, as_points: bool = False) -> np.ndarray:
    """Every point of ``path`` read as the out-of-core path reads it."""
    source = open_points(path, as_points=as_points)
    return np.concatenate(list(source.blocks(1000)))


# ---------------------------------------------------------------- PLY header


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_property_declared_twice_is_refused(tmp_path, fmt):
    v, f = MESH
    data = malformed.ply(np.c_[v, v[:, 0] + 1], f, fmt)
    path = tmp_path / "twice.ply"
    path.write_bytes(data.replace(b"property float z\n", b"property float z\nproperty float x\n"))
    message = "the PLY header declares property 'x' of element 'vertex' twice"
    with pytest.raises(InputError, match=message):
        load(path)
    if fmt != "ascii":
        with pytest.raises(InputError, match=message):
            open_points(path, as_points=True)


def test_an_element_declared_twice_is_refused(tmp_path):
    v, _ = MESH
    once = malformed.ply(v, None, "binary_little_endian")
    head, body = once.split(b"end_header\n")
    vertex = head[head.index(b"element vertex") : head.index(b"element face")]
    path = tmp_path / "twice.ply"
    path.write_bytes(head + vertex + b"end_header\n" + body + v.astype("<f4").tobytes())
    with pytest.raises(InputError, match="declares element 'vertex' twice"):
        load(path)


#: Triangle strips with restarts (-1) at odd and even places, a list too short for a
#: triangle, a -1 stepped over (MeshLab reads it so).
STRIPS = [
    [0, 1, 2, 3, 4, 5, -1, 6, 7, 8, 9, -1, 10, 11, 12],
    [13, 14, 15, 16, -1, 17, 18, 19, 20, 21, 22],
    [1, 2],
    [4, 5, -1, 6, 7, 8, 9],
    [0, 1, -1, 3, 4, 5, 6, -1],
    [0, -1, -1, 3, 4, 5],
]


def _strips_ply(fmt: str, strips: list[list[int]]) -> bytes:
    v = np.random.default_rng(1).random((30, 3))
    head = (
        f"ply\nformat {fmt} 1.0\nelement vertex {len(v)}\nproperty double x\n"
        "property double y\nproperty double z\n"
        f"element tristrips {len(strips)}\nproperty list int int vertex_indices\nend_header\n"
    ).encode()
    if fmt == "ascii":
        rows = [b" ".join(b"%r" % float(c) for c in p) for p in v]
        rows += [b" ".join(b"%d" % x for x in [len(s), *s]) for s in strips]
        return head + b"\n".join(rows) + b"\n"
    e = "<" if fmt == "binary_little_endian" else ">"
    lists = b"".join(struct.pack(f"{e}i{len(s)}i", len(s), *s) for s in strips)
    return head + v.astype(e + "f8").tobytes() + lists


@pytest.mark.parametrize("fmt", FORMATS)
def test_triangle_strips_are_read_as_meshlab_reads_them(tmp_path, fmt):
    path = tmp_path / "strips.ply"
    path.write_bytes(_strips_ply(fmt, STRIPS))
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    faces = load(path).faces
    assert faces is not None and len(faces) == 18
    np.testing.assert_array_equal(faces, ms.current_mesh().face_matrix())
    assert faces[:3].tolist() == [[0, 1, 2], [2, 1, 3], [2, 3, 4]]  # every second one swapped
    assert faces[4].tolist() == [6, 7, 8]  # a strip starts unswapped after a -1


@pytest.mark.parametrize(
    ("strip", "bad"), [([0, 1, 2, -1, -1, 3, 4], -1), ([-1, 0, 1, 2], -1), ([30, 1, 2], 30)]
)
def test_triangle_strips_meshlab_refuses_are_refused(tmp_path, strip, bad):
    path = tmp_path / "strips.ply"
    path.write_bytes(_strips_ply("ascii", [[0, 1, 2], strip]))
    with pytest.raises(pymeshlab.PyMeshLabException, match="Bad vertex index"):
        pymeshlab.MeshSet().load_new_mesh(str(path))
    message = f"tristrips item 1 (line 41) has vertex index {bad} where a triangle needs one"
    with pytest.raises(InputError, match=re.escape(message)):
        load(path)


@pytest.mark.parametrize(("strip", "bad"), [([0, -1, 2, 3], -1), ([0, 1, 30], 30)])
def test_what_meshlab_would_read_outside_its_vertices_is_refused(tmp_path, strip, bad):
    """MeshLab checks only a triangle's first corner: it reads vertex -1 or 30 outside
    its array (pymeshlab crashes on the second file). Refused here."""
    path = tmp_path / "strips.ply"
    path.write_bytes(_strips_ply("binary_little_endian", [strip]))
    with pytest.raises(InputError, match=f"tristrips item 0 has vertex index {bad} where"):
        load(path)


# ---------------------------------------------------------------- list properties


@pytest.mark.parametrize("fmt", FORMATS)
def test_list_properties_of_vertices_are_skipped(tmp_path, fmt):
    v, f = MESH
    path = tmp_path / "lists.ply"
    path.write_bytes(malformed.vertex_list_ply(v, f, fmt))
    geometry = load(path)
    np.testing.assert_array_equal(geometry.vertices[:, :2], v[:, :2].astype(np.float32))
    np.testing.assert_array_equal(geometry.vertices[:, 2], v[:, 2])
    np.testing.assert_array_equal(geometry.faces, f)
    # the same file without the lists gives the same detection
    plain = write_ply(tmp_path / "plain.ply", geometry.vertices, f, binary=True)
    np.testing.assert_array_equal(meshlab_sharp.detect(path).mask, meshlab_sharp.detect(plain).mask)


@pytest.mark.slow
def test_a_binary_vertex_list_runs_from_the_command_line_and_out_of_core(tmp_path):
    v, f = MESH
    path = tmp_path / "lists.ply"
    path.write_bytes(malformed.vertex_list_ply(v, f, "binary_little_endian"))
    proc = run_detect(
        path, "-q", "--as-points", "--scales", "12,16", "--indices", tmp_path / "a.txt"
    )
    assert (proc.returncode, proc.stderr) == (0, "")
    proc = run_detect(
        path, "-q", "--as-points", "--scales", "12,16", "--indices", tmp_path / "b.txt",
        "-o", tmp_path / "b.ply", "--max-memory", "1GB",
    )  # fmt: skip
    assert (proc.returncode, proc.stderr) == (0, "")
    assert (tmp_path / "a.txt").read_text() == (tmp_path / "b.txt").read_text() != ""
    np.testing.assert_array_equal(_streamed(path, as_points=True), load(path).vertices)


# ---------------------------------------------------------------- counts


def _binary_cloud(tmp_path: Path, name: str, declared: int, extra: bytes = b"") -> Path:
    data = malformed.ply(CLOUD, None, "binary_little_endian")
    data = data.replace(b"vertex %d\n" % len(CLOUD), b"vertex %d\n" % declared)
    path = tmp_path / name
    path.write_bytes(data + extra)
    return path


@pytest.mark.parametrize(
    ("declared", "extra", "message"),
    [
        (len(CLOUD) + 1, b"", "truncated PLY file: the header's counts need at least"),
        (len(CLOUD) - 1, b"", "12 bytes of data after the last element"),
        (len(CLOUD), b"\0" * 5, "5 bytes of data after the last element"),
    ],
)
def test_a_ply_count_mismatch_is_the_same_error_in_memory_and_out_of_core(
    tmp_path, declared, extra, message
):
    path = _binary_cloud(tmp_path, "c.ply", declared, extra)
    with pytest.raises(InputError, match=message) as in_memory:
        load(path)
    with pytest.raises(InputError) as streamed:
        _streamed(path)
    assert str(streamed.value) == str(in_memory.value)


def test_a_ply_count_mismatch_after_the_faces_is_refused_out_of_core_too(tmp_path):
    v, f = MESH
    path = tmp_path / "m.ply"
    path.write_bytes(malformed.ply(v, f, "binary_little_endian") + b"\0" * 3)
    with pytest.raises(InputError, match="3 bytes of data after the last element") as in_memory:
        load(path, as_points=True)
    with pytest.raises(InputError) as streamed:
        _streamed(path, as_points=True)
    assert str(streamed.value) == str(in_memory.value)


@pytest.mark.slow
def test_the_command_line_says_the_same_in_memory_and_out_of_core(tmp_path):
    path = _binary_cloud(tmp_path, "c.ply", len(CLOUD) - 3)
    in_memory = one_error_line(run_detect(path, "-q"))
    assert "36 bytes of data after the last element" in in_memory
    assert one_error_line(run_detect(path, "-q", "--max-memory", "1GB")) == in_memory


@pytest.mark.slow
@pytest.mark.parametrize("delta", [10, -10])
def test_a_las_count_mismatch_is_the_same_in_memory_and_out_of_core(tmp_path, delta):
    pytest.importorskip("laspy")
    from meshlab_sharp.io.las import write_las

    path = tmp_path / "c.las"
    write_las(path, CLOUD)
    data = bytearray(path.read_bytes())
    (n,) = struct.unpack_from("<I", data, 107)  # LAS 1.2: number of point records
    assert n == len(CLOUD)
    struct.pack_into("<I", data, 107, n + delta)
    path.write_bytes(bytes(data))
    if delta > 0:
        message = (
            f"c.las: the file is truncated: the header announces {n + delta} points of 20 "
            f"bytes, {n} are in the file"
        )
    else:
        message = (
            f"c.las: {-delta * 20} bytes of point records after the {n + delta} points the "
            "header counts"
        )
    with pytest.raises(InputError, match=re.escape(message)):
        load(path)
    with pytest.raises(InputError, match=re.escape(message)):
        _streamed(path)
    assert one_error_line(run_detect(path, "-q", "--max-memory", "1GB")) == one_error_line(
        run_detect(path, "-q")
    )


# ---------------------------------------------------------------- point lists


@pytest.mark.parametrize(
    ("text", "read_as", "warning"),
    [
        (b"6,370;2,698;0,410", (6, 370, 2), "'6,370;2,698;0,410' looks like numbers with decimal"),
        (b"6,370 2,698 0,410 7,1", (6, 370, 2), "'6,370 2,698 0,410 7,1' looks like numbers"),
        (b"1,000.0 2.5 3.5", (1, 0, 2.5), "'1,000.0' looks like a number with thousands"),
        (b"1.5;-12,345,678.25;2", (1.5, -12, 345), "'-12,345,678.25' looks like a number with"),
    ],
)
def test_decimal_commas_and_thousands_separators_are_warned_about(tmp_path, text, read_as, warning):
    path = tmp_path / "p.xyz"
    path.write_bytes(malformed.point_list(CLOUD) + text + b"\n")
    line = len(CLOUD) + 1
    with pytest.warns(InputWarning, match=re.escape(f"p.xyz: line {line}: {warning}")):
        geometry = load(path)
    np.testing.assert_array_equal(geometry.vertices[-1], read_as)  # what the warning is for
    proc = run_detect(path, "-q")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.startswith(f"meshlab-sharp: warning: {path}: line {line}: {warning}")
    assert len(proc.stderr.splitlines()) == 1


@pytest.mark.parametrize(
    "text", [b"1.5,2.5,3.5", b"1,2,3", b"1;2;3", b"1.5 2.5 3.5 100,200", b"0,100.5,3"]
)
def test_ordinary_separators_give_no_warning(tmp_path, text):
    path = tmp_path / "p.xyz"
    path.write_bytes(malformed.point_list(CLOUD) + text + b"\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(load(path).vertices) == len(CLOUD) + 1


# ---------------------------------------------------------------- sample, 3DS


def test_the_mesh_sample_out_of_core_is_refused_like_a_mesh_file(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["detect", "--sample", "mesh", "--max-memory", "1GB"]) == 1
    assert capsys.readouterr().err == (
        "meshlab-sharp: error: sample part (mesh): a mesh; out-of-core detection "
        "(--max-memory, --dask) handles point clouds only: add --as-points, or run without "
        "--max-memory\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert list((tmp_path / "out").iterdir()) == []


def _cube_3ds(path: Path) -> bytes:
    v, f = MESH
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f))
    ms.save_current_mesh(str(path))
    return path.read_bytes()


def test_a_truncated_3ds_file_is_refused(tmp_path):
    data = _cube_3ds(tmp_path / "cube.3ds")
    assert load(tmp_path / "cube.3ds").faces.shape == MESH[1].shape
    cut = tmp_path / "cut.3ds"
    for end in range(1, len(data), 97):
        cut.write_bytes(data[:end])
        with pytest.raises(InputError, match=r"cut\.3ds: truncated 3DS file"):
            load(cut)


def test_a_3ds_vertex_count_beyond_its_chunk_is_refused(tmp_path):
    data = bytearray(_cube_3ds(tmp_path / "cube.3ds"))
    at = data.index(struct.pack("<H", 0x4110)) + 6
    struct.pack_into("<H", data, at, struct.unpack_from("<H", data, at)[0] + 1)
    path = tmp_path / "more.3ds"
    path.write_bytes(bytes(data))
    assert one_error_line(run_detect(path, "-q")) == (
        f"meshlab-sharp: error: {path}: truncated 3DS file: chunk 0x4110 at byte {at - 6} "
        "holds fewer items than its count"
    )
