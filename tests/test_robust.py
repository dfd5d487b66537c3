"""Robust mode (docs/method.md): the cases it exists for, on small parts."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapes

import meshlab_sharp
from evaluation import groundtruth as gt
from evaluation.scoring import evaluate
from meshlab_sharp import creases, robust
from meshlab_sharp.cli import main
from meshlab_sharp.neighbourhoods import Neighbourhood, knn
from meshlab_sharp.reference import detect as reference_sequence
from meshlab_sharp.reference import robust as reference_robust

N = 4000


@pytest.fixture(scope="module")
def cylinder():
    return gt.make_part("cylinder", n_points=N, seed=3)


def _f1(part, mask):
    spacing = part.extra.get("local_spacing", part.spacing)
    return evaluate(part.vertices, mask, part.edges, spacing)


def test_bad_mode_is_an_input_error():
    points = shapes.cube_grid_points(9)
    for bad in ("Robust", "fast", "", None, 1):
        with pytest.raises(meshlab_sharp.InputError, match="mode"):
            meshlab_sharp.detect(points, mode=bad)


def test_robust_is_the_default_and_the_report_names_the_mode():
    points = shapes.box_cylinder_points(1500, seed=2)
    default = meshlab_sharp.detect(points)
    robust = meshlab_sharp.detect(points, mode="robust")
    paper = meshlab_sharp.detect(points, mode="paper")
    assert meshlab_sharp.DEFAULT_MODE == "robust"
    np.testing.assert_array_equal(default.mask, robust.mask)
    np.testing.assert_array_equal(default.thresholds, robust.thresholds)
    assert default.mode == "robust" and default.summary()["options"]["mode"] == "robust"
    assert paper.summary()["options"]["mode"] == "paper"


@pytest.mark.parametrize("m", [15, 21])
def test_cube_grid_points_give_exactly_the_12_edges(m):
    points = shapes.cube_grid_points(m)
    result = meshlab_sharp.detect(points, mode="robust")
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(points))
    assert result.summary()["options"]["mode"] == "robust"


def test_cube_grid_mesh_gives_exactly_the_12_edges():
    vertices, faces = shapes.cube_grid_mesh(4)
    result = meshlab_sharp.detect(vertices, faces, mode="robust")
    assert result.kind == "mesh"
    np.testing.assert_array_equal(result.mask, shapes.on_cube_edges(vertices))


def test_outliers_robust_finds_the_edges_paper_does_not():
    # the cone: with these samples, paper mode's min-max range is taken by outliers
    part = gt.add_outliers(gt.make_part("cone", n_points=N, seed=3), 0.01, seed=1)
    paper = _f1(part, meshlab_sharp.detect(part.vertices, mode="paper").mask)
    result = meshlab_sharp.detect(part.vertices, mode="robust")
    scores = _f1(part, result.mask)
    assert paper.f1 < 0.2
    assert scores.f1 >= 0.9, scores
    # outliers near the surface or in pairs are not isolated (docs/method.md)
    assert result.mask[part.outliers].sum() <= 0.25 * part.outliers.sum()


def test_smooth_control_has_almost_no_features():
    part = gt.make_part("sphere", n_points=N, seed=1)
    paper = meshlab_sharp.detect(part.vertices, mode="paper")
    result = meshlab_sharp.detect(part.vertices, mode="robust")
    assert paper.mask.mean() > 0.1
    assert result.mask.mean() <= 0.01
    assert (result.thresholds >= robust.R_MIN).all()


def test_density_gradient():
    part = gt.density_gradient(gt.make_part("chamfered_box", n_points=N, seed=2), 4.0)
    scores = _f1(part, meshlab_sharp.detect(part.vertices, mode="robust").mask)
    assert scores.f1 >= 0.9, scores
    assert scores.thickness <= 1.3


def test_clean_part_is_thin_and_no_worse_than_paper(cylinder):
    paper = _f1(cylinder, meshlab_sharp.detect(cylinder.vertices).mask)
    scores = _f1(cylinder, meshlab_sharp.detect(cylinder.vertices, mode="robust").mask)
    assert scores.f1 >= paper.f1
    assert scores.f1 >= 0.95 and scores.thickness <= 1.3, scores


def test_mesh_input_uses_rings():
    part = gt.make_part("cylinder", "mesh", n_points=1500)
    result = meshlab_sharp.detect(part.vertices, part.faces, mode="robust")
    assert result.kind == "mesh" and result.scales == meshlab_sharp.DEFAULT_RING_SCALES
    scores = _f1(part, result.mask)
    assert scores.f1 >= 0.95, scores


@pytest.mark.parametrize("transform", ["rotation", "scale", "all"])
def test_rotation_and_scale_invariance(cylinder, transform):
    points = cylinder.vertices
    rot = shapes.random_rotation(5)
    moved = {
        "rotation": points @ rot.T,
        "scale": points * 7.25,
        "all": (points @ rot.T) * 0.04 + [-3.0, 8.0, 1.0],
    }[transform]
    ref = meshlab_sharp.detect(points, mode="robust")
    got = meshlab_sharp.detect(moved, mode="robust")
    differ = int((ref.mask != got.mask).sum())
    assert ref.n_features > 100
    # only round-off near a threshold or a tie in thinning may differ
    assert differ <= 0.01 * ref.n_features
    assert np.abs(ref.thresholds - got.thresholds).max() <= 1.0 / 256 + 1e-12


def test_isolated_points_and_return_details():
    points = np.vstack([shapes.cube_grid_points(11), [[5.0, 5.0, 5.0], [-4.0, 0.0, 9.0]]])
    result = meshlab_sharp.detect(points, mode="robust", return_details=True)
    assert not result.mask[-2:].any()
    assert np.isnan(result.distances[:, -2:]).all()
    finite = result.distances[:, :-2]
    assert (finite >= 0).all() and (finite <= 1).all()
    np.testing.assert_array_equal(result.mask[:-2], shapes.on_cube_edges(points[:-2]))


def test_cli_mode(tmp_path):
    points = shapes.cube_grid_points(11)
    src = tmp_path / "cube.xyz"
    np.savetxt(src, points)
    report = tmp_path / "r.json"
    out = tmp_path / "out.ply"
    code = main(
        ["detect", str(src), "-o", str(out), "--report", str(report), "--mode", "robust", "-q"]
    )
    assert code == 0
    data = json.loads(report.read_text())
    assert data["options"]["mode"] == "robust"
    assert data["n_features"] == int(shapes.on_cube_edges(points).sum())
    with pytest.raises(SystemExit):
        main(["detect", str(src), "--mode", "fast", "-q"])


# ---------------------------------------------------------------------------------
# Sharp mesh edges (meshlab_sharp.creases), support and thinning: each step pinned
# ---------------------------------------------------------------------------------


def test_cad_pipe_every_rim_vertex():
    # 160 vertices, all on sharp rims: thinning must not remove any of them
    verts, faces = shapes.pipe_mesh()
    result = meshlab_sharp.detect(verts, faces, mode="robust")
    assert result.mask.all() and (result.strength == 1.0).all()


def test_cad_polygon_facets_below_the_crease_angle_are_not_edges():
    # rims turn by 90 degrees (4 rings of n edges); the side facets of an n-gon turn by
    # 360 / n: 18.9 degrees for n = 19 (not sharp), 21.2 for n = 17 (2 n more edges)
    for n, sharp in ((24, 4 * 24), (19, 4 * 19), (17, 6 * 17)):
        _, angles = creases.dihedral_angles(*shapes.pipe_mesh(n))
        mask, threshold = creases.sharp_vertices(*shapes.pipe_mesh(n))
        assert threshold == math.radians(creases.CREASE_ANGLE)
        assert (angles > threshold).sum() == sharp
        assert mask.all()


@pytest.mark.parametrize(("angle", "sharp"), [(21.0, True), (19.0, False)])
def test_a_fold_is_sharp_just_above_the_crease_angle(angle, sharp):
    verts, faces, fold = shapes.fold_mesh(angle)
    result = meshlab_sharp.detect(verts, faces, mode="robust")
    if sharp:
        np.testing.assert_array_equal(result.mask, fold)
    else:
        assert not result.mask.any()


def test_dihedral_angles_of_a_box():
    verts, faces, _ = gt.reference_surface("box")
    edges, angles = creases.dihedral_angles(verts, faces)
    flat = len(edges) - 12  # 12 box edges, the others inside the triangulated faces
    np.testing.assert_allclose(np.sort(np.degrees(angles)), [0.0] * flat + [90.0] * 12, atol=1e-9)
    assert (edges[:, 0] < edges[:, 1]).all()


def test_crease_threshold_rises_with_the_lower_quartile():
    floor = math.radians(creases.CREASE_ANGLE)
    assert creases.crease_threshold(np.zeros(0)) == floor
    assert creases.crease_threshold(np.r_[np.zeros(3), np.full(9, 1.5)]) == floor
    # 9 angles: the lower quartile is element (9 - 1) // 4 = 2 of the sorted angles
    angles = np.radians([9.0, 1.0, 3.0, 2.0, 8.0, 7.0, 6.0, 5.0, 4.0])
    assert creases.crease_threshold(angles) == creases.NOISE_FACTOR * math.radians(3.0)
    assert creases.NOISE_FACTOR == 4.0 / 0.3186


@pytest.mark.parametrize("below", [0, 1, 2, 3, 4])
def test_crease_threshold_is_the_quartile_rule_when_the_floor_wins_early(below):
    """The shortcut (the floor wins when more than ``(e - 1) // 4`` angles a give
    ``NOISE_FACTOR * a <= floor``) returns what the sorted quartile gives, on either side
    of the count and with angles exactly at ``floor / NOISE_FACTOR``."""
    floor = math.radians(creases.CREASE_ANGLE)
    edge = floor / creases.NOISE_FACTOR
    rng = np.random.default_rng(below)
    angles = np.r_[np.full(below, edge), np.nextafter(edge, 1.0) + rng.random(9 - below) * 0.5]
    rng.shuffle(angles)
    quartile = np.sort(angles)[(len(angles) - 1) // 4]
    assert creases.crease_threshold(angles) == max(floor, creases.NOISE_FACTOR * quartile)


@pytest.mark.parametrize("zeros", [0, 1, 2, 3, 5, 9, 40])
def test_crease_threshold_with_the_zeros_left_out_is_the_threshold_with_them(zeros):
    """``crease_threshold(angles, zeros=z)`` (the compiled path leaves its flat edges'
    zero angles out) is the threshold of the angles with ``z`` zeros among them: the
    quartile among the zeros (the floor), just past them, or further; no angle but zeros;
    angles under the floor's edge (the shortcut) and NaN."""
    floor = math.radians(creases.CREASE_ANGLE)
    rng = np.random.default_rng(zeros)
    for angles in (
        rng.random(11) * 0.8,
        np.r_[np.full(4, floor / creases.NOISE_FACTOR), rng.random(7) * 0.5],
        np.r_[rng.random(6) * 0.9, np.nan],
        np.zeros(0),
    ):
        full = rng.permutation(np.r_[np.zeros(zeros), angles])
        expected = creases.crease_threshold(full)
        assert creases.crease_threshold(angles.copy(), zeros=zeros) == expected
    assert creases.crease_threshold(np.full(3, 0.7), zeros=0) == creases.NOISE_FACTOR * 0.7


