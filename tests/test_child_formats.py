"""The other formats MeshLab reads go through pymeshlab in a child process: same
geometry as the file holds, and a malformed file is a one-line error, never a crash."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pymeshlab
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp.errors import InputError
from meshlab_sharp.io import load


@pytest.mark.parametrize("ext", [".wrl", ".x3d", ".dae", ".3ds"])
def test_formats_pymeshlab_writes_load_back_with_the_12_edges(tmp_path, ext):
    vertices, faces = shapes.cube_grid_mesh(3)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces))
    path = tmp_path / f"cube{ext}"
    ms.save_current_mesh(str(path))
    geometry = load(path)
    assert geometry.vertices.shape == vertices.shape
    assert geometry.faces is not None and geometry.faces.shape == faces.shape
    result = meshlab_sharp.detect(path, mode="paper")
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(geometry.vertices, tol=1e-6))


def test_bad_face_index_in_x3d_is_an_input_error(tmp_path):
    path = tmp_path / "bad.x3d"
    path.write_text(
        "<X3D><Scene><Shape><IndexedFaceSet coordIndex='0 1 99 -1'>"
        "<Coordinate point='0 0 0 1 0 0'/></IndexedFaceSet></Shape></Scene></X3D>"
    )
    with pytest.raises(InputError, match=r"bad\.x3d: cannot read the file"):
        load(path)


def test_garbage_collada_is_one_line_from_the_cli(tmp_path):
    path = tmp_path / "garbage.dae"
    path.write_bytes(b"\x00\x01 not a COLLADA file")
    proc = subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", "detect", str(path), "-q"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("meshlab-sharp: error:"), proc.stderr
    assert not list(tmp_path.glob("*_sharp*"))
