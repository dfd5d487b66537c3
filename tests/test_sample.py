"""The built-in sample part: deterministic, on its surface, truth on the part, mesh clean."""

from __future__ import annotations

import math

import numpy as np
import pymeshlab
import pytest
from scipy.spatial import cKDTree

from evaluation.groundtruth import crease_segments
from evaluation.scoring import distance_to_segments
from meshlab_sharp import sample
from meshlab_sharp.sample import sample_part

N = 6_000


@pytest.fixture(scope="module")
def points():
    return sample_part("points", n_points=N, seed=3)


@pytest.fixture(scope="module")
def mesh():
    # the default size (25,000): smaller meshes get a few stray creases at the hole
    return sample_part("mesh")


def _box(p, lo, hi):
    c = (np.array(lo) + hi) / 2
    h = (np.array(hi) - lo) / 2
    q = np.abs(p - c) - h
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def _cyl(p, cx, cy, r, z0, z1):
    rad = np.hypot(p[:, 0] - cx, p[:, 1] - cy) - r
    return np.maximum.reduce([rad, z0 - p[:, 2], p[:, 2] - z1])


def fandisk_sdf(p: np.ndarray) -> np.ndarray:
    """Signed CSG distance bound of the exact (round, not polygonal) sample solid."""
    solid = np.minimum.reduce(
        [
            _box(p, (0, 0, 0), (100, 60, 20)),
            _box(p, (0, 0, 0), (50, 60, 40)),
            _cyl(p, 68, 30, 9, 10, 30),
        ]
    )
    s = 1 / math.sqrt(2)
    chamfer = (p - [0, 0, 32]) @ np.array([-s, 0, s])
    a = math.radians(25)
    slope = (p - [85, 0, 20]) @ np.array([math.sin(a), 0, math.cos(a)])
    hole = -_cyl(p, 27, 30, 6, -1, 41)
    rad = np.hypot(p[:, 0] - 27, p[:, 1] - 30)
    countersink = -(rad - (p[:, 2] - 30)) / math.sqrt(2)  # r = z - 30 (45 degrees)
    return np.maximum.reduce([solid, chamfer, slope, hole, countersink])


def test_points_deterministic(points):
    again = sample_part("points", n_points=N, seed=3)
    assert np.array_equal(points.vertices, again.vertices)
    assert np.array_equal(points.edges, again.edges)
    other = sample_part("points", n_points=N, seed=4)
    assert not np.array_equal(points.vertices, other.vertices)


def test_points_shape_and_float32(points):
    v = points.vertices
    assert v.shape == (N, 3) and v.dtype == np.float64
    assert points.faces is None
    assert np.array_equal(v, v.astype(np.float32).astype(np.float64))
    assert points.edges.ndim == 3 and points.edges.shape[1:] == (2, 3)
    assert points.name == "fandisk"


def test_points_on_surface(points):
    d = np.abs(fandisk_sdf(points.vertices))
    # polygonal round surfaces: chord error 9 * (1 - cos(pi / 128)) = 0.003
    assert d.max() < 0.005


def test_points_uniform(points):
    d, _ = cKDTree(points.vertices).query(points.vertices, k=2)
    nn = d[:, 1]
    assert abs(nn.mean() - points.spacing) < 1e-9
    assert nn.min() > 0.5 * points.spacing  # Poisson-disk: no clumps
    assert nn.std() / nn.mean() < 0.2


def test_truth_edges_on_part(points):
    e = points.edges
    assert 1300 < points.edge_length < 1400
    assert np.abs(fandisk_sdf(e.reshape(-1, 3))).max() < 0.005
    mid = e.mean(axis=1)
    d, _ = cKDTree(points.vertices).query(mid)
    assert d.max() < 1.5 * points.spacing
    # the weak edges are there: the 25-degree slope edge (x = 85, z = 20) and the
    # countersink's lower circle (r = 6, z = 36)
    d = distance_to_segments(np.array([[85.0, 30.0, 20.0], [33.0, 30.0, 36.0]]), e)
    assert d.max() < 1e-6


@pytest.mark.slow
def test_mesh_watertight_and_isotropic(mesh):
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=mesh.vertices, face_matrix=mesh.faces))
    topo = ms.get_topological_measures()
    assert topo["is_mesh_two_manifold"]
    assert topo["boundary_edges"] == 0
    assert topo["connected_components_number"] == 1
    assert topo["genus"] == 1  # the drilled hole
    assert mesh.faces.dtype == np.int64
    assert 20_000 < mesh.n < 30_000
    f = mesh.faces
    e = np.unique(np.sort(np.vstack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    length = np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1)
    assert np.percentile(length / mesh.spacing, 1) > 0.5
    assert np.percentile(length / mesh.spacing, 99) < 1.6


def test_mesh_on_surface_and_edges_are_mesh_edges(mesh):
    assert np.abs(fandisk_sdf(mesh.vertices)).max() < 0.02
    creases = crease_segments(mesh.vertices, mesh.faces)
    crease_len = np.linalg.norm(creases[:, 1] - creases[:, 0], axis=1).sum()
    assert abs(crease_len - mesh.edge_length) < 0.01 * mesh.edge_length
    d = distance_to_segments(creases.reshape(-1, 3), mesh.edges)
    assert d.max() < 0.1 * mesh.spacing


@pytest.mark.slow
def test_mesh_deterministic():
    a = sample_part("mesh", n_points=5_000, seed=1)
    b = sample_part("mesh", n_points=5_000, seed=99)
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.faces, b.faces)


def test_bad_kind():
    with pytest.raises(ValueError):
        sample_part("voxels")


def _same(a, b) -> bool:
    arrays = ("vertices", "edges", "normals", "outliers")
    return (
        all(np.array_equal(getattr(a, f), getattr(b, f)) for f in arrays)
        and (a.faces is None) == (b.faces is None)
        and (a.faces is None or np.array_equal(a.faces, b.faces))
        and (a.name, a.kind, a.seed, a.spacing) == (b.name, b.kind, b.seed, b.spacing)
        and all(
            np.array_equal(x, y)
            for x, y in zip(a.extra["reference"], b.extra["reference"], strict=True)
        )
    )


@pytest.mark.slow
@pytest.mark.parametrize(("kind", "n"), [("points", 2_000), ("mesh", 1_000)])
def test_the_cache_keeps_the_part(tmp_path, monkeypatch, kind, n):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    built = sample_part(kind, n_points=n, seed=5, cache=True)
    assert _same(built, sample_part(kind, n_points=n, seed=5))
    (cached,) = (tmp_path / "meshlab-sharp" / "sample").iterdir()
    assert cached.name.startswith(f"fandisk-{kind}-{n}-seed5-")

    def no_build(*args, **kwargs):
        raise AssertionError("the part was built again")

    with monkeypatch.context() as patch:
        patch.setattr(sample, "make_part", no_build)
        assert _same(sample_part(kind, n_points=n, seed=5, cache=True), built)
    cached.write_bytes(b"not an npz")  # a damaged cache is built again
    assert _same(sample_part(kind, n_points=n, seed=5, cache=True), built)
    assert np.load(cached)["vertices"].shape == built.vertices.shape