def test_noisy_mesh_raises_the_threshold_and_still_finds_the_edges():
    part = gt.make_part("box", "mesh", n_points=1500)
    rng = np.random.default_rng(4)
    noisy = part.vertices + part.normals * rng.normal(0, 0.1 * part.spacing, part.n)[:, None]
    _, angles = creases.dihedral_angles(noisy, part.faces)
    assert creases.crease_threshold(angles) > math.radians(25.0)
    scores = _f1(part, meshlab_sharp.detect(noisy, part.faces, mode="robust").mask)
    assert scores.f1 >= 0.95, scores


def _csr(lists):
    indptr = np.r_[0, np.cumsum([len(x) for x in lists])].astype(np.int64)
    return Neighbourhood(indptr, np.concatenate(lists).astype(np.int64))


def test_line_directions_follow_the_features():
    pts = np.array([[0.0, 0, 0], [1, 0.1, 0], [2, 0, 0], [-1, -0.1, 0], [0, 5, 0]])
    mask = np.array([True, True, True, True, False])
    e = reference_robust.line_directions(pts, mask, _csr([list(range(5))] * 5))
    assert (e[4] == 0).all()
    np.testing.assert_allclose(np.abs(e[:4, 0]), 1.0, atol=0.01)


def test_supported_counts_other_features_along_the_line():
    # features on the x axis, one beside it (across the line of the others)
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [-1, 0, 0], [0, 1, 0], [0, 0, 3]])
    mask = np.array([True, True, True, True, True, False])
    e = np.tile([1.0, 0.0, 0.0], (6, 1))
    around = _csr([[0, 1, 3, 4, 5], [1, 0, 2], [2, 1], [3, 0], [4, 0, 1, 2, 3], [5, 0]])
    # 0: 1 and 3 along (4 across, 5 no feature); 1: 0 and 2; 2: only 1; 3: only 0;
    # 4: 1, 2 and 3 along (|cos| 0.71, 0.89, 0.71 >= 0.5), 0 across (|cos| 0)
    out = reference_robust.supported(pts, mask, e, around, 2)
    np.testing.assert_array_equal(out, [True, True, False, False, True, False])
    out = reference_robust.supported(pts, mask, e, around, 1)
    np.testing.assert_array_equal(out, [True, True, True, True, True, False])
    assert robust.SUPPORT_MIN == 2 and robust.SUPPORT_KNN == 16


