"""Feature curves: known answers on a cube and a cylinder, invariance to the
input's order, the writers read back by pymeshlab and ezdxf, the MeshSet edge mesh, the
command line, and the curve scores."""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pymeshlab
import pytest
import shapes
from files import write_ply
from scipy.spatial import cKDTree

import meshlab_sharp
from evaluation import groundtruth as gt
from evaluation.scoring import evaluate_curves, truth_curves
from meshlab_sharp import _header
from meshlab_sharp.cli import main
from meshlab_sharp.curves import classify, extract_curves
from meshlab_sharp.errors import InputError, MeshlabSharpError
from meshlab_sharp.io import curve_arrays, require_ezdxf, save_curves
from meshlab_sharp.reference.curves.graph import nearest
from meshlab_sharp.reference.curves.refine import line_fit_positions
from meshlab_sharp.reference.curves.trace import Piece, join_pieces, piece_lengths

MODES = ("paper", "robust")
CUBE_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)


def _cube_checks(result, spacing):
    """12 straight curves along the cube's edges, each about 2 long, 8 corners at the
    cube's corners."""
    assert len(result.curves) == 12
    assert [c.kind for c in result.curves] == ["line"] * 12
    assert not any(c.closed for c in result.curves)
    for c in result.curves:
        d = np.abs(c.params["direction"])
        assert d.max() > 0.999  # along an axis
        assert abs(c.length - 2.0) < 3 * spacing
        # on an edge: two coordinates at +-1
        assert np.all(np.sum(np.abs(np.abs(c.points) - 1) < spacing, axis=1) >= 2)
    assert len(result.corners) == 8
    d = np.linalg.norm(result.corners.points[:, None] - CUBE_CORNERS[None], axis=2)
    assert np.all(d.min(axis=1) < spacing)
    assert sorted(d.argmin(axis=1)) == list(range(8))


@pytest.mark.parametrize("mode", MODES)
def test_cube_cloud_gives_12_lines_and_8_corners(mode):
    points = shapes.cube_grid_points(21)  # spacing 0.1
    result = meshlab_sharp.detect(points, mode=mode, curves=True)
    _cube_checks(result, 0.1)
    # every curve vertex came from a detected point
    for c in result.curves:
        assert result.mask[c.indices].all()


