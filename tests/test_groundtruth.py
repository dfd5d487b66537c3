"""Ground-truth parts and corruptions."""

from __future__ import annotations

import math
import shutil
import subprocess

import numpy as np
import pymeshlab
import pytest
from scipy.spatial import cKDTree

from evaluation import groundtruth as gt
from evaluation import parts as evaluation_parts
from evaluation import scan
from meshlab_sharp import parts

N = 2_000


def _circles(r: float) -> float:
    """Length of one SEGMENTS-gon of radius r."""
    return gt.SEGMENTS * 2 * r * math.sin(math.pi / gt.SEGMENTS)


def _star_length() -> float:
    v = evaluation_parts._part_star_prism()[0][:10, :2]
    return 2 * np.linalg.norm(v - np.roll(v, 1, axis=0), axis=1).sum() + 10 * 20


EXPECTED_LENGTH = {
    "box": 4 * (60 + 40 + 30),
    "chamfered_box": 2 * 2 * (60 + 40) + 4 * 24 + 2 * (48 + 28) + 4 * 6 * math.sqrt(3),
    "cylinder": 2 * _circles(20),
    "cone": _circles(25) + _circles(10),
    "drilled_plate": 4 * (80 + 50) + 4 * 12 + 2 * (_circles(5) + _circles(7) + _circles(9)),
    "concave_steps": 8 * 40 + 2 * 180,
    "star_prism": _star_length(),
    **{f"wedge{a}": 3 * 30 + 2 * (100 + 100 * math.sin(math.radians(a) / 2)) for a in (30, 45, 60)},
}


@pytest.mark.parametrize("name", gt.part_names())
def test_reference_closed_and_truth_length(name):
    v, f, e = gt.reference_surface(name)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f))
    topo = ms.get_topological_measures()
    assert topo["is_mesh_two_manifold"] and topo["boundary_edges"] == 0
    length = np.linalg.norm(e[:, 1] - e[:, 0], axis=1).sum() if len(e) else 0.0
    if name in gt.SMOOTH_PARTS:
        assert len(e) == 0
    elif name in EXPECTED_LENGTH:
        assert length == pytest.approx(EXPECTED_LENGTH[name], rel=1e-9)
    else:
        assert length > 0


@pytest.mark.parametrize("name", gt.part_names())
def test_points_on_reference_and_truth_near_points(name):
    part = gt.make_part(name, n_points=N, seed=1)
    assert part.vertices.shape == (N, 3) and part.faces is None
    assert np.allclose(np.linalg.norm(part.normals, axis=1), 1.0)
    nn, _ = cKDTree(part.vertices).query(part.vertices, k=2)
    assert nn[:, 1].min() > 0.4 * part.spacing
    if len(part.edges):
        d, _ = cKDTree(part.vertices).query(part.edges.mean(axis=1))
        assert d.max() < 1.5 * part.spacing


def test_points_on_analytic_surfaces():
    sphere = gt.make_part("sphere", n_points=N)
    assert np.abs(np.linalg.norm(sphere.vertices, axis=1) - 25).max() < 0.02
    torus = gt.make_part("torus", n_points=N)
    p = torus.vertices
    tube = np.hypot(np.hypot(p[:, 0], p[:, 1]) - 25, p[:, 2])
    chord = 35 * (1 - math.cos(math.pi / 128)) + 10 * (1 - math.cos(math.pi / 64))
    assert np.abs(tube - 10).max() < chord + 1e-4
    rbox = gt.make_part("rounded_box", n_points=N)
    inner = np.array([22.0, 12.0, 7.0])
    q = np.maximum(np.abs(rbox.vertices) - inner, 0)
    assert np.abs(np.linalg.norm(q, axis=1) - 8).max() < 0.01
    box = gt.make_part("box", n_points=N)
    b = box.vertices
    dist = np.minimum(np.minimum(b, [60, 40, 30] - b).min(axis=1), np.inf)
    assert np.abs(dist).max() < 1e-5


def test_deterministic_and_seeded():
    a = gt.make_part("star_prism", n_points=N, seed=5)
    b = gt.make_part("star_prism", n_points=N, seed=5)
    c = gt.make_part("star_prism", n_points=N, seed=6)
    assert np.array_equal(a.vertices, b.vertices)
    assert not np.array_equal(a.vertices, c.vertices)


def test_star_tips_are_45_degrees():
    v = evaluation_parts._part_star_prism()[0][:10, :2]
    tip, left, right = v[0], v[9], v[1]
    u, w = left - tip, right - tip
    ang = math.degrees(math.acos(u @ w / np.linalg.norm(u) / np.linalg.norm(w)))
    assert ang == pytest.approx(45.0)


