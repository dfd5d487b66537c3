"""The report picture: a PNG that decodes, has the asked size and shows something."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from shapes import cube_grid_mesh, cube_grid_points

import meshlab_sharp
from meshlab_sharp import InputError, MeshlabSharpError
from meshlab_sharp.cli import main
from meshlab_sharp.io import Geometry

pytest.importorskip("matplotlib")
from matplotlib.image import imread

from meshlab_sharp.plot import require_matplotlib, save_report


def check_png(path, width, height):
    assert path.exists() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = imread(path)
    assert image.shape[:2] == (height, width)
    rgb = image[..., :3]
    assert rgb.std() > 0.05, "blank picture"
    red = (rgb[..., 0] > 0.7) & (rgb[..., 1] < 0.3) & (rgb[..., 2] < 0.3)
    assert red.sum() > 500, "features (red) are not visible"
    return image


def test_report_of_a_point_cloud(tmp_path):
    g = Geometry(cube_grid_points(21), None, "cube")
    result = meshlab_sharp.detect(g, return_details=True)
    out = save_report(tmp_path / "cube.png", result, g, size=(1000, 800))
    check_png(out, 1000, 800)
    assert not list(tmp_path.glob(".*part*")), "no temporary file left"


def test_report_of_a_mesh_with_preprocessing(tmp_path):
    v, f = cube_grid_mesh(4)
    result = meshlab_sharp.detect(
        v, f, return_details=True, preprocessing={"denoise": True, "simplify": 0.7}
    )
    check_png(save_report(tmp_path / "m.png", result), 1600, 1200)


def test_report_needs_details_and_png(tmp_path):
    g = Geometry(cube_grid_points(11), None, "cube")
    result = meshlab_sharp.detect(g)
    with pytest.raises(InputError, match="return_details"):
        save_report(tmp_path / "a.png", result, g)
    with pytest.raises(InputError, match="png"):
        save_report(tmp_path / "a.jpg", result, g)
    with pytest.raises(InputError, match="size"):
        save_report(tmp_path / "a.png", result, g, size=(10, 10))
    assert not any(tmp_path.iterdir())


def test_missing_matplotlib_is_a_one_line_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(MeshlabSharpError, match=r"pip install 'meshlab-sharp\[plot\]'"):
        require_matplotlib()


@pytest.mark.slow
def test_cli_plot_with_preprocessing(tmp_path, capsys):
    import pymeshlab

    points = np.vstack([cube_grid_points(31), [[3.0, 3.0, 3.0], [-3.0, 2.5, 0.0]]])
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=points))
    ms.save_current_mesh(str(tmp_path / "c.ply"), binary=True)
    png = tmp_path / "report.png"
    rc = main(["detect", str(tmp_path / "c.ply"), "-q", "--remove-outliers", "--plot", str(png)])
    assert rc == 0, capsys.readouterr().err
    check_png(png, 1600, 1200)
