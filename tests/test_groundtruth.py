"""Ground-truth parts and corruptions."""

from __future__ import annotations

import math

import numpy as np
import pymeshlab
import pytest
from scipy.spatial import cKDTree

from meshlab_sharp import groundtruth as gt

N = 2_000


def _circles(r: float) -> float:
    """Length of one SEGMENTS-gon of radius r."""
    return gt.SEGMENTS * 2 * r * math.sin(math.pi / gt.SEGMENTS)


def _star_length() -> float:
    v = gt._part_star_prism()[0][:10, :2]
    return 2 * np.linalg.norm(v - np.roll(v, 1, axis=0), axis=1).sum() + 10 * 20


EXPECTED_LENGTH = {
    "box": 4 * (60 + 40 + 30),
    "chamfered_box": 2 * 2 * (60 + 40) + 4 * 24 + 2 * (48 + 28) + 4 * 6 * math.sqrt(3),
    "cylinder": 2 * _circles(20),
    "cone": _circles(25) + _circles(10),
    "drilled_plate": 4 * (80 + 50) + 4 * 12 + 2 * (_circles(5) + _circles(7) + _circles(9)),
    "concave_steps": 8 * 40 + 2 * 180,
    "star_prism": _star_length(),
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
    v = gt._part_star_prism()[0][:10, :2]
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