@pytest.mark.parametrize(("cone_cos", "dropped"), [(0.5, True), (0.4, False)])
def test_thinning_cone(cone_cos, dropped):
    # features on the x axis and one stronger feature j at 63 degrees from it
    # (|cos| = 0.454): across the line for a 60-degree cone (0.5), along it for 0.4
    t = math.radians(63.0)
    pts = np.array(
        [
            [0.0, 0, 0],
            [1, 0, 0],
            [2, 0, 0],
            [-1, 0, 0],
            [-2, 0, 0],
            [0.3 * math.cos(t), 0.3 * math.sin(t), 0],
        ]
    )
    everyone = _csr([list(range(6))] * 6)
    e = reference_robust.line_directions(pts, np.ones(6, bool), everyone)
    score = np.array([0.5, 0.5, 0.5, 0.5, 0.5, 0.9])
    out = reference_robust.thin(
        pts, np.ones(6, bool), score, e, everyone, cone_cos=cone_cos, side=math.inf
    )
    assert out[0] == (not dropped)
    assert robust.THIN_CONE_COS == 0.5
    assert robust.THIN_KNN == 12 and robust.THIN_RING == 2


def test_noise_grows_the_scales():
    grid = shapes.flat_square(40)
    assert reference_sequence.noise_scale_factor(grid, knn(grid, 40), 7) == 1.0
    assert robust.NOISE_TOLERATED == 0.15 and robust.NOISE_KNN == 7
    clean = gt.make_part("box", n_points=N, seed=3)
    assert reference_sequence.noise_scale_factor(clean.vertices, knn(clean.vertices, 40), 7) == 1.0
    part = gt.add_noise(clean, 0.5, seed=1)
    f = reference_sequence.noise_scale_factor(part.vertices, knn(part.vertices, 40), 7)
    # median |d . n| / |d| is about 0.30 at 50 % noise on Poisson-disk samples: f ~ 4,
    # capped at 3
    assert f == robust.NOISE_MAX_FACTOR == 3.0
    result = meshlab_sharp.detect(part.vertices, mode="robust")
    defaults = meshlab_sharp.DEFAULT_KNN_SCALES
    assert result.scales == tuple(math.floor(k * f + 0.5) for k in defaults)
    assert meshlab_sharp.detect(part.vertices, mode="paper").scales == defaults


@pytest.mark.slow
def test_backends_agree_with_grown_scales():
    part = gt.add_noise(gt.make_part("fandisk", n_points=N, seed=1), 0.5, seed=2)
    compiled = meshlab_sharp.detect(part.vertices, mode="robust", backend="compiled")
    reference = meshlab_sharp.detect(part.vertices, mode="robust", backend="numpy")
    assert compiled.scales == reference.scales != meshlab_sharp.DEFAULT_KNN_SCALES
    np.testing.assert_array_equal(compiled.mask, reference.mask)
    np.testing.assert_array_equal(compiled.thresholds, reference.thresholds)