def test_small_mesh_part_watertight():
    part = gt.make_part("cylinder", "mesh", n_points=3_000)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=part.vertices, face_matrix=part.faces))
    topo = ms.get_topological_measures()
    assert topo["is_mesh_two_manifold"] and topo["boundary_edges"] == 0
    creases = gt.crease_segments(part.vertices, part.faces)
    length = np.linalg.norm(creases[:, 1] - creases[:, 0], axis=1).sum()
    assert length == pytest.approx(part.edge_length, rel=0.01)


@pytest.fixture(scope="module")
def box():
    return gt.make_part("box", n_points=N, seed=2)


@pytest.mark.parametrize("direction", ["normal", "isotropic"])
def test_noise(box, direction):
    noisy = gt.add_noise(box, 0.25, seed=1, direction=direction)
    delta = noisy.vertices - box.vertices
    sigma = 0.25 * box.spacing
    if direction == "normal":
        along = np.einsum("ij,ij->i", delta, box.normals)
        assert np.allclose(np.linalg.norm(delta, axis=1), np.abs(along), atol=1e-5)
        assert along.std() == pytest.approx(sigma, rel=0.1)
    else:
        assert delta.std(axis=0) == pytest.approx([sigma] * 3, rel=0.1)
    assert np.array_equal(noisy.edges, box.edges) and noisy.spacing == box.spacing
    again = gt.add_noise(box, 0.25, seed=1, direction=direction)
    assert np.array_equal(noisy.vertices, again.vertices)


def test_iid_part_is_on_the_surface_and_clustered(box):
    """As many points, drawn independently on the box's faces (60 x 40 x 30 at the
    origin) with their faces' normals, the same edges and spacing; clustered: the median
    nearest-neighbour distance well below the Poisson-disk cloud's."""
    iid = gt.iid_part(box, seed=4)
    assert iid.n == box.n and iid.spacing == box.spacing
    assert np.array_equal(iid.edges, box.edges)
    p = iid.vertices.astype(np.float64)
    on_face = np.isclose(p, 0.0, atol=1e-4) | np.isclose(p, [60.0, 40.0, 30.0], atol=1e-4)
    assert on_face.any(axis=1).all()
    assert np.allclose(np.abs(iid.normals).max(axis=1), 1.0)
    near = [np.median(cKDTree(q).query(q, k=2)[0][:, 1]) for q in (p, box.vertices)]
    assert near[0] < 0.75 * near[1]
    assert np.array_equal(gt.iid_part(box, seed=4).vertices, iid.vertices)


def test_outliers(box):
    out = gt.add_outliers(box, 0.01, seed=1)
    assert out.n == N + 20 and out.outliers.sum() == 20
    assert np.array_equal(out.vertices[:N], box.vertices)
    assert out.outliers[N:].all()
    d, _ = cKDTree(box.vertices).query(out.vertices[N:])
    assert d.min() > 2 * box.spacing
    noisy = gt.add_noise(out, 0.5, seed=3)
    assert np.array_equal(noisy.vertices[N:], out.vertices[N:])


def test_density_gradient(box):
    grad = gt.density_gradient(box, 4.0)
    assert grad.n == N
    dense = grad.vertices[:, 0] < 30  # the box's halves have equal areas
    ratio = dense.sum() / (~dense).sum()
    assert 3.3 < ratio < 4.7
    local = grad.extra["local_spacing"]
    assert local[dense].mean() * 1.6 < local[~dense].mean()


# ----------------------------------------------------------------------------------
# Acute wedges
# ----------------------------------------------------------------------------------


@pytest.mark.parametrize("angle", [30, 45, 60])
def test_wedge_apex_angle_and_edges(angle):
    v, f, e = gt.reference_surface(f"wedge{angle}")
    # the apex edge is the vertical edge through the origin; its faces turn by 180 - angle
    ends, fa, fb, normals = parts.crease_edges(v, f, gt.CREASE_ANGLE)
    apex = [k for k, (a, b) in enumerate(ends) if np.allclose(v[[a, b], :2], 0)]
    assert len(apex) == 1
    turn = math.degrees(math.acos(normals[fa[apex[0]]] @ normals[fb[apex[0]]]))
    assert turn == pytest.approx(180 - angle)
    base = 2 * 50 * math.sin(math.radians(angle) / 2)
    length = np.linalg.norm(e[:, 1] - e[:, 0], axis=1).sum()
    assert len(e) == 9 and length == pytest.approx(3 * 30 + 2 * (100 + base))


