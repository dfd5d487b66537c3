"""The package against an independent, deliberately plain numpy reading of ALGORITHM.md.

Nothing here imports the package's internals: brute-force distances, per-point loops,
Otsu's criterion in its textbook float form with bin centres.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pymeshlab
import pytest
import shapes

import meshlab_sharp

B = 256


def spec_knn(points: np.ndarray, k: int) -> list[np.ndarray]:
    """k nearest (point itself included), by distance then lower index."""
    n = len(points)
    d2 = ((points[:, None, :] - points[None, :, :]) ** 2).sum(-1)
    idx = np.broadcast_to(np.arange(n), (n, n))
    order = np.lexsort((idx, d2), axis=-1)
    return [order[i, :k] for i in range(n)]


def spec_ring_search(faces: np.ndarray, n: int, k: int) -> list[list[int]]:
    """Per vertex, the vertices within k edges in the order a breadth-first search finds
    them, each vertex's neighbours taken in the order its faces list them (face (a, b,
    c): a gets b, c; b gets a, c; c gets a, b), each once."""
    adj: list[list[int]] = [[] for _ in range(n)]
    for a, b, c in faces.tolist():
        for v, first, second in ((a, b, c), (b, a, c), (c, a, b)):
            for w in (first, second):
                if w not in adj[v]:
                    adj[v].append(w)
    found = []
    for i in range(n):
        seen = {i: 0}
        order = [i]
        queue = deque([i])
        while queue:
            u = queue.popleft()
            if seen[u] == k:
                continue
            for w in adj[u]:
                if w not in seen:
                    seen[w] = seen[u] + 1
                    order.append(w)
                    queue.append(w)
        found.append(order)
    return found


def spec_rings(faces: np.ndarray, n: int, k: int) -> list[np.ndarray]:
    """Vertices within k edges (breadth-first search), in increasing order."""
    return [np.array(sorted(order)) for order in spec_ring_search(faces, n, k)]


def spec_pca_normal(points: np.ndarray, i: int, nb: np.ndarray, weighting: str) -> np.ndarray:
    q = points[nb]
    c = q.mean(axis=0)
    d = np.linalg.norm(q - points[i], axis=1)
    h = d.max()
    mu = np.exp(-(d**2) / h**2) if (weighting == "gaussian" and h > 0) else np.ones(len(nb))
    cov = (mu[:, None] * (q - c)).T @ (q - c)
    return np.linalg.eigh(cov)[1][:, 0]


def spec_face_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    acc = np.zeros_like(points)
    for f in faces:
        n = np.cross(points[f[1]] - points[f[0]], points[f[2]] - points[f[0]])
        for v in f:
            acc[v] += n / np.linalg.norm(n)
    return acc / np.linalg.norm(acc, axis=1, keepdims=True)


def spec_otsu(v: np.ndarray) -> float:
    bins = np.minimum(np.floor(v * B), B - 1).astype(int)
    hist = np.bincount(bins, minlength=B).astype(float)
    centres = (np.arange(B) + 0.5) / B
    best, best_t = -1.0, None
    for t in range(1, B):
        c0, c1 = hist[:t].sum(), hist[t:].sum()
        if c0 == 0 or c1 == 0:
            continue
        w0, w1 = c0 / len(v), c1 / len(v)
        m0 = (hist[:t] * centres[:t]).sum() / c0
        m1 = (hist[t:] * centres[t:]).sum() / c1
        crit = w0 * w1 * (m0 - m1) ** 2
        if crit > best * (1 + 1e-12):
            best, best_t = crit, t
    return best_t / B


def spec_detect(points, faces, scales, weighting="gaussian"):
    """Returns (mask, thresholds, per-scale normalised distances)."""
    n = len(points)
    normals = spec_face_normals(points, faces) if faces is not None else None
    votes = np.zeros(n, dtype=int)
    thresholds, values = [], []
    for k in scales:
        hoods = spec_rings(faces, n, k) if faces is not None else spec_knn(points, k)
        pdis = np.empty(n)
        for i, nb in enumerate(hoods):
            normal = (
                normals[i] if normals is not None else spec_pca_normal(points, i, nb, weighting)
            )
            pdis[i] = abs((points[i] - points[nb].mean(axis=0)) @ normal)
        v = (pdis - pdis.min()) / (pdis.max() - pdis.min())
        t = spec_otsu(v)
        thresholds.append(t)
        values.append(v)
        votes += v >= t
    return votes == len(scales), np.array(thresholds), np.array(values)


def _cylinder_mesh():
    ms = pymeshlab.MeshSet()
    ms.create_cone(r0=1.0, r1=1.0, h=2.0, subdiv=48)
    ms.meshing_isotropic_explicit_remeshing(iterations=3, targetlen=pymeshlab.PercentageValue(6))
    m = ms.current_mesh()
    return m.vertex_matrix(), m.face_matrix().astype(np.int64)


CASES = {
    "box-points": lambda: (shapes.random_box_points(900, seed=3), None, "gaussian"),
    "box-cylinder-points": lambda: (shapes.box_cylinder_points(1200, seed=4), None, "gaussian"),
    "box-cylinder-points-unweighted": lambda: (
        shapes.box_cylinder_points(1200, seed=5),
        None,
        "none",
    ),
    "cube-grid-points": lambda: (shapes.cube_grid_points(11), None, "gaussian"),
    "cube-grid-mesh": lambda: (*shapes.cube_grid_mesh(3), "gaussian"),
    "cylinder-mesh": lambda: (*_cylinder_mesh(), "gaussian"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_matches_independent_reading_of_the_spec(case):
    points, faces, weighting = CASES[case]()
    default = (
        meshlab_sharp.DEFAULT_RING_SCALES if faces is not None else meshlab_sharp.DEFAULT_KNN_SCALES
    )
    expected_mask, expected_t, values = spec_detect(points, faces, default, weighting)
    result = meshlab_sharp.detect(
        points, faces, weighting=weighting, return_details=True, mode="paper"
    )
    np.testing.assert_array_equal(result.thresholds, expected_t)
    # Only points within 1e-9 of a threshold may differ (ALGORITHM.md's tolerance).
    near = (np.abs(values - expected_t[:, None]) < 1e-9).any(axis=0)
    assert np.array_equal(result.mask[~near], expected_mask[~near])
    np.testing.assert_allclose(result.distances, values, atol=1e-9)
    assert 0 < result.n_features < len(points)
