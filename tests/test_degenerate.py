"""Covariances whose smallest eigenvalue is not single get the same normal on every path.

A neighbourhood as symmetric as a grid's has a double or triple smallest eigenvalue: its
eigenvectors fill a plane or all of space, and LAPACK (the numpy reference) and the
native library's closed form would each take a different vector of it. Both take the one
the header names (``EIG_TIE_DIRECTION``, see :func:`meshlab_sharp.normals.smallest_eigenvectors`).
"""

from __future__ import annotations

import numpy as np
import pytest
from shapes import random_rotation

from meshlab_sharp import _kernels, detect
from meshlab_sharp.normals import (
    EIG_TIE_DIRECTION,
    largest_eigenvectors,
    smallest_eigenvectors,
)

compiled = pytest.mark.skipif(not _kernels.available(), reason="compiled kernels not built")


def _compiled_eigvecs(cov: np.ndarray) -> np.ndarray:
    """ms_eigvecs of the matrices cov (c, 3, 3)."""
    six = np.ascontiguousarray(cov[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]])
    out = np.empty((len(cov), 3))
    lib = _kernels._LIB
    assert lib is not None
    lib.ms_eigvecs(_kernels._ptr(six), len(six), _kernels._ptr(out))
    return out


def _rotated(values: tuple[float, float, float], seeds: range) -> tuple[np.ndarray, np.ndarray]:
    """Matrices R diag(values) R^T for random rotations R, and the rotations (c, 3, 3)."""
    rotations = np.stack([random_rotation(s) for s in seeds])
    cov = np.einsum("cab,b,cdb->cad", rotations, np.array(values), rotations)
    return (cov + cov.transpose(0, 2, 1)) / 2, rotations


def _shuffled_grid(m: int) -> np.ndarray:
    """The m^3 integer points of a cube, in a shuffled order."""
    axes = np.meshgrid(*[np.arange(m, dtype=float)] * 3, indexing="ij")
    grid = np.stack(axes, -1).reshape(-1, 3)
    return grid[np.random.default_rng(0).permutation(len(grid))]


def test_double_smallest_eigenvalue_takes_the_tie_direction_in_its_plane() -> None:
    cov, rotations = _rotated((1.0, 1.0, 3.0), range(20))
    got = smallest_eigenvectors(cov)
    v = rotations[:, :, 2]  # the single (largest) eigenvalue's line
    w = EIG_TIE_DIRECTION - (v @ EIG_TIE_DIRECTION)[:, None] * v
    expected = w / np.linalg.norm(w, axis=1, keepdims=True)
    assert np.allclose(np.abs(np.sum(got * expected, axis=1)), 1.0, rtol=0, atol=1e-9)
    # the same for the largest eigenvalue, double
    cov, rotations = _rotated((1.0, 3.0, 3.0), range(20, 40))
    v = rotations[:, :, 0]
    w = EIG_TIE_DIRECTION - (v @ EIG_TIE_DIRECTION)[:, None] * v
    expected = w / np.linalg.norm(w, axis=1, keepdims=True)
    got = largest_eigenvectors(cov)
    assert np.allclose(np.abs(np.sum(got * expected, axis=1)), 1.0, rtol=0, atol=1e-9)


def test_triple_and_diagonal_cases() -> None:
    near_identity = 2.0 * np.eye(3) + 1e-9 * _rotated((1.0, 2.0, 3.0), range(1))[0][0]
    diagonal = [np.diag([2.0, 1.0, 3.0]), np.diag([1.0, 1.0, 1.0 + 1e-4])]
    matrices = np.stack([near_identity, 3.0 * np.eye(3), *diagonal, np.zeros((3, 3))])
    got = smallest_eigenvectors(matrices)
    np.testing.assert_array_equal(got[:3], [EIG_TIE_DIRECTION, EIG_TIE_DIRECTION, [0, 1, 0]])
    # a double root of a diagonal matrix: the tie direction in the plane of its axes
    tie = EIG_TIE_DIRECTION * [1.0, 1.0, 0.0]
    np.testing.assert_allclose(got[3], tie / np.linalg.norm(tie), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(got[4], [1.0, 0.0, 0.0])  # the zero matrix
    # well separated: LAPACK's line
    cov, rotations = _rotated((1.0, 2.0, 3.0), range(5))
    got = smallest_eigenvectors(cov)
    assert np.allclose(np.abs(np.sum(got * rotations[:, :, 0], axis=1)), 1.0, atol=1e-12)


@compiled
def test_closed_form_chooses_as_numpy() -> None:
    double, _ = _rotated((1.0, 1.0, 3.0), range(50))
    separated, _ = _rotated((1.0, 2.0, 3.0), range(50, 60))
    triple = 5.0 * np.eye(3) + 1e-9 * _rotated((1.0, 2.0, 3.0), range(1))[0][0]
    diagonal = np.stack([np.diag([2.0, 1.0, 1.0]), np.diag([2.0, 1.0, 3.0]), np.zeros((3, 3))])
    cov = np.concatenate([double, separated, triple[None], diagonal])
    ref = smallest_eigenvectors(cov)
    fast = _compiled_eigvecs(cov)
    assert np.allclose(np.abs(np.sum(ref * fast, axis=1)), 1.0, rtol=0, atol=1e-9)
    tied = np.r_[0:50, 60:64]  # the chosen vectors themselves, not only their lines
    assert np.allclose(ref[tied], fast[tied], rtol=0, atol=1e-7)


@compiled
def test_grid_normals_and_distances_equal_in_both_paths() -> None:
    # interior points of a grid: double smallest eigenvalues at k = 16, 20 and 24 (about
    # 3, 76 and 12 % of them); the vectors LAPACK and the closed form took apart moved
    # projected distances by up to 0.08 of the spacing
    points = _shuffled_grid(12)
    out = {}
    for backend in ("numpy", "compiled"):
        out[backend] = detect(points, return_details=True, backend=backend)
    ref, fast = out["numpy"], out["compiled"]
    np.testing.assert_array_equal(fast.kept, ref.kept)
    ok = ~np.isnan(ref.distances)
    np.testing.assert_array_equal(ok, ~np.isnan(fast.distances))
    np.testing.assert_allclose(fast.distances[ok], ref.distances[ok], rtol=0, atol=1e-12)
    lines = np.abs(np.sum(fast.normals * ref.normals, axis=2))[ok]
    assert np.allclose(lines, 1.0, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fast.candidate_counts, ref.candidate_counts)


@compiled
@pytest.mark.slow
def test_grid_features_equal_in_memory_out_of_core_and_numpy() -> None:
    # a shuffled 16^3 grid: 219 features on every path (ties everywhere: the normals of
    # most interior points are chosen in a plane or all of space)
    points = _shuffled_grid(16)
    masks = {}
    for backend in ("numpy", "compiled"):
        masks[backend] = detect(points, backend=backend).mask
    masks["tiled"] = detect(points, max_memory="2GB").mask
    assert int(masks["compiled"].sum()) == 219
    np.testing.assert_array_equal(masks["numpy"], masks["compiled"])
    np.testing.assert_array_equal(masks["tiled"], masks["compiled"])