# ----------------------------------------------------------------------------------
# CAD tessellations
# ----------------------------------------------------------------------------------


def test_cad_box_is_its_kernel_triangulation():
    part = gt.cad_part("box")
    v, f, _ = gt.reference_surface("box")
    assert part.kind == "mesh" and part.extra["scoring"] == "vertices"
    assert np.array_equal(part.faces, f) and np.array_equal(part.vertices, v)
    assert len(part.edges) == 12
    corners = np.all(np.isin(part.vertices, [0, 60, 40, 30]), axis=1)
    assert corners.sum() == 8 and part.n == 10  # 8 corners and the 2 cap centres


def test_coarse_cylinder_truth_is_two_24_gons():
    v, f, e = gt.reference_surface("cylinder", gt.COARSE_SEGMENTS)
    assert len(v) == 2 * 24 + 2 and len(e) == 2 * 24
    assert np.allclose(np.hypot(e[..., 0], e[..., 1]), 20)
    assert sorted(set(np.round(e[..., 2].ravel(), 9))) == [0, 40]
    # the side facets turn by 15 degrees: below the crease angle, not in the truth
    _, fa, fb, normals = parts.crease_edges(v, f, 1.0)
    turns = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", normals[fa], normals[fb]), -1, 1)))
    assert sorted(set(np.round(turns, 6))) == [15.0, 90.0]


@pytest.mark.parametrize("name", gt.ROUND_PARTS)
def test_coarse_parts_closed_with_fewer_facets(name):
    fine = gt.reference_surface(name)
    v, f, e = gt.reference_surface(name, gt.COARSE_SEGMENTS)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f))
    topo = ms.get_topological_measures()
    assert topo["is_mesh_two_manifold"] and topo["boundary_edges"] == 0
    assert len(v) < len(fine[0]) / 3 and len(e) < len(fine[2]) / 3


def test_too_few_segments_rejected():
    with pytest.raises(ValueError, match="crease"):
        gt.reference_surface("cylinder", 18)


@pytest.mark.parametrize("name", gt.OPENSCAD_PARTS)
def test_openscad_exports(name):
    stem = name[len("scad_") :]
    stl = gt.OPENSCAD_DIR / f"{stem}.stl"
    assert (gt.OPENSCAD_DIR / f"{stem}.scad").exists()
    assert stl.stat().st_size < 200_000
    v, f, e = gt.openscad_surface(name)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f))
    topo = ms.get_topological_measures()
    assert topo["is_mesh_two_manifold"] and topo["boundary_edges"] == 0
    # the truth is exact: facets turn by <= 15 degrees ($fn >= 24; float32 rounding adds
    # 0.01), designed edges by
    # >= 45 degrees; nothing in between
    _, fa, fb, normals = parts.crease_edges(v, f, 1e-3)
    turns = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", normals[fa], normals[fb]), -1, 1)))
    assert not np.any((turns > 16) & (turns < 40)) and np.any(turns >= 40)
    assert len(e) == int((turns > gt.CREASE_ANGLE).sum())
    part = gt.openscad_part(name)
    assert part.extra["scoring"] == "vertices" and part.n == len(v)


def test_weld_merges_stl_triangle_soup():
    v, f, _ = gt.reference_surface("box")
    soup = v[f].reshape(-1, 3)
    wv, wf = gt.weld(soup, np.arange(len(soup)).reshape(-1, 3))
    assert len(wv) == len(v) and len(wf) == len(f)
    assert np.allclose(np.sort(wv[wf].reshape(-1, 9), axis=0), np.sort(v[f].reshape(-1, 9), axis=0))


@pytest.mark.skipif(shutil.which("openscad") is None, reason="openscad not installed")
def test_openscad_exports_match_their_sources(tmp_path):
    name = "scad_knob"
    out = tmp_path / "knob.stl"
    subprocess.run(
        ["openscad", "-o", str(out), str(gt.OPENSCAD_DIR / "knob.scad")],
        check=True,
        capture_output=True,
    )
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(out))
    v, _ = gt.weld(ms.current_mesh().vertex_matrix(), ms.current_mesh().face_matrix())
    assert np.array_equal(v, gt.openscad_surface(name)[0])


# ----------------------------------------------------------------------------------
# Thin walls
# ----------------------------------------------------------------------------------

W = 2.0


