"""Stray points off the sampled surface, alone or in small clusters, are not features
(robust mode's isolation, docs/method.md, step 1): in memory, on the
Python-driven path and tile by tile."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import meshlab_sharp
from evaluation import groundtruth as gt
from meshlab_sharp.multiscale import DEFAULT_KNN_SCALES
from meshlab_sharp.tiles import detect_tiled

#: At most this share of the stray points may be features.
MAX_FLAGGED = 0.02


def stray_clusters(part: gt.SamplePart, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` clusters of 2 or 3 points, each 1 to 3 spacings from its cluster's
    centre, which lies 5 to 20 spacings off the part along the normal of a random
    sample, at least 10 spacings from the other centres; every point at least 5 spacings
    from the surface. Returns the points (m, 3) and each one's cluster."""
    rng = np.random.default_rng(seed)
    surface = cKDTree(part.vertices)
    s = part.spacing
    centres: list[np.ndarray] = []
    points, cluster = [], []
    while len(centres) < count:
        i = rng.integers(part.n)
        c = part.vertices[i] + rng.uniform(5.0, 20.0) * s * part.normals[i]
        offsets = rng.normal(size=(int(rng.integers(2, 4)), 3))
        offsets /= np.linalg.norm(offsets, axis=1, keepdims=True)
        offsets *= rng.uniform(1.0, 3.0, (len(offsets), 1)) * s
        members = c + offsets
        if surface.query(members)[0].min() < 5 * s:
            continue
        if any(np.linalg.norm(c - o) < 10 * s for o in centres):
            continue
        cluster += [len(centres)] * len(members)
        centres.append(c)
        points.append(members)
    return np.vstack(points), np.array(cluster)


@pytest.fixture(scope="module")
def strayed() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A box cloud of 8,000 points with about 1 % of its points in stray clusters; its
    clean features; which points are stray."""
    part = gt.make_part("box", n_points=8000, seed=3)
    stray, cluster = stray_clusters(part, 32, seed=1)
    assert 64 <= len(stray) <= 96 and np.bincount(cluster).min() >= 2
    points = np.vstack([part.vertices, stray])
    is_stray = np.r_[np.zeros(part.n, bool), np.ones(len(stray), bool)]
    clean = meshlab_sharp.detect(part.vertices).mask
    assert clean.sum() > 200
    return points, clean, is_stray


def _check(mask: np.ndarray, clean: np.ndarray, is_stray: np.ndarray) -> None:
    assert mask[is_stray].mean() <= MAX_FLAGGED, int(mask[is_stray].sum())
    # the surface's features are those of the part alone
    assert (mask[~is_stray] != clean).sum() <= 0.01 * clean.sum()


@pytest.mark.slow
@pytest.mark.parametrize("details", [False, True])
def test_stray_clusters_are_not_features(strayed, details: bool) -> None:
    points, clean, is_stray = strayed
    result = meshlab_sharp.detect(points, return_details=details)
    _check(result.mask, clean, is_stray)
    assert result.kept[~is_stray].all()  # no surface point is left out


@pytest.mark.slow
def test_stray_clusters_are_not_features_tile_by_tile(strayed) -> None:
    points, clean, is_stray = strayed
    ref = meshlab_sharp.detect(points)
    out = detect_tiled(points, scales=DEFAULT_KNN_SCALES, mode="robust", tile_points=1500)
    assert out["tiling"]["tiles"] >= 4
    assert np.array_equal(out["mask"], ref.mask) and np.array_equal(out["kept"], ref.kept)
    _check(out["mask"], clean, is_stray)