@pytest.mark.parametrize("mode", MODES)
def test_cube_mesh_curves_are_chains_of_mesh_edges(mode):
    vertices, faces = shapes.cube_grid_mesh(4)  # edge length 0.125
    result = meshlab_sharp.detect(vertices, faces, mode=mode, curves=True)
    _cube_checks(result, 0.125)
    edges = {tuple(sorted(e)) for f in faces for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    for c in result.curves:
        np.testing.assert_array_equal(c.points, vertices[c.indices])  # mesh vertices
        for a, b in c.segments:
            assert tuple(sorted((c.indices[a], c.indices[b]))) in edges
    np.testing.assert_array_equal(result.corners.points, vertices[result.corners.indices])
    assert np.abs(np.abs(result.corners.points) - 1).max() == 0.0  # exactly the corners


def test_sampled_box_cloud_gives_12_lines_and_8_corners():
    part = gt.make_part("box", n_points=6000, seed=3)
    result = meshlab_sharp.detect(part.vertices, mode="robust", curves=True)
    scores = evaluate_curves(result.curves, result.corners.points, part.edges, part.spacing)
    assert (scores.n_curves, scores.n_corners) == (12, 8)
    assert scores.corners_found == 1.0
    assert scores.precision > 0.99 and scores.coverage > 0.97
    assert scores.rms < 0.35  # below the spacing: refined onto the planes' intersection


@pytest.mark.parametrize(("n", "seed"), [(4000, 0), (8000, 2)])
def test_iid_box_cloud_gives_12_lines_and_8_corners(n, seed):
    """Points drawn independently on a 2 x 1.4 x 1 box: they cluster, the detected points
    along an edge leave gaps of several spacings, and the curves still run along each
    edge from corner to corner, one an edge, with the 8 corners at the box's."""
    points = shapes.random_box_points(n, seed=seed)
    spacing = 0.78 * np.sqrt(12.4 / n)  # blue noise's on this area: 0.043, 0.031
    result = meshlab_sharp.detect(points, mode="robust", curves=True)
    assert len(result.curves) == 12 and len(result.corners) == 8
    assert [c.kind for c in result.curves] == ["line"] * 12
    lengths = sorted(c.length for c in result.curves)
    np.testing.assert_allclose(lengths, [1.0] * 4 + [1.4] * 4 + [2.0] * 4, atol=2 * spacing)
    box = np.array([[x, y, z] for x in (-1, 1) for y in (-0.7, 0.7) for z in (-0.5, 0.5)])
    d = np.linalg.norm(result.corners.points[:, None] - box[None], axis=2)
    assert sorted(d.argmin(axis=1)) == list(range(8))
    assert d.min(axis=1).max() < 1.5 * spacing


def test_the_spacing_of_an_iid_cloud_follows_its_density():
    """The curves' spacing: on a Poisson-disk cloud the median nearest-neighbour
    distance d of the features (regular: DENSITY_SCALE times the median distance to the
    DENSITY_NEIGHBOURS-th nearest is below d); on an iid cloud of the same box, whose
    nearest distances are shorter (clustered points), that density term is q d with
    q > 1.3 and the spacing is d q^1.5, within 10 % of the Poisson-disk spacing."""
    from meshlab_sharp.reference.curves import extract as reference

    blue = gt.make_part("box", n_points=8000, seed=1)
    iid = shapes.random_box_points(8000, seed=2, size=(60.0, 40.0, 30.0))
    found = []
    for points in (blue.vertices.astype(np.float64), iid):
        mask = meshlab_sharp.detect(points).mask
        features = np.unique(points[mask], axis=0)
        d, _ = cKDTree(points).query(features, k=reference.DENSITY_NEIGHBOURS + 1)
        nearest, density = np.median(d[:, 1]), reference.DENSITY_SCALE * np.median(d[:, -1])
        found.append((*reference.cloud_spacing(cKDTree(points), features), nearest, density))
    (blue_s, blue_irregular, blue_near, blue_density), (iid_s, iid_irregular, near, density) = found
    assert (blue_s, blue_irregular) == (blue_near, False) and blue_density < blue_near
    assert iid_irregular and density > 1.3 * near
    assert iid_s == pytest.approx(near * (density / near) ** 1.5, rel=1e-12)
    assert abs(iid_s / blue_s - 1) < 0.1


@pytest.mark.parametrize(
    ("kind", "mode"), [("points", "robust"), ("points", "paper"), ("mesh", "robust")]
)
def test_cylinder_gives_two_closed_circles_of_its_radius(kind, mode):
    part = gt.make_part("cylinder", kind, n_points=6000 if kind == "points" else 3000, seed=2)
    result = meshlab_sharp.detect(part.vertices, part.faces, mode=mode, curves=True)
    assert len(result.curves) == 2
    assert len(result.corners) == 0
    heights = []
    for c in result.curves:
        assert c.kind == "arc" and c.closed
        assert abs(c.params["radius"] - 20.0) < 0.02 * 20.0
        assert abs(abs(c.params["normal"][2]) - 1.0) < 1e-3
        assert np.linalg.norm(c.params["centre"][:2]) < 0.1
        assert c.params["angle"] == 360.0
        heights.append(c.params["centre"][2])
    np.testing.assert_allclose(sorted(heights), [0.0, 40.0], atol=0.1)


@pytest.mark.parametrize("mode", MODES)
def test_curves_do_not_depend_on_the_order_of_the_points(mode):
    part = gt.make_part("box", n_points=6000, seed=3)
    order = np.random.default_rng(5).permutation(part.n)
    a = meshlab_sharp.detect(part.vertices, mode=mode, curves=True)
    b = meshlab_sharp.detect(part.vertices[order], mode=mode, curves=True)
    assert len(a.curves) == len(b.curves)
    for ca, cb in zip(a.curves, b.curves, strict=True):
        np.testing.assert_allclose(ca.points, cb.points, atol=1e-9)
        np.testing.assert_array_equal(ca.indices, order[cb.indices])
        assert (ca.kind, ca.closed) == (cb.kind, cb.closed)
    np.testing.assert_allclose(a.corners.points, b.corners.points, atol=1e-9)


def test_the_curves_of_a_thin_wall_stay_on_its_rims():
    """A tube whose wall is 3 spacings thick: the two arms fitted across a rim are
    often a face of the wall and the face beside the other rim, whose lines meet off the
    surface; the refinement does not move the curves there (MS_CURVE_WALL_GAP)."""
    part = gt.make_thin_part("tube", 3, n_points=3000)
    result = meshlab_sharp.detect(part.vertices, curves=True)
    assert result.curves is not None and result.corners is not None
    s = evaluate_curves(result.curves, result.corners.points, part.edges, part.spacing)
    assert s.precision >= 0.85


def test_curves_reach_the_corners_across_a_gap_in_the_detection():
    """Features missing within 6 spacings of every corner (the three ends 8.5 spacings
    apart): the ends' lines meet at the corner, which is found, and the curves run on
    to it."""
    points = shapes.cube_grid_points(21)  # spacing 0.1
    mask = meshlab_sharp.detect(points, mode="robust").mask
    gap = np.linalg.norm(points[:, None] - CUBE_CORNERS[None], axis=2).min(axis=1) < 0.6
    curves, corners = extract_curves(points, mask & ~gap)
    assert len(curves) == 12 and len(corners) == 8
    d = np.linalg.norm(corners.points[:, None] - CUBE_CORNERS[None], axis=2)
    assert sorted(d.argmin(axis=1)) == list(range(8))
    assert d.min(axis=1).max() < 0.05  # half a spacing
    for c in curves:
        assert abs(c.length - 2.0) < 0.1
        for end in (c.points[0], c.points[-1]):
            assert np.linalg.norm(CUBE_CORNERS - end, axis=1).min() < 0.05


def test_a_short_fragment_with_two_free_ends_is_dropped():
    """One edge of a cube (spacing 0.05, edges 40 spacings long) detected only over 6
    spacings in its middle, 17 spacings from the corners: that fragment is left out;
    the other 11 edges and the 8 corners stay."""
    points = shapes.cube_grid_points(41)
    mask = meshlab_sharp.detect(points, mode="robust").mask
    near_edge = (np.abs(points[:, 0] - 1) <= 0.125) & (np.abs(points[:, 1] - 1) <= 0.125)
    fragment = near_edge & (np.abs(points[:, 2]) <= 0.15)
    assert (mask & fragment).sum() >= 6
    curves, corners = extract_curves(points, mask & (~near_edge | fragment))
    assert len(curves) == 11 and len(corners) == 8
    assert min(c.length for c in curves) > 1.9


def test_collinear_pieces_with_bent_ends_are_joined():
    """Two pieces of one line whose last vertices bend 1.5 spacings off it, to opposite
    sides (3 spacings apart): their chords line up, so they are one curve; two parallel
    pieces 3 spacings apart stay two."""
    x = np.arange(0.0, 10.01, 0.5)

    def piece(xs: np.ndarray, y: float) -> Piece:
        p = np.stack([xs, np.full(len(xs), y), np.zeros(len(xs))], axis=1)
        return Piece(np.arange(len(p)), p)

    a, b = piece(x, 0.0), piece(x + 10.75, 0.0)
    a.points[-1, 1], b.points[0, 1] = 0.75, -0.75
    joined = join_pieces([a, b], 0.5)
    assert len(joined) == 1
    assert len(joined[0].points) == len(a.points) + len(b.points)
    assert len(join_pieces([piece(x, 0.0), piece(x + 10.75, 1.5)], 0.5)) == 2


def test_line_fits_of_many_curves_at_once():
    """Vertices on a straight line stay on it; each curve is fitted on its own vertices
    only (the same as alone); a loop of no more than ``half`` vertices is unchanged."""
    rng = np.random.default_rng(2)
    t = np.array([1.0, 2.0, 2.0]) / 3.0
    line = np.arange(12.0)[:, None] * t + np.array([0.5, -1.0, 2.0])
    wavy = rng.normal(size=(9, 3))
    tiny = rng.normal(size=(2, 3))
    points = np.concatenate([line, wavy, tiny])
    dirs = np.tile(t, (len(points), 1))
    sizes, closed = np.array([12, 9, 2]), np.array([False, True, True])
    out = line_fit_positions(points, dirs, sizes, closed, 2)
    np.testing.assert_allclose(out[:12], line, atol=1e-12)
    np.testing.assert_array_equal(out[21:], tiny)
    alone = line_fit_positions(wavy, dirs[:9], np.array([9]), np.array([True]), 2)
    np.testing.assert_array_equal(out[12:21], alone)
    # a loop's vertex 0: the mean of vertices 7, 8, 0, 1, 2, then onto the line along t
    mean = wavy[[7, 8, 0, 1, 2]].mean(axis=0)
    np.testing.assert_allclose(out[12], mean + ((wavy[0] - mean) @ t) * t, atol=1e-12)


def test_curves_are_opt_in_and_reported_in_the_summary():
    points = shapes.cube_grid_points(21)
    plain = meshlab_sharp.detect(points)
    assert plain.curves is None and plain.corners is None
    assert "curves" not in plain.summary() and "curves" not in plain.timings
    result = meshlab_sharp.detect(points, curves=True)
    summary = result.summary()["curves"]
    assert summary["n_curves"] == 12 and summary["n_corners"] == 8
    assert summary["kinds"] == {"line": 12}
    assert result.timings["curves"] >= 0


def test_nearest_orders_ties_by_index():
    """On a grid most neighbours lie at equal distances: the k nearest within the bound
    are those of a brute-force sort by (squared distance, index), whatever the kd-tree's
    own order (the plugin's order)."""
    points = shapes.cube_grid_points(7)
    queries = points[::5] + 0.01 * np.arange(3)
    for k, bound in [(9, 2.5 / 3), (40, np.inf), (3, 0.2)]:
        got = nearest(cKDTree(points), queries, k, bound)
        for q, row in zip(queries, got, strict=True):
            d2 = ((points - q) ** 2).sum(axis=1)
            order = np.lexsort((np.arange(len(points)), d2))
            expected = [i for i in order[:k] if d2[i] < bound**2]
            expected += [len(points)] * (k - len(expected))
            np.testing.assert_array_equal(row, expected)


def test_no_features_no_curves():
    result = meshlab_sharp.detect(shapes.flat_square(20), scales=[8, 12], curves=True)
    assert result.curves == [] and len(result.corners) == 0
    curves, corners = extract_curves(np.zeros((5, 3)), np.zeros(5, bool))
    assert curves == [] and corners.points.shape == (0, 3)


def test_classify_known_shapes():
    t = np.linspace(0, 1, 30)
    line = np.c_[t, 2 * t, np.zeros_like(t)]
    kind, p = classify(line, False, 0.01)
    assert kind == "line"
    np.testing.assert_allclose(p["direction"], np.array([1, 2, 0]) / np.sqrt(5), atol=1e-12)
    a = np.linspace(0, np.pi, 40)
    arc = np.c_[3 + 2 * np.cos(a), 1 + 2 * np.sin(a), np.full_like(a, 5.0)]
    kind, p = classify(arc, False, 0.01)
    assert kind == "arc"
    np.testing.assert_allclose(p["centre"], [3, 1, 5], atol=1e-9)
    assert abs(p["radius"] - 2) < 1e-9 and abs(p["angle"] - 180) < 1e-6
    np.testing.assert_allclose(p["normal"], [0, 0, 1], atol=1e-9)
    helix = np.c_[np.cos(3 * a), np.sin(3 * a), a]
    assert classify(helix, False, 0.01)[0] == "freeform"


# -- writers ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cube_curves():
    result = meshlab_sharp.detect(shapes.cube_grid_points(21), curves=True)
    return result.curves


def _loaded(path):
    """The MeshSet holding the file (a Mesh must not outlive its MeshSet)."""
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    return ms


@pytest.mark.parametrize("ext", [".ply", ".obj"])
def test_ply_and_obj_read_back_as_edge_meshes(tmp_path, cube_curves, ext):
    vertices, edges, _ = curve_arrays(cube_curves)
    path = save_curves(tmp_path / f"c{ext}", cube_curves)
    ms = _loaded(path)
    mesh = ms.current_mesh()
    assert mesh.vertex_number() == len(vertices)
    assert mesh.edge_number() == len(edges) == sum(len(c.points) - 1 for c in cube_curves)
    np.testing.assert_allclose(mesh.vertex_matrix(), vertices, atol=1e-6)
    np.testing.assert_array_equal(mesh.edge_matrix(), edges)
    assert [p.name for p in tmp_path.iterdir()] == [f"c{ext}"]  # no temporary left


def test_dxf_has_one_3d_polyline_per_curve(tmp_path):
    ezdxf = pytest.importorskip("ezdxf")
    part = gt.make_part("cylinder", "mesh", n_points=3000)
    result = meshlab_sharp.detect(part.vertices, part.faces, curves=True)
    cube = meshlab_sharp.detect(shapes.cube_grid_points(21), curves=True)
    curves = result.curves + cube.curves
    save_curves(tmp_path / "c.dxf", curves)
    doc = ezdxf.readfile(tmp_path / "c.dxf")
    entities = list(doc.modelspace())
    assert len(entities) == len(curves) == 14
    for e, c in zip(entities, curves, strict=True):
        assert e.dxftype() == "POLYLINE" and e.is_3d_polyline
        assert e.is_closed == c.closed
        assert e.dxf.layer == f"SHARP_{c.kind.upper()}"
        np.testing.assert_allclose([v.dxf.location for v in e.vertices], c.points, atol=1e-9)


def test_dxf_without_ezdxf_is_a_one_line_error(tmp_path, monkeypatch, cube_curves):
    monkeypatch.setitem(sys.modules, "ezdxf", None)  # import ezdxf now fails
    with pytest.raises(MeshlabSharpError, match=r"pip install 'meshlab-sharp\[dxf\]'"):
        require_ezdxf()
    with pytest.raises(MeshlabSharpError, match="needs ezdxf"):
        save_curves(tmp_path / "c.dxf", cube_curves)
    assert list(tmp_path.iterdir()) == []


def test_unknown_curve_format_is_refused(tmp_path, cube_curves):
    with pytest.raises(InputError, match=r"must end in \.ply, \.obj, \.dxf"):
        save_curves(tmp_path / "c.stl", cube_curves)


# -- pymeshlab ----------------------------------------------------------------------


def test_detect_meshset_adds_the_curves_as_an_edge_mesh():
    vertices, faces = shapes.cube_grid_mesh(3)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces), "cube")
    result = meshlab_sharp.detect_meshset(ms, curves=True)
    assert ms.mesh_number() == 2
    assert ms.current_mesh().face_number() == len(faces)  # the analysed mesh stays current
    added = ms.mesh(1)
    assert added.face_number() == 0
    assert added.edge_number() == sum(len(c.segments) for c in result.curves)
    np.testing.assert_array_equal(
        added.vertex_matrix(), np.concatenate([c.points for c in result.curves])
    )
    without = pymeshlab.MeshSet()
    without.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces))
    assert meshlab_sharp.detect_meshset(without).curves is None
    assert without.mesh_number() == 1