def test_thin_tube_wall():
    v, _, e = gt.thin_surface("tube", W)
    r = np.hypot(v[:, 0], v[:, 1])
    inner = r[(r > 1) & (r < 14)]
    # the inner polygon's corners, and points on its chords where the caps' triangles cut
    assert inner.max() == pytest.approx(15 - W, abs=1e-9)
    assert inner.min() >= (15 - W) * math.cos(math.pi / gt.SEGMENTS) - 1e-9
    assert np.allclose(r[r >= 14], 15)
    length = np.linalg.norm(e[:, 1] - e[:, 0], axis=1).sum()
    assert length == pytest.approx(2 * _circles(15) + 2 * _circles(15 - W), rel=1e-9)


def _planes(name: str, axis: int) -> list[float]:
    """Offsets of the planes of the faces of a thin part (wall W) normal to an axis."""
    v, f, _ = gt.thin_surface(name, W)
    normals, _ = parts.face_normals(v, f)
    on = np.abs(normals[:, axis]) > 1 - 1e-9
    return sorted(set(np.round(v[f[on, 0], axis], 9)))


def test_thin_bracket_wall():
    assert _planes("sheet_bracket", 2) == [0, W, 40]
    assert _planes("sheet_bracket", 0) == [0, W, 60]


def test_thin_housing_walls_and_ribs():
    assert _planes("ribbed_housing", 0) == [
        0,
        W,
        27 - W / 2,
        27 + W / 2,
        53 - W / 2,
        53 + W / 2,
        80 - W,
        80,
    ]
    assert _planes("ribbed_housing", 1) == [0, W, 25 - W / 2, 25 + W / 2, 50 - W, 50]
    assert _planes("ribbed_housing", 2) == [0, W, 14, 20, 30]


def test_thin_rotor_blades():
    v, _, _ = gt.thin_surface("blade_rotor", W)
    pitch = math.radians(30)
    r = np.hypot(v[:, 0], v[:, 1])
    for k in range(6):
        phi = k * math.pi / 3
        radial = np.array([math.cos(phi), math.sin(phi), 0.0])
        normal = np.array(
            [-math.cos(pitch) * math.sin(phi), math.cos(pitch) * math.cos(phi), math.sin(pitch)]
        )
        blade = v[(r > 12.5) & (v @ radial > 0.9 * r)]
        proj = blade @ normal
        assert proj.max() - proj.min() == pytest.approx(W, abs=1e-9)


@pytest.mark.parametrize(("kind", "tol"), [("points", 0.05), ("mesh", 0.1)])
def test_thin_wall_in_spacings(kind, tol):
    part = gt.make_thin_part("tube", 2, kind, n_points=3000)
    assert part.extra["wall"] / part.spacing == pytest.approx(2, rel=tol)
    v, _, _ = gt.thin_surface("tube", part.extra["wall"])
    area = parts.face_normals(*gt.thin_surface("tube", part.extra["wall"])[:2])[1].sum()
    n = part.n if kind == "points" else 3000
    assert part.extra["wall"] == pytest.approx(2 * gt.expected_spacing(area, n, kind), rel=1e-3)
    assert len(v) and np.array_equal(part.edges, gt.thin_surface("tube", part.extra["wall"])[2])


# ----------------------------------------------------------------------------------
# Simulated scan
# ----------------------------------------------------------------------------------


def _first_hit_brute(v, f, origin, target):
    """Distance from origin to the first triangle hit on the ray towards target."""
    d = (target - origin) / np.linalg.norm(target - origin)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    n = np.cross(b - a, c - a)
    denom = n @ d
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ij,ij->i", n, a - origin) / denom
    p = origin + t[:, None] * d
    inside = (
        (np.einsum("ij,ij->i", np.cross(b - a, p - a), n) >= -1e-9)
        & (np.einsum("ij,ij->i", np.cross(c - b, p - b), n) >= -1e-9)
        & (np.einsum("ij,ij->i", np.cross(a - c, p - c), n) >= -1e-9)
    )
    return np.where(inside & (t > 0) & (np.abs(denom) > 1e-12), t, np.inf).min()


