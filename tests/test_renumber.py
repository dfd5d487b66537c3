"""The mesh ring pass over vertices renumbered breadth-first (``ms_bfs_renumber``, for
memory locality on meshes whose vertex order has none): every output bit the same as
over the caller's numbering, and the rule (``ms_scattered``) that turns it on."""

from __future__ import annotations

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp import _header, _kernels

pytestmark = pytest.mark.skipif(_kernels.default_backend() != "compiled", reason="no kernel")


def _meshes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    v, f = shapes.cube_grid_mesh(3)
    fv, ff, _ = shapes.fold_mesh(60.0)
    # two components and three isolated vertices between them
    two = np.concatenate([fv + 30.0, np.zeros((3, 3)), v])
    two_faces = np.concatenate([ff, f + len(fv) + 3])
    return {
        "cube": (v, f),
        "cube-shuffled": shapes.shuffled_mesh(v, f),
        "noisy-shuffled": shapes.shuffled_mesh(*shapes.noisy_mesh(v, f, 0.2, seed=3), seed=1),
        "two-parts-isolated": shapes.shuffled_mesh(two, two_faces, seed=2),
        "flat": (np.c_[shapes.flat_square(12)[:, :2], np.zeros(144)], _grid_faces(12)),
    }


def _grid_faces(m: int) -> np.ndarray:
    """The triangles of an m x m grid of vertices numbered row by row. (2 (m-1)^2, 3)."""
    q = np.arange(m * m).reshape(m, m)
    a, b, c, d = q[:-1, :-1], q[1:, :-1], q[:-1, 1:], q[1:, 1:]
    return np.concatenate([np.stack([a, b, d], -1), np.stack([a, d, c], -1)]).reshape(-1, 3)


MESHES = _meshes()


@pytest.mark.parametrize("relative", [False, True])
@pytest.mark.parametrize("normals", ["fixed", "pca"])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_the_renumbered_pass_gives_the_same_bits(name, normals, relative):
    v, f = MESHES[name]
    indptr, indices = _kernels.adjacency(f, len(v))
    fixed = None
    if normals == "fixed":  # some zero rows: PCA there
        fixed = np.random.default_rng(0).normal(size=v.shape)
        fixed[::4] = 0.0
    run = {
        on: _kernels.ring_projected_distances(
            v,
            indptr,
            indices,
            (1, 2, 4),
            fixed,
            keep_normals=not relative,
            relative=relative,
            renumber=on,
        )
        for on in (False, True)
    }
    for field in ("pdis", "normals", "relative", "score"):
        a, b = getattr(run[False], field), getattr(run[True], field)
        assert (a is None) == (b is None)
        if a is not None:
            assert a.tobytes() == b.tobytes(), field


def test_the_renumbering_keeps_each_list_in_order():
    v, f = MESHES["two-parts-isolated"]
    indptr, indices = _kernels.adjacency(f, len(v))
    n = len(v)
    order, rank = np.empty(n, np.int32), np.empty(n, np.int32)
    ptr, idx = np.empty(n + 1, np.int64), np.empty(len(indices), np.int32)
    at = np.empty_like(v)
    _kernels._LIB.ms_bfs_renumber(
        *(_kernels._ptr(a) for a in (indptr, indices)), n, _kernels._ptr(v), None,
        *(_kernels._ptr(a) for a in (order, rank, ptr, idx, at)), None,
    )  # fmt: skip
    assert sorted(order) == list(range(n)) and np.array_equal(rank[order], np.arange(n))
    assert order[0] == 0  # the search starts at the lowest vertex
    np.testing.assert_array_equal(at, v[order])
    for k in range(n):
        old = order[k]
        np.testing.assert_array_equal(
            order[idx[ptr[k] : ptr[k + 1]]], indices[indptr[old] : indptr[old + 1]]
        )


def test_the_rule_renumbers_only_a_scattered_order():
    gap = _header.integer("SCATTERED_GAP")
    m = 320  # a 102,400-vertex grid numbered row by row: gaps of 1 and m
    x, y = np.meshgrid(np.arange(m, dtype=float), np.arange(m, dtype=float))
    v, f = np.column_stack([x.ravel(), y.ravel(), np.sin(x.ravel() / 7)]), _grid_faces(m)
    assert len(v) > 4 * gap
    assert not _kernels.scattered(*_kernels.adjacency(f, len(v)))
    sv, sf = shapes.shuffled_mesh(v, f)
    assert _kernels.scattered(*_kernels.adjacency(sf, len(sv)))
    small = shapes.shuffled_mesh(*shapes.cube_grid_mesh(3))  # fewer vertices than the gap
    assert not _kernels.scattered(*_kernels.adjacency(small[1], len(small[0])))


@pytest.mark.parametrize("mode", ["paper", "robust"])
def test_detect_is_the_same_with_and_without_the_renumbering(monkeypatch, mode):
    v, f = shapes.shuffled_mesh(*shapes.noisy_mesh(*shapes.cube_grid_mesh(5), 0.05, seed=4), seed=5)
    results, asked = [], []

    def rule(on: bool) -> object:
        return lambda indptr, indices: asked.append(on) or on

    for on in (False, True):
        monkeypatch.setattr(_kernels, "scattered", rule(on))
        results.append(meshlab_sharp.detect(v, f, mode=mode))
    assert False in asked and True in asked  # the ring pass asked the rule both times
    a, b = results
    assert a.scales == b.scales
    for field in ("thresholds", "candidate_counts", "mask", "strength"):
        x, y = np.asarray(getattr(a, field)), np.asarray(getattr(b, field))
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), field
    assert a.n_features > 0