# -- command line -------------------------------------------------------------------


@pytest.mark.parametrize("ext", [".ply", ".obj", ".dxf"])
def test_cli_writes_curves(tmp_path, capsys, ext):
    if ext == ".dxf":
        pytest.importorskip("ezdxf")
    src = write_ply(tmp_path / "cube.ply", shapes.cube_grid_points(21))
    out = tmp_path / f"curves{ext}"
    assert main(["detect", str(src), "--curves", str(out)]) == 0
    assert "curves: 12 (12 line), 8 corners" in capsys.readouterr().out
    if ext == ".dxf":
        import ezdxf

        assert len(ezdxf.readfile(out).modelspace()) == 12
    else:
        assert _loaded(out).current_mesh().edge_number() == 12 * 20  # 21 grid points per edge
    hidden = [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert hidden == []


def test_cli_curves_checked_before_computation(tmp_path, capsys):
    absent = tmp_path / "absent.ply"  # the input does not exist: the outputs fail first
    missing = tmp_path / "missing"
    assert main(["detect", str(absent), "--curves", str(missing / "c.ply")]) == 1
    assert capsys.readouterr().err == (
        f"meshlab-sharp: error: cannot write {missing / 'c.ply'}: the folder {missing} "
        "does not exist\n"
    )
    assert main(["detect", str(absent), "--curves", str(tmp_path / "c.stl")]) == 1
    assert "must end in .ply, .obj, .dxf" in capsys.readouterr().err
    src = write_ply(tmp_path / "cube.ply", shapes.cube_grid_points(9))
    (tmp_path / "c.ply").write_text("old\n")
    assert main(["detect", str(src), "--curves", str(tmp_path / "c.ply")]) == 1
    assert capsys.readouterr().err.endswith("c.ply exists; use --force to overwrite it\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply", "cube.ply"]


def test_cli_curves_are_all_or_nothing_with_the_other_outputs(tmp_path, capsys):
    src = write_ply(tmp_path / "cube.ply", shapes.cube_grid_points(9))
    (tmp_path / "r.json").write_text("old\n")
    # the report exists: nothing is written, the curves neither
    code = main(
        [
            "detect",
            str(src),
            "--curves",
            str(tmp_path / "c.obj"),
            "--report",
            str(tmp_path / "r.json"),
        ]
    )
    assert code == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cube.ply", "r.json"]


# -- scores -------------------------------------------------------------------------


def test_truth_curves_and_perfect_scores_of_the_exact_edges():
    part = gt.make_part("box", n_points=2000)
    n, corners = truth_curves(part.edges)
    assert n == 12 and len(corners) == 8
    exact = [
        meshlab_sharp.curves.Curve(seg, np.zeros(2, np.int64), False, "line", {})
        for seg in part.edges
    ]
    s = evaluate_curves(exact, corners, part.edges, part.spacing)
    assert (s.precision, s.coverage, s.rms, s.count_ratio, s.corners_found) == (1, 1, 0, 1, 1)
    n, corners = truth_curves(gt.make_part("cylinder", n_points=2000).edges)
    assert n == 2 and len(corners) == 0


@pytest.mark.slow
def test_report_picture_draws_the_curves(tmp_path):
    pytest.importorskip("matplotlib")
    from meshlab_sharp.io import Geometry
    from meshlab_sharp.plot import save_report

    points = shapes.cube_grid_points(11)
    result = meshlab_sharp.detect(points, curves=True, return_details=True)
    path = save_report(tmp_path / "r.png", result, Geometry(points, None, "cube"), size=(400, 300))
    assert path.read_bytes().startswith(b"\x89PNG")


def test_piece_lengths_in_one_pass_match_each_piece() -> None:
    """Known lengths (a closed unit square counts its closing side, a lone vertex is 0),
    and the batch gives every piece exactly its own length, whatever its neighbours."""
    square = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    pieces = [
        Piece(np.arange(4), square, closed=True),
        Piece(np.arange(4), square),
        Piece(np.arange(1), square[:1]),
    ]
    assert piece_lengths(pieces).tolist() == [4.0, 3.0, 0.0]
    assert piece_lengths([]).shape == (0,)
    rng = np.random.default_rng(3)
    many = [
        Piece(np.arange(m), rng.normal(size=(m, 3)) * 10.0 ** rng.uniform(-3, 3), bool(m % 2))
        for m in rng.integers(1, 40, size=200)
    ]
    batch = piece_lengths(many)
    for pc, length in zip(many, batch, strict=True):
        p = np.vstack([pc.points, pc.points[:1]]) if pc.closed else pc.points
        assert length == pytest.approx(np.linalg.norm(np.diff(p, axis=0), axis=1).sum(), 1e-14)
        assert length == piece_lengths([pc])[0] == pc.length


#: The modules that read the curves' constants: the numpy reference's, and fit.py.
CURVE_MODULES = {
    name: Path(meshlab_sharp.reference.curves.__file__).with_name(f"{name}.py")
    for name in ("graph", "trace", "extract", "refine", "mesh")
} | {"fit": Path(meshlab_sharp.curves.__file__).with_name("fit.py")}
CURVES_CPP = sorted((Path(__file__).resolve().parent.parent / "native" / "src").glob("curves*.cpp"))
#: The constants the native library has no use for: it does not classify the curves
#: (fit.py).
PYTHON_ONLY = {"FIT_TOLERANCE", "FIT_MAX", "MAX_RADIUS_RATIO"}
#: curves.cpp's upper-case constants that tune nothing: pi, infinity, the C library's
#: math table, how many vertices share one call of the math functions, the least items
#: a thread takes and the largest dense cell grid (no result depends on them).
NOT_TUNING = {"PI", "INF", "C_MATH", "REFINE_BATCH", "MIN_BLOCK", "MAX_DENSE_CELLS"}


def test_the_curves_constants_are_typed_only_in_their_header():
    """Every upper-case name the curves modules assign is read from
    meshlab_sharp.h (``NAME = CURVES.<kind>("NAME")``) unless it holds no number
    (fit.KINDS), and every header constant is read by one of them; the native
    curves.cpp uses the header's ``MS_CURVE_`` macros and gives no upper-case constant
    a number of its own (only NOT_TUNING)."""
    read: dict[str, str] = {}
    for name, path in CURVE_MODULES.items():
        for node in ast.parse(path.read_text()).body:
            if not isinstance(node, ast.Assign | ast.AnnAssign) or node.value is None:
                continue
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                if not (isinstance(target, ast.Name) and target.id.isupper()):
                    continue
                value, where = node.value, f"{name}.py: {target.id}"
                if isinstance(value, ast.Call) and ast.unparse(value.func).startswith("CURVES."):
                    assert [ast.unparse(a) for a in value.args] == [repr(target.id)], where
                    assert target.id not in read, where
                else:  # no number of its own
                    numbers = [
                        n
                        for n in ast.walk(value)
                        if isinstance(n, ast.Constant) and type(n.value) in (int, float)
                    ]
                    assert not numbers, f"{where} = {ast.unparse(value)}"
                    continue
                read[target.id] = name
    assert set(read) == set(_header.CURVES.constants)

    text = "\n".join(path.read_text() for path in CURVES_CPP)
    typed = re.findall(
        r"^\s*(?:static\s+)?(?:constexpr|const)\s+[\w:<> ]+?\s"  # a type
        r"([A-Z][A-Z0-9_]*)(?:\[\])?\s*=\s*(.+);",
        text,
        re.MULTILINE,
    )
    for name, value in typed:
        assert name in NOT_TUNING or "MS_CURVE_" in value or "sizeof" in value, (name, value)
    assert not re.search(r"^\s*#\s*define\s", text, re.MULTILINE)
    used = set(re.findall(r"\bMS_CURVE_([A-Z0-9_]+)", text))
    header = _header.CURVES.path.read_text()
    via = {  # the constants the header's derived ones are made of
        part
        for name in used
        for part in re.findall(rf"^#define MS_CURVE_{name} .*?MS_CURVE_(\w+)", header, re.M)
    }
    assert used | via == set(_header.CURVES.constants) - PYTHON_ONLY
    for name in used - {"TURN_SCALES"}:  # the C++ spells no header name without its prefix
        assert not re.search(rf"(?<![\w]){name}(?!\w)", re.sub(r"//.*", "", text)), name


def test_the_curves_use_the_headers_values():
    """Known values (the curves' results were tuned with them), the derived ones as their
    definitions say, the same numbers in every module that names them, and in C++ (the
    header compiled with g++) the same values and the same integer or floating types as
    the Python parser reads."""
    from meshlab_sharp.curves import fit
    from meshlab_sharp.reference.curves import extract, graph, refine, trace

    c = _header.CURVES.constants
    assert (graph.LINK_NEIGHBOURS, graph.LINK_RADIUS, graph.PRUNE_ROUNDS) == (8, 2.5, 4)
    assert trace.TURN_SCALES == (1.0, 2.0, 4.0, 8.0)
    assert (trace.CORNER_TURN, trace.GAP_LENGTH, trace.LOOP_LENGTH) == (35.0, 4.0, 3.0)
    assert (refine.REFINE_NEIGHBOURS, refine.MIN_ARM_ANGLE, fit.FIT_TOLERANCE) == (40, 20.0, 0.5)
    assert extract.MIN_CURVE_LENGTH == trace.GAP_LENGTH == 4.0
    assert extract.SPUR_PIECE == trace.SHORTEST_CUT == 2 * trace.GAP_LENGTH == 8.0
    assert extract.RAW_TANGENT_WINDOW == 2 * trace.TANGENT_WINDOW == 4.0
    for module in (extract, fit, graph, refine, trace):
        for name, value in vars(module).items():
            if name in c:
                assert value == c[name] and type(value) is type(c[name]), (module, name)

    if shutil.which("g++") is None:
        pytest.skip("needs g++")
    lines = ["#include <cstdio>", "#include <initializer_list>", "#include <type_traits>"]
    lines += ['#include "meshlab_sharp.h"', "int main() {"]
    for name, value in c.items():
        if isinstance(value, tuple):
            lines.append(f"{{ for (auto x : MS_CURVE_{name})")
            lines.append(
                f'printf("{name} %d %.17g\\n", int(std::is_integral<decltype(x)>()), double(x)); }}'
            )
        else:
            lines.append(f"{{ const auto x = MS_CURVE_{name};")
            lines.append(
                f'printf("{name} %d %.17g\\n", int(std::is_integral<decltype(x)>()), double(x)); }}'
            )
    lines.append("}")
    with tempfile.TemporaryDirectory() as tmp:
        source, exe = Path(tmp) / "curves.cpp", Path(tmp) / "curves"
        source.write_text("\n".join(lines))
        include = _header.PATH.parent
        subprocess.run(["g++", "-std=c++14", f"-I{include}", source, "-o", exe], check=True)
        out = subprocess.run([exe], capture_output=True, text=True, check=True).stdout
    seen: dict[str, list] = {}
    for line in out.splitlines():
        name, integral, number = line.split()
        seen.setdefault(name, []).append((integral == "1", float(number)))
    for name, value in c.items():
        items = value if isinstance(value, tuple) else (value,)
        assert seen[name] == [(type(v) is int, float(v)) for v in items], name


def test_the_header_parser_reads_names_and_lists_of_reals():
    text = (
        "#define MS_CURVE_A 4.0\n#define MS_CURVE_B (2.0 * MS_CURVE_A)\n"
        "#define MS_CURVE_C MS_CURVE_A\n#define MS_CURVE_D {1.0, 0.5}\n#define MS_E 1\n"
    )
    assert _header.parse(text, "MS_CURVE_") == {"A": 4.0, "B": 8.0, "C": 4.0, "D": (1.0, 0.5)}
    for bad in ("(2.0 * MS_CURVE_Z)", "{1, 2.0}", "{}", "MS_E", "(2 * MS_CURVE_A)"):
        with pytest.raises(ValueError, match=r"_curves\.h: unsupported constant"):
            _header.parse(
                f"#define MS_CURVE_A 4.0\n#define MS_CURVE_X {bad}\n", "MS_CURVE_", "_curves.h"
            )
    with pytest.raises(TypeError, match=r"MS_CURVE_TURN_SCALES is .*, not tuple of int"):
        _header.CURVES.integers("TURN_SCALES")
    with pytest.raises(TypeError, match=r"MS_CURVE_LINK_NEIGHBOURS is 8, not float"):
        _header.CURVES.real("LINK_NEIGHBOURS")