def test_scan_points_on_surface_and_visible():
    v, f, _ = gt.reference_surface("concave_steps")
    scanners = scan.scanner_positions(v)
    res = scan.scan(v, f, scanners, n_points=3000, noise=0.0, seed=1)
    assert np.array_equal(res.points, res.surface)
    assert abs(len(res.points) - 3000) < 150
    # on the triangle it hit, with its normal
    a = v[f[res.face, 0]]
    assert np.abs(np.einsum("ij,ij->i", res.surface - a, res.normals)).max() < 1e-9
    # the first thing its scanner sees in that direction (independent brute force)
    rng = np.random.default_rng(0)
    for k in rng.choice(len(res.points), 60, replace=False):
        origin = scanners[res.view[k]]
        first = _first_hit_brute(v, f, origin, res.surface[k])
        assert first == pytest.approx(np.linalg.norm(res.surface[k] - origin), abs=1e-6)
    # facing the scanner, never the underside (z = 0)
    to_scanner = scanners[res.view] - res.surface
    assert np.all(np.einsum("ij,ij->i", to_scanner, res.normals) > 0)
    assert not np.any(res.normals[:, 2] < -0.5)


def test_scan_density_and_noise_grow_with_range():
    v, f, _ = gt.reference_surface("box")
    scanners = scan.scanner_positions(v)
    dist = np.linalg.norm(scanners - 0.5 * (v.min(0) + v.max(0)), axis=1)
    res = scan.scan(v, f, scanners, n_points=4000, noise=0.5, seed=2)
    assert abs(len(res.points) - 4000) < 200
    counts = np.bincount(res.view)
    ratio = []
    for k in range(len(scanners)):
        sel = res.view == k
        nn, _ = cKDTree(res.surface[sel]).query(res.surface[sel], k=2)
        ratio.append(np.median(nn[:, 1]) / dist[k])
        # noise along the ray only
        delta = res.points[sel] - res.surface[sel]
        ray = res.surface[sel] - scanners[k]
        cross = np.linalg.norm(np.cross(delta, ray), axis=1) / np.linalg.norm(ray, axis=1)
        assert cross.max() < 1e-9
    # one angular step: spacing proportional to the distance, fewer points from afar
    assert max(ratio) / min(ratio) < 1.15
    assert counts[np.argmax(dist)] < 0.7 * counts[np.argmin(dist)]
    # sigma ~ range^2: the error relative to the footprint (~ range) grows with range
    rng_len = np.linalg.norm(res.surface - scanners[res.view], axis=1)
    err = np.linalg.norm(res.points - res.surface, axis=1) / res.footprint
    near, far = rng_len < np.median(rng_len), rng_len >= np.median(rng_len)
    assert err[far].mean() > 1.1 * err[near].mean()


def test_scan_visible_edges_of_a_box():
    part = gt.scan_part("box", n_points=4000, seed=0)
    vis = part.extra["visible_edges"]
    mid = vis.mean(axis=1)
    # the underside is never seen: its 4 edges are left out, the other 8 kept whole
    assert mid[:, 2].min() > 1e-9
    length = np.linalg.norm(vis[:, 1] - vis[:, 0], axis=1).sum()
    assert length == pytest.approx(4 * 30 + 2 * (60 + 40), rel=0.02)
    assert len(part.extra["local_spacing"]) == part.n


# ----------------------------------------------------------------------------------
# Conditions
# ----------------------------------------------------------------------------------

CHEAP = ("box", "ribbed_housing", "wedge45", "sphere", "cylinder", "scad_knob", "chamfered_box")


@pytest.mark.parametrize("condition", list(gt.CONDITIONS))
def test_every_condition_generates(condition):
    cond = gt.CONDITIONS[condition]
    part_name = next(p for p in CHEAP if p in cond.parts)
    part = gt.make_condition(part_name, condition, n_points=1500, seed=3)
    assert part.name == part_name and part.vertices.shape == (part.n, 3)
    assert (part.faces is None) == (part.kind == "points")
    assert (len(part.edges) > 0) == (cond.group != "smooth" and part_name not in gt.SMOOTH_PARTS)
    if cond.group == "cad":
        assert part.extra["scoring"] == "vertices"
    elif part.kind == "points" and condition != "outliers1":
        assert abs(part.n - 1500) <= 75


def test_suite_and_errors():
    pairs = gt.suite(quick=True)
    assert len(pairs) == len(set(pairs))
    assert {c for _, c in pairs} == {c for c, x in gt.CONDITIONS.items() if x.quick_parts}
    assert all(p in gt.CONDITIONS[c].parts for p, c in gt.suite())
    assert gt.suite(conditions=["cad"], parts=["box"]) == [("box", "cad")]
    with pytest.raises(KeyError):
        gt.suite(conditions=["nope"])
    with pytest.raises(KeyError):
        gt.make_condition("box", "nope", n_points=100)
    with pytest.raises(ValueError, match="does not apply"):
        gt.make_condition("sphere", "mesh", n_points=100)
