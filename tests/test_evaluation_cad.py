"""The CAD evaluation: B-rep truth through gmsh/OpenCASCADE, inputs, scores."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial import cKDTree

gmsh = pytest.importorskip("gmsh")

from evaluation.cad.inputs import _seen_pieces, gmsh_mesh, make_inputs  # noqa: E402
from evaluation.cad.run import (  # noqa: E402
    classify,
    curve_scores,
    evaluate_part,
    seen_corners,
)
from evaluation.cad.sources import PARTS  # noqa: E402
from evaluation.cad.truth import brep_truth, closest_gap  # noqa: E402


@pytest.fixture
def occ():
    """gmsh initialized with an empty OpenCASCADE model; finalized after the test."""
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("test")
    yield gmsh.model.occ
    gmsh.finalize()


def _box(occ, dx: float = 1.0, dy: float = 2.0, dz: float = 3.0) -> int:
    tag = occ.addBox(0, 0, 0, dx, dy, dz)
    occ.synchronize()
    return tag


def test_box_has_12_sharp_curves_and_8_corners(occ):
    _box(occ)
    truth = brep_truth()
    assert len(truth.sharp_curves) == 12
    assert truth.edge_length == pytest.approx(4 * (1 + 2 + 3), rel=1e-9)
    corners = {tuple(np.round(c, 9)) for c in truth.corners}
    assert corners == {(x, y, z) for x in (0, 1) for y in (0, 2) for z in (0, 3)}
    assert all(a == pytest.approx(90) and b == pytest.approx(90) for a, b in truth.angles.values())
    assert truth.ambiguous_angles() == []


def test_cylinder_has_two_circles_and_no_corner(occ):
    occ.addCylinder(0, 0, 0, 0, 0, 2, 1)
    occ.synchronize()
    truth = brep_truth()
    # three curves: two circles and the seam, whose only face is the side
    assert len(gmsh.model.getEntities(1)) == 3
    assert len(truth.sharp_curves) == 2
    assert len(truth.corners) == 0
    assert truth.edge_length == pytest.approx(4 * math.pi, rel=1e-3)
    z = truth.segments[..., 2]
    assert set(np.round(np.unique(z), 9)) == {0.0, 2.0}
    r = np.linalg.norm(truth.segments[..., :2], axis=-1)
    assert np.allclose(r, 1.0)


def test_fillet_edges_are_not_sharp(occ):
    box = _box(occ, 2, 2, 1)
    # the 4 vertical edges are the box's only edges of length 1
    vertical = [c for _, c in gmsh.model.getEntities(1) if abs(occ.getMass(1, c) - 1.0) < 1e-9]
    assert len(vertical) == 4
    occ.fillet([box], vertical, [0.3])
    occ.synchronize()
    truth = brep_truth()
    # top and bottom outlines: 4 lines and 4 quarter circles each; the lines where a
    # fillet meets a side are tangent, so not sharp; no vertex has 3 sharp curves
    assert len(truth.sharp_curves) == 16
    assert len(truth.corners) == 0
    assert set(np.round(np.unique(truth.segments[..., 2]), 9)) == {0.0, 1.0}
    not_sharp = set(truth.angles) - set(truth.sharp_curves)
    assert len(not_sharp) == 8
    assert all(truth.angles[c][1] < 1e-3 for c in not_sharp)


def test_all_filleted_box_has_no_truth(occ):
    box = _box(occ)
    occ.fillet([box], [c for _, c in gmsh.model.getEntities(1)], [0.2])
    occ.synchronize()
    truth = brep_truth()
    assert truth.segments.shape == (0, 2, 3)
    assert classify(truth, 0.05) == ("filleted", [])


def test_closest_gap_and_classes_of_a_thin_plate(occ):
    _box(occ, 1, 1, 0.1)
    truth = brep_truth()
    # the top and bottom rims are 0.1 apart and share no vertex
    assert closest_gap(truth, 0.5) == pytest.approx(0.1, abs=1e-9)
    assert closest_gap(truth, 0.05) == math.inf
    assert classify(truth, 0.01)[0] == "clear"
    cls, reasons = classify(truth, 0.05)
    assert cls == "ambiguous"
    assert reasons == ["features 2.00 spacings apart"]


def _chamfered_box(occ, width: float) -> None:
    """The unit cube with the edge x = y = 1 chamfered ``width`` on both faces."""
    box = _box(occ, 1, 1, 1)
    edge = next(
        c
        for _, c in gmsh.model.getEntities(1)
        if np.allclose(gmsh.model.getBoundingBox(1, c), [1, 1, 0, 1, 1, 1], atol=1e-7)
    )
    face = int(gmsh.model.getAdjacencies(1, edge)[0][0])
    occ.chamfer([box], [edge], [face], [width])
    occ.synchronize()


def test_chamfer_narrower_than_3_spacings_is_ambiguous(occ):
    _chamfered_box(occ, 0.05)
    truth = brep_truth()
    # the chamfer's two long edges and its end corners are 0.05 * sqrt(2) apart
    width = 0.05 * math.sqrt(2)
    # 11 box edges, the chamfer's 2 long and 2 end edges; 6 box corners, 4 new
    assert len(truth.sharp_curves) == 15 and len(truth.corners) == 10
    assert closest_gap(truth, 3 * 0.05) == pytest.approx(width, rel=1e-6)
    assert classify(truth, 0.05) == ("ambiguous", ["features 1.41 spacings apart"])
    assert classify(truth, 0.02) == ("clear", [])


def _cut_corner_cube(occ, d: float) -> None:
    """The unit cube less the small tetrahedron of its corner (1, 1, 1) with legs ``d``."""
    box = _box(occ, 1, 1, 1)
    apex = [(1, 1, 1), (1 - d, 1, 1), (1, 1 - d, 1), (1, 1, 1 - d)]
    p = [occ.addPoint(*xyz) for xyz in apex]
    lines = {
        (a, b): occ.addLine(p[a], p[b]) for a, b in ((0, 1), (0, 2), (0, 3), (1, 2), (2, 3), (3, 1))
    }

    def loop(*edges: tuple[int, int]) -> int:
        return occ.addPlaneSurface([occ.addCurveLoop([lines[e] for e in edges])])

    faces = [
        loop((0, 1), (1, 2), (0, 2)),
        loop((0, 2), (2, 3), (0, 3)),
        loop((0, 3), (3, 1), (0, 1)),
        loop((1, 2), (2, 3), (3, 1)),
    ]
    tet = occ.addVolume([occ.addSurfaceLoop(faces)])
    occ.cut([(3, box)], [(3, tet)])
    occ.synchronize()


def test_two_corners_closer_than_3_spacings_are_separate_features(occ):
    _cut_corner_cube(occ, 0.05)
    truth = brep_truth()
    # the cut makes a triangle of side 0.05 * sqrt(2) whose vertices are corners; the
    # cube's edges meet it at right angles: only the corners are close
    side = 0.05 * math.sqrt(2)
    assert len(truth.corners) == 10
    assert closest_gap(truth, 3 * 0.05) == pytest.approx(side, rel=1e-6)
    no_corners = replace(truth, corners=np.zeros((0, 3)))
    assert closest_gap(no_corners, 3 * 0.05) == math.inf
    assert classify(truth, 0.05)[0] == "ambiguous"
    assert classify(truth, 0.02)[0] == "clear"


def test_curves_meeting_at_a_sharp_angle_are_separate_features(occ):
    # a prism on a triangle with a 10-degree tip: its two long rims leave the tip
    # 10 degrees apart; near it they are closer than 3 spacings at any spacing
    tan10 = math.tan(math.radians(10))
    occ.extrude(
        [(2, occ.addPlaneSurface([occ.addCurveLoop(_triangle(occ, (1, 0), (1, tan10)))]))],
        0,
        0,
        0.5,
    )
    occ.synchronize()
    truth = brep_truth()
    assert len(truth.sharp_curves) == 9 and len(truth.corners) == 6
    for spacing in (0.05, 0.01):
        gap = closest_gap(truth, 3 * spacing)
        assert gap < 3 * spacing
        assert classify(truth, spacing)[0] == "ambiguous"
    # an equilateral triangle: rims 60 degrees apart are one feature near a tip
    gmsh.clear()
    occ.extrude(
        [
            (
                2,
                occ.addPlaneSurface(
                    [occ.addCurveLoop(_triangle(occ, (1, 0), (0.5, math.sqrt(0.75))))]
                ),
            )
        ],
        0,
        0,
        0.5,
    )
    occ.synchronize()
    assert classify(brep_truth(), 0.05) == ("clear", [])


def _triangle(occ, b: tuple[float, float], c: tuple[float, float]) -> list[int]:
    """The lines of the triangle (0, 0), ``b``, ``c`` in the plane z = 0."""
    p = [occ.addPoint(x, y, 0) for x, y in ((0, 0), b, c)]
    return [occ.addLine(p[i], p[(i + 1) % 3]) for i in range(3)]


def test_stl_like_box_is_its_8_corners_and_cylinder_24_per_turn(occ):
    _box(occ)
    verts, faces = gmsh_mesh(10.0, 24, extend=False)
    assert len(verts) == 8 and len(faces) == 12
    gmsh.clear()
    occ.addCylinder(0, 0, 0, 0, 0, 2, 1)
    occ.synchronize()
    verts, _ = gmsh_mesh(10.0, 24, extend=False)
    ring = np.count_nonzero(np.isclose(verts[:, 2], 2.0) & np.isclose(np.hypot(*verts[:, :2].T), 1))
    assert 22 <= ring <= 26


def _curve(points: np.ndarray) -> SimpleNamespace:
    return SimpleNamespace(points=np.asarray(points, np.float64), closed=False)


def test_curve_scores_known_answer(occ):
    _box(occ)
    truth = brep_truth()
    ends = np.array([[x, y, z] for x in (0, 1) for y in (0, 2) for z in (0, 3)], np.float64)
    edges = [(a, b) for a in ends for b in ends if (a < b).sum() == 1 and (a <= b).all()]
    assert len(edges) == 12
    exact = curve_scores([_curve(e) for e in edges], ends, truth, 0.05)
    assert exact["precision"] == 1.0 and exact["coverage"] == pytest.approx(1.0)
    assert exact["count_ratio"] == 1.0 and exact["corners_found"] == 1.0
    assert exact["corners_hit"] == 8 and exact["n_truth_corners"] == 8
    # the four edges along z (length 12 of 24) only, no corners, and one curve 1 away
    along_z = [e for e in edges if e[1][2] - e[0][2] == 3]
    off = _curve([[0.5, 1.0, 4.0], [0.5, 1.0, 5.0]])
    part = curve_scores([*(_curve(e) for e in along_z), off], np.zeros((0, 3)), truth, 0.05)
    # covered: the 12 of length along z, and 1.5 spacings at both ends of the 8 others
    assert part["coverage"] == pytest.approx((12 + 8 * 2 * 1.5 * 0.05) / 24, abs=0.002)
    assert part["precision"] == pytest.approx(12 / 13, abs=0.01)
    assert part["count_ratio"] == pytest.approx(5 / 12)
    assert part["corners_found"] == 0.0 and part["corners_hit"] == 0


def test_curve_scores_on_the_seen_truth(occ):
    _box(occ)
    truth = brep_truth()
    ends = np.array([[x, y, z] for x in (0, 1) for y in (0, 2) for z in (0, 3)], np.float64)
    edges = [(a, b) for a in ends for b in ends if (a < b).sum() == 1 and (a <= b).all()]
    exact = [_curve(e) for e in edges]
    seen = np.ones(len(truth.segments), bool)
    assert len(seen_corners(truth, seen)) == 8
    assert curve_scores(exact, ends, truth, 0.05, seen=seen) == curve_scores(
        exact, ends, truth, 0.05
    )
    # seen: the four edges along z and two edges of the top face z = 3, those on x = 0
    # and y = 0; of the top corners only (0, 0, 3) has three seen curves
    mid = truth.segments.mean(axis=1)
    seen = np.isclose(mid[:, 2], 3) & ~np.isclose(mid[:, 0], 1) & ~np.isclose(mid[:, 1], 2)
    seen |= ~np.isclose(mid[:, 2], 0) & ~np.isclose(mid[:, 2], 3)
    assert {tuple(c) for c in seen_corners(truth, seen)} == {(0.0, 0.0, 3.0)}
    along_z = [_curve(e) for e in edges if e[1][2] - e[0][2] == 3]
    s = curve_scores(along_z, np.zeros((0, 3)), truth, 0.05, seen=seen)
    # 12 of the 15 seen length covered, and 1.5 spacings at both ends of the 2 others
    assert s["coverage"] == pytest.approx((12 + 2 * 2 * 1.5 * 0.05) / 15, abs=0.002)
    assert s["precision"] == 1.0
    assert s["count_ratio"] == pytest.approx(4 / 6)
    assert s["n_truth_corners"] == 1 and s["corners_hit"] == 0


def test_seen_pieces_are_matched_on_their_own_curve(occ):
    _box(occ)
    truth = brep_truth()
    edges, curve = truth.segments, truth.segment_curve
    # the scan saw the mesh creases of the four edges along z only
    along_z = np.isclose(
        edges[:, 1, 2] - edges[:, 0, 2], np.linalg.norm(edges[:, 1] - edges[:, 0], axis=1)
    )
    near = _seen_pieces(edges, curve, edges, along_z, 0.05)
    assert np.array_equal(near, along_z)
    # matched on any curve, the other edges' pieces within half a spacing of a corner
    # were seen
    stubs = _seen_pieces(edges, np.zeros(len(edges), np.int64), edges, along_z, 0.05)
    extra = edges[stubs & ~along_z].mean(axis=1)
    assert len(extra) > 16
    assert cKDTree(truth.corners).query(extra)[0].max() <= 0.025


def test_inputs_of_a_box(occ):
    _box(occ)
    truth = brep_truth()
    parts = make_inputs("box", truth.segments, 3000, which=("fine_mesh", "iid", "noise25"))
    assert list(parts) == ["fine_mesh", "iid", "noise25"]
    assert parts["iid"].n == parts["noise25"].n == 3000
    fine = parts["fine_mesh"]
    assert 2500 < fine.n < 3500
    # every vertex on the box's surface, every truth edge made of mesh edges
    v = fine.vertices
    on_face = np.isclose(v, 0, atol=1e-6) | np.isclose(v, [1, 2, 3], atol=1e-6)
    assert on_face.any(axis=1).all()


@pytest.mark.slow
def test_evaluate_part_runs_every_input(tmp_path):
    source = next(p for p in PARTS if p.name == "chamfer_box")
    if not source.path.is_file():
        pytest.skip(f"{source.path} not installed")
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        row = evaluate_part(source, 4000, tmp_path)
    finally:
        gmsh.finalize()
    # at 4,000 points the chamfers are narrower than 3 spacings
    assert row["class"] == "ambiguous"
    assert row["reasons"][0].endswith("spacings apart")
    # the chamfered box: 12 box edges, 3 become 6 chamfer edges: 18 curves, 12 corners
    assert row["sharp_curves"] == 18 and row["corners"] == 12
    assert set(row["inputs"]) == {"fine_mesh", "stl_like", "blue_noise", "noise25", "iid", "scan"}
    assert "detection" not in row["inputs"]["stl_like"]
    for name, r in row["inputs"].items():
        assert 0 <= r["flagged"] <= 1
        if name != "stl_like":
            assert 0 <= r["detection"]["f1"] <= 1
    # a fine mesh's sharp edges are mesh edges: found exactly
    assert row["inputs"]["fine_mesh"]["detection"]["f1"] > 0.99


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--parts", "nosuch"], "unknown part 'nosuch'"),
        (["--points", "10"], "--points must be at least 1000"),
        (["--json", "no/such/dir/x.json"], "no/such/dir: no such folder"),
    ],
)
def test_script_bad_options_are_one_line_errors(args, message, tmp_path):
    script = Path(__file__).resolve().parent.parent / "scripts" / "evaluate_cad.py"
    run = subprocess.run(
        [sys.executable, str(script), *args], capture_output=True, text=True, cwd=tmp_path
    )
    assert run.returncode == 1
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("meshlab-sharp: error: ")
    assert message in lines[0]
