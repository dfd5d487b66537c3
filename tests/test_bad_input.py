"""Bad input gets a clear one-line error (or a documented result), never a traceback."""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import shapes
from files import write_ply, write_xyz

import meshlab_sharp
from meshlab_sharp.cli import main
from meshlab_sharp.io import atomic_write

CUBE = shapes.cube_grid_points(9)


def _nan_cube(value: float) -> np.ndarray:
    p = CUBE.copy()
    p[17, 1] = value
    return p


def _make(tmp: Path, case: str) -> Path:
    """Create the bad input ``case`` under ``tmp`` and return its path."""
    if case == "missing":
        return tmp / "nope.ply"
    if case == "empty-ply":
        return _touch(tmp / "empty.ply", b"")
    if case == "empty-xyz":
        return _touch(tmp / "empty.xyz", b"")
    if case == "whitespace-xyz":
        return _touch(tmp / "blank.xyz", b"\n\n  \n")
    if case in ("truncated-binary-ply", "truncated-ascii-ply"):
        full = write_ply(tmp / "full.ply", CUBE, binary=case.startswith("truncated-binary"))
        data = full.read_bytes()
        return _touch(tmp / "truncated.ply", data[: len(data) // 2])
    if case == "truncated-header-ply":
        return _touch(tmp / "hdr.ply", b"ply\nformat ascii 1.0\nelement vertex 3\n")
    if case.startswith("garbage-"):
        ext = case.split("-")[1]
        return _touch(tmp / f"garbage.{ext}", np.random.default_rng(0).bytes(4096))
    if case == "nan-ascii-ply":
        return write_ply(tmp / "nan.ply", _nan_cube(np.nan))
    if case == "inf-binary-ply":
        return write_ply(tmp / "inf.ply", _nan_cube(np.inf), binary=True)
    if case == "nan-binary-ply":
        return write_ply(tmp / "nanb.ply", _nan_cube(np.nan), binary=True)
    if case == "nan-xyz":
        return write_xyz(tmp / "nan.xyz", _nan_cube(np.nan))
    if case == "inf-obj":
        lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in _nan_cube(-np.inf).tolist()]
        return _touch(tmp / "inf.obj", ("\n".join(lines) + "\n").encode())
    if case == "too-few-points":
        return write_xyz(tmp / "few.xyz", CUBE[:30])
    if case == "all-identical":
        return write_xyz(tmp / "same.xyz", np.tile([[1.0, 2.0, 3.0]], (100, 1)))
    if case == "off-bad-face-index":
        return _touch(tmp / "bad.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    if case == "obj-bad-face-index":
        return _touch(tmp / "bad.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n")
    if case in HOSTILE:
        name, data = HOSTILE[case]
        return _touch(tmp / name, data)
    if case == "all-faces-degenerate":
        v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], float)
        return write_ply(tmp / "degenerate.ply", v, [[0, 1, 2], [1, 2, 3]])
    raise AssertionError(case)


