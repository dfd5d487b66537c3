"""The mesh ring pass taking a vertex's search from the previous vertex's, every member
plus one, where the lists that search walked are shifted (``ms_shifted_lists``: a
grid-numbered mesh): the flags as numpy computes them, every output bit the same as
searching every vertex, and the pass really skipping the searches."""

from __future__ import annotations

import numpy as np
import pytest
import shapes

from meshlab_sharp import _kernels
from meshlab_sharp.normals import face_average_normals

pytestmark = pytest.mark.skipif(_kernels.default_backend() != "compiled", reason="no kernel")


def _grid(m: int, seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """An m x m grid of vertices numbered row by row (a height field, bumpy, plus noise
    when ``seed`` is given), its 2 (m - 1)^2 triangles in row order, then three
    isolated vertices and a fan of 1100 triangles around one apex (a 1-ring of 1101
    members: past the pass's first 1024 entries)."""
    q = np.arange(m * m).reshape(m, m)
    a, b, c, d = q[:-1, :-1], q[1:, :-1], q[:-1, 1:], q[1:, 1:]
    faces = np.stack([np.stack([a, b, d], -1), np.stack([a, d, c], -1)], 2).reshape(-1, 3)
    x, y = np.meshgrid(np.linspace(0.0, 1.0, m), np.linspace(0.0, 1.0, m), indexing="ij")
    v = np.column_stack([x.ravel(), y.ravel(), 0.2 * np.sin(5.0 * x.ravel()) * y.ravel()])
    v[(x.ravel() > 0.5) & (y.ravel() > 0.3), 2] += 0.1  # a step: sharp edges
    if seed is not None:
        v = v + np.random.default_rng(seed).normal(scale=0.3 / m, size=v.shape)
    t = np.linspace(0.0, 2.0 * np.pi, 1100, endpoint=False)
    rim = np.stack([3.0 + np.cos(t), np.sin(t), np.zeros(1100)], axis=1)
    isolated = np.array([[5.0, 5.0, 5.0], [6.0, 5.0, 5.0], [7.0, 5.0, 5.0]])
    base = len(v) + 3
    ring = base + 1 + np.arange(1100)
    fan = np.stack([np.full(1100, base), ring, np.roll(ring, -1)], axis=1)
    vertices = np.concatenate([v, isolated, [[3.0, 0.0, 1.5]], rim])
    return vertices, np.concatenate([faces, fan]).astype(np.int64)


def _meshes() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    v, f = shapes.cube_grid_mesh(6)
    return {
        "grid": _grid(100),
        "noisy-grid": _grid(100, seed=4),
        "cube": (np.asarray(v, np.float64), np.asarray(f, np.int64)),
        "cube-shuffled": shapes.shuffled_mesh(np.asarray(v, np.float64), np.asarray(f, np.int64)),
    }


MESHES = _meshes()


def _numpy_shifted(indptr: np.ndarray, indices: np.ndarray) -> np.ndarray:
    n = len(indptr) - 1
    lists = [indices[indptr[w] : indptr[w + 1]] for w in range(n)]
    same = [
        len(lists[w + 1]) == len(lists[w]) and (lists[w + 1] == lists[w] + 1).all()
        for w in range(n - 1)
    ]
    return np.array(same + [False], dtype=np.uint8)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_shifted_lists_are_numpys(name):
    v, f = MESHES[name]
    indptr, indices = _kernels.adjacency(f, len(v))
    flags = _kernels.shifted_lists(indptr, indices, workers=2)
    assert flags.dtype == np.uint8 and flags.tobytes() == _numpy_shifted(indptr, indices).tobytes()
    if "grid" in name:  # the grid's interior, the isolated vertices but the last
        assert flags.sum() > 0.9 * 100 * 100 and flags[100 * 100 : 100 * 100 + 2].all()
    if name == "cube-shuffled":
        assert flags.sum() < 0.05 * len(v)


def _marks(v, indptr, indices, rings, fixed, follow):
    """The distinct marks ms_ring_pdis leaves in its visit marks on one thread (each a
    searched vertex's own index: the last search to meet each vertex), and its projected
    distances."""
    n = len(v)
    rs = np.asarray(rings, np.int64)
    stamp = np.full(n, -1, np.int32)
    pdis = np.empty((len(rs), n))
    shifted = _kernels.shifted_lists(indptr, indices) if follow else None
    p = _kernels._ptr
    rc = _kernels._LIB.ms_ring_pdis(
        p(v), n, p(indptr), p(indices), p(fixed), p(rs), len(rs), 1, 0, n, p(stamp), None,
        p(shifted), p(pdis), None, None, None,
    )  # fmt: skip
    assert rc == 0
    return np.unique(stamp[stamp >= 0]), pdis


def test_the_pass_follows_on_a_grid():
    """On the noisy grid most vertices are not searched: the marks left come from a few
    searched vertices (without the flags, from most vertices); the distances agree."""
    v, f = MESHES["noisy-grid"]
    indptr, indices = _kernels.adjacency(f, len(v))
    fixed = face_average_normals(v, f)
    followed, pdis = _marks(v, indptr, indices, (1, 2, 4), fixed, True)
    every, pdis_every = _marks(v, indptr, indices, (1, 2, 4), fixed, False)
    assert len(every) > 0.7 * len(v)
    assert len(followed) < 0.15 * len(v)
    assert pdis.tobytes() == pdis_every.tobytes()


@pytest.mark.parametrize("relative", [False, True])
@pytest.mark.parametrize("normals", ["fixed", "pca"])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_following_gives_the_same_bits(name, normals, relative):
    """Every output (distances or relative distances and score, normals) the same with
    and without following, on two threads over several chunks, both weightings, rings
    that skip some and one of more than 1024 members (the queue grown)."""
    v, f = MESHES[name]
    indptr, indices = _kernels.adjacency(f, len(v))
    fixed = None
    if normals == "fixed":  # face normals, some zero rows: PCA there
        fixed = face_average_normals(v, f)
        fixed[::7] = 0.0
    for rings, weighting in (((1, 2, 4), "gaussian"), ((1, 3, 20), "none")):
        run = {
            follow: _kernels.ring_projected_distances(
                v,
                indptr,
                indices,
                rings,
                fixed,
                weighting,
                keep_normals=True,
                relative=relative,
                workers=2,
                follow=follow,
            )
            for follow in (False, True)
        }
        for field in ("pdis", "normals", "relative", "score"):
            a, b = getattr(run[False], field), getattr(run[True], field)
            assert (a is None) == (b is None), field
            if a is not None:
                assert a.tobytes() == b.tobytes(), (field, rings)
    if name.endswith("grid"):
        assert len(v) > _kernels.CHUNK and np.diff(indptr).max() == 1100


def test_following_on_the_renumbered_pass():
    """A shuffled grid renumbered breadth-first (its lists then shifted nowhere much)
    gives the same bits following or not, as the grid in its own order."""
    v, f = MESHES["noisy-grid"]
    sv, sf = shapes.shuffled_mesh(v, f, seed=5)
    outs = []
    for verts, faces, renumber in ((v, f, False), (sv, sf, True)):
        indptr, indices = _kernels.adjacency(faces, len(verts))
        fixed = face_average_normals(verts, faces)
        for follow in (False, True):
            run = _kernels.ring_projected_distances(
                verts, indptr, indices, (1, 2, 4), fixed, relative=True,
                renumber=renumber, follow=follow,
            )  # fmt: skip
            assert run.relative is not None and run.score is not None
            outs.append((run.relative, run.score, renumber))
    assert outs[0][0].tobytes() == outs[1][0].tobytes()
    assert outs[2][0].tobytes() == outs[3][0].tobytes()
    assert outs[2][1].tobytes() == outs[3][1].tobytes()