def _touch(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _obj_grid(n: int) -> bytes:
    """An OBJ with n vertices and no faces."""
    return b"".join(b"v %d %d 0\n" % (i % 17, i // 17) for i in range(n))


_OFF_SQUARE = b"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n"
_PLY_HEAD = (
    b"ply\nformat %s 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
    b"property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n"
)
_SQUARE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype="<f4")


def _binary_ply(faces: list[list[int]], declared: int | None = None) -> bytes:
    head = _PLY_HEAD % (b"binary_little_endian", len(faces) if declared is None else declared)
    body = b"".join(bytes([len(f)]) + np.array(f, "<i4").tobytes() for f in faces)
    return head + _SQUARE.tobytes() + body


def _stl(corners: np.ndarray) -> bytes:
    """A binary STL of (t, 3, 3) corners."""
    tri = np.zeros(len(corners), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    tri["v"] = corners
    return bytes(80) + np.uint32(len(corners)).tobytes() + tri.tobytes()


_NAN_TRIANGLE = np.array(
    [[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 0], [np.nan, 1, 0], [1, 1, 0]]]
)

#: Hostile files that a lenient reader would crash on or read wrong: name, content.
HOSTILE = {
    "obj-index-far": ("far.obj", _obj_grid(200) + b"f 1 2 3\nf 1 2 99999\n"),
    "obj-index-far-tabs": ("tabs.obj", _obj_grid(200) + b"f\t1\t2\t99999\n"),
    "obj-index-far-polygon": ("poly.obj", _obj_grid(200) + b"f 1 2 3 4 5 6 7 8 9 99999 10\n"),
    "obj-index-zero": ("zero.obj", _obj_grid(200) + b"f 0 1 2\n"),
    "obj-index-negative-past-first": ("neg.obj", b"v 0 0 0\nv 1 0 0\nf -1 -2 -3\n"),
    "obj-two-corners": ("two.obj", _obj_grid(200) + b"f 1 2\n"),
    "obj-overflow": ("big.obj", _obj_grid(3) + b"v 1 1e400 0\n"),
    "off-count-mismatch": ("count.off", _OFF_SQUARE + b"3 0 1 2 3 0 1 2 3\n3 0 1 2\n"),
    "off-truncated-faces": ("trunc.off", _OFF_SQUARE + b"3 0 1 2\n"),
    "off-extra-faces": ("extra.off", _OFF_SQUARE + b"3 0 1 2\n3 1 3 2\n3 1 2 3\n"),
    "ply-two-index-face": ("two.ply", _binary_ply([[0, 1, 2], [1, 3]])),
    "ply-one-index-face-ascii": (
        "one.ply",
        _PLY_HEAD % (b"ascii", 2) + b"0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n1 3\n",
    ),
    "ply-count-smaller-binary": ("small.ply", _binary_ply([[0, 1, 2], [1, 3, 2]], declared=1)),
    "ply-count-smaller-ascii": (
        "small-ascii.ply",
        _PLY_HEAD % (b"ascii", 1) + b"0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n",
    ),
    "ply-huge-count": ("huge.ply", _binary_ply([[0, 1, 2]], declared=4_000_000_000)),
    "stl-nan-triangle": ("nan.stl", _stl(_NAN_TRIANGLE)),
    "stl-size-mismatch": ("size.stl", _stl(_NAN_TRIANGLE[:1])[:-7]),
    "xyz-hex": ("hex.xyz", b"1 2 3\n4 5 6\n7 8 0x1F\n"),
    "xyz-two-columns": ("two.xyz", b"1 2 3\n4 5\n"),
    "unsupported-format": ("part.step", b"ISO-10303-21;\n"),
}

ERRORS = {
    "obj-index-far": "line 202: face index 99999 points to a missing vertex (the file has 200",
    "obj-index-far-tabs": "line 201: face index 99999 points to a missing vertex",
    "obj-index-far-polygon": "line 201: face index 99999 points to a missing vertex",
    "obj-index-zero": "line 201: face index 0 is invalid (OBJ counts vertices from 1)",
    "obj-index-negative-past-first": "line 3: face index -3 counts back past the first vertex",
    "obj-two-corners": "line 201: a face needs at least 3 vertices, this one has 2",
    "obj-overflow": "line 4: non-finite coordinate 1e400 (overflows float64)",
    "off-count-mismatch": "line 7: the face declares 3 vertices but the line holds 8 numbers",
    "off-truncated-faces": "truncated OFF file: 1 of 2 faces",
    "off-extra-faces": "line 9: data after the last face",
    "ply-two-index-face": "face 1 has 2 vertex indices; a face needs at least 3",
    "ply-one-index-face-ascii": "face 1 (line 15) has 1 vertex indices",
    "ply-count-smaller-binary": "13 bytes of data after the last element",
    "ply-count-smaller-ascii": "line 15: 1 lines of data after the last element",
    "ply-huge-count": "the header's counts need at least 4000000048 bytes",
    "stl-nan-triangle": "triangle 1 has a non-finite coordinate",
    "stl-size-mismatch": "a binary STL with 1 triangles has 134 bytes, this file has 127",
    "xyz-hex": "line 3: '0x1F' is not a number",
    "xyz-two-columns": "line 2: two values; a point needs x y z",
    "unsupported-format": "unsupported format '.step'",
    "missing": "no such file",
    "empty-ply": "empty",
    "empty-xyz": "empty",
    "whitespace-xyz": "the file holds no points",
    "truncated-binary-ply": "truncated PLY file",
    "truncated-ascii-ply": "truncated PLY file",
    "truncated-header-ply": "truncated PLY header",
    "garbage-ply": "not a PLY file",
    "garbage-xyz": "not a text point list",
    "garbage-stl": "not a valid STL file",
    "garbage-obj": "not a text OBJ file",
    "nan-ascii-ply": "non-finite",
    "nan-binary-ply": "non-finite",
    "inf-binary-ply": "non-finite",
    "nan-xyz": "non-finite",
    "inf-obj": "non-finite",
    "too-few-points": "fewer than the largest scale",
    "all-identical": "identical",
    "off-bad-face-index": "face index 7 is outside the 3 vertices",
    "obj-bad-face-index": "line 5: face index 9 points to a missing vertex",
    "all-faces-degenerate": "zero area",
}


@pytest.mark.parametrize("case", sorted(ERRORS))
def test_api_raises_input_error(tmp_path, case):
    path = _make(tmp_path, case)
    with pytest.raises(meshlab_sharp.InputError, match=re.escape(ERRORS[case])):
        meshlab_sharp.detect(path)


@pytest.mark.parametrize("case", sorted(ERRORS))
def test_cli_prints_one_line_and_fails(tmp_path, case, capsys):
    path = _make(tmp_path, case)
    before = _digest(path)
    code = main(["detect", str(path), "-q"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.startswith("meshlab-sharp: error: ")
    assert ERRORS[case] in err
    assert err.count("\n") == 1
    assert _digest(path) == before
    assert not list(tmp_path.glob("*_sharp.ply"))
    assert not list(tmp_path.glob(".*part*"))


def test_real_script_gives_no_traceback(tmp_path):
    path = _make(tmp_path, "nan-binary-ply")
    proc = subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", "detect", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().startswith("meshlab-sharp: error:")


def test_plane_is_the_documented_no_features_result(tmp_path, capsys):
    path = write_ply(tmp_path / "plane.ply", shapes.flat_square(25) @ shapes.random_rotation(2).T)
    assert main(["detect", str(path), "--indices", str(tmp_path / "i.txt")]) == 0
    assert "0 sharp features" in capsys.readouterr().out
    assert (tmp_path / "i.txt").read_text() == ""


def test_mesh_without_faces_is_a_point_cloud(tmp_path):
    path = write_ply(tmp_path / "cloud.ply", CUBE, faces=None)
    result = meshlab_sharp.detect(path)
    assert result.kind == "points"
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(CUBE))


def test_array_inputs_are_validated():
    with pytest.raises(meshlab_sharp.InputError, match="shape"):
        meshlab_sharp.detect(np.zeros((10, 2)))
    with pytest.raises(meshlab_sharp.InputError, match="no points"):
        meshlab_sharp.detect(np.zeros((0, 3)))
    with pytest.raises(meshlab_sharp.InputError, match="non-finite"):
        meshlab_sharp.detect(_nan_cube(np.nan))
    with pytest.raises(meshlab_sharp.InputError, match="face indices"):
        meshlab_sharp.detect(CUBE, np.array([[0, 1, len(CUBE)]]))
    with pytest.raises(meshlab_sharp.InputError, match="weighting"):
        meshlab_sharp.detect(CUBE, weighting="cubic")
    with pytest.raises(meshlab_sharp.InputError, match=">= 2"):
        meshlab_sharp.detect(CUBE, scales=[0, 12])
    with pytest.raises(meshlab_sharp.InputError, match="integers"):
        meshlab_sharp.detect(CUBE, scales=["a"])


def test_bad_scales_on_the_command_line(tmp_path, capsys):
    path = write_xyz(tmp_path / "cube.xyz", CUBE)
    with pytest.raises(SystemExit) as exc:
        main(["detect", str(path), "--scales", "twelve"])
    assert exc.value.code == 1  # usage errors too: one line, status 1
    err = capsys.readouterr().err
    assert err.startswith("meshlab-sharp: error: argument --scales: invalid scales")
    assert err.count("\n") == 1


def test_atomic_write_leaves_nothing_when_interrupted(tmp_path):
    dest = tmp_path / "out.ply"

    def half_then_interrupt(tmp: str) -> None:
        Path(tmp).write_bytes(b"ply\nformat")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(dest, half_then_interrupt)
    assert os.listdir(tmp_path) == []


def _digest(path: Path) -> str | None:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.exists() else None


def test_a_file_name_with_a_newline_keeps_the_message_on_one_line(tmp_path, capsys):
    path = _touch(tmp_path / "two\nlines.xyz", b"1 2 0x1F\n")
    assert main(["detect", str(path), "-q"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "'0x1F' is not a number" in err
