"""Vertices renumbered breadth-first (``ms_bfs_renumber``, for memory locality on meshes
whose vertex order has none): by the ring pass and by ``detect`` right after cleaning
(``clean(..., local_order=True)``), every output bit the same as over the caller's numbering,
and the rule (``ms_scattered``, ``ms_scattered_faces``) that turns it on."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp import _header, _kernels, cleaning
from meshlab_sharp.io import as_geometry
from meshlab_sharp.reference import detect as reference_sequence

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
from bench import cad_mesh

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
        # the Python-driven sequence asks the rule; ms_detect decides inside
        results.append(reference_sequence.detect(v, f, mode=mode, backend="compiled"))
    assert False in asked and True in asked  # the ring pass asked the rule both times
    a, b = results
    assert a.scales == b.scales
    for field in ("thresholds", "candidate_counts", "mask", "strength"):
        x, y = np.asarray(getattr(a, field)), np.asarray(getattr(b, field))
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), field
    assert a.n_features > 0


def _vertices_shuffled(
    vertices: np.ndarray, faces: np.ndarray, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The mesh with its vertices in random order, its faces (and their corners) in the
    same order: (n, 3) vertices, (m, 3) faces and the permutation (n,) (new vertex i is
    old vertex ``perm[i]``)."""
    perm = np.random.default_rng(seed).permutation(len(vertices))
    rank = np.empty_like(perm)
    rank[perm] = np.arange(len(perm))
    return vertices[perm], rank[faces], perm


def _partly_shuffled(faces: np.ndarray, n: int, fraction: float, seed: int) -> np.ndarray:
    """``faces`` with a random ``fraction`` of the n vertices numbered among themselves
    at random (the others keep their numbers): about that fraction of far first
    neighbours, the rule's vote near its edge."""
    rng = np.random.default_rng(seed)
    moved = rng.choice(n, int(fraction * n), replace=False)
    number = np.arange(n)
    number[moved] = rng.permutation(moved)
    return number[faces]


def _rule_cases() -> dict[str, tuple[np.ndarray, int]]:
    """Faces and vertex counts on both sides of the rule and at its edge."""
    v, f = cad_mesh(80_000)
    n = len(v)
    cases = {
        "grid": (f, n),
        "shuffled": (_vertices_shuffled(v, f, 1)[1], n),
        "faces-shuffled-too": (shapes.shuffled_mesh(v, f, seed=2)[1], n),
        "small-shuffled": (lambda sv, sf: (sf, len(sv)))(
            *shapes.shuffled_mesh(*shapes.cube_grid_mesh(3))
        ),
        # vertices without faces (some sampled), and a face using a vertex twice
        "unreferenced": (np.concatenate([f[::2] * 2, [[4, 4, 6]]]), 2 * n),
    }
    for fraction in (0.45, 0.5, 0.55, 0.6):
        for seed in range(3):
            cases[f"part-{fraction}-{seed}"] = (_partly_shuffled(f, n, fraction, seed), n)
    return cases


RULE_CASES = _rule_cases()


@pytest.mark.parametrize("name", sorted(RULE_CASES))
def test_the_rule_from_the_faces_is_the_rule_on_the_adjacency(name):
    faces, n = RULE_CASES[name]
    assert _kernels.scattered_faces(faces, n) == _kernels.scattered(*_kernels.adjacency(faces, n))


@pytest.mark.parametrize("name", ["grid", "shuffled", "part-0.5-0", "part-0.55-1"])
def test_the_rule_from_the_faces_maps_them_as_cleaning_merges_duplicates(name):
    """Faces over an input with duplicates, mapped through ``remap`` (input -> merged
    vertex) inside the rule: the rule of the mapped faces' adjacency."""
    faces, n = RULE_CASES[name]
    rng = np.random.default_rng(5)
    dup_of = rng.choice(n, n // 3, replace=False)  # vertices with a duplicate n + j
    duplicate = np.full(n, -1)
    duplicate[dup_of] = n + np.arange(len(dup_of))
    faces_in = np.where((duplicate[faces] >= 0) & (rng.random(faces.shape) < 0.5),
                        duplicate[faces], faces)  # fmt: skip
    remap = np.concatenate([np.arange(n), dup_of])
    assert not np.array_equal(faces_in, faces)
    np.testing.assert_array_equal(remap[faces_in], faces)
    want = _kernels.scattered(*_kernels.adjacency(faces, n))
    assert _kernels.scattered_faces(faces_in, n, remap) == want


def test_the_rule_cases_fall_on_both_sides():
    answers = {name: _kernels.scattered_faces(*case) for name, case in RULE_CASES.items()}
    assert answers["shuffled"] and answers["faces-shuffled-too"]
    assert not answers["grid"] and not answers["small-shuffled"]
    edge = [answers[name] for name in answers if name.startswith("part-")]
    assert any(edge) and not all(edge)


def _clean_mesh(
    vertices: np.ndarray, faces: np.ndarray, local_order: bool
) -> cleaning.CleanGeometry:
    return cleaning.clean(
        as_geometry(vertices, faces), backend="compiled", workers=-1, local_order=local_order
    )


def _bench_mesh_with(dropped: bool) -> tuple[np.ndarray, np.ndarray]:
    """cad_mesh(80_000) (whose vertices have duplicates) with, when ``dropped``, an
    unreferenced vertex and a zero-area face more."""
    v, f = cad_mesh(80_000)
    if dropped:
        v = np.concatenate([v, v[:7], [[9.0, 9.0, 9.0]]])
        f = np.concatenate([f, [[len(v) - 8, 1, 2], [0, 1, 0]]])
    return v, f


@pytest.mark.parametrize("dropped", [False, True])
def test_a_scattered_mesh_is_renumbered_keeping_its_faces_and_lists_in_order(dropped):
    sv, sf, _ = _vertices_shuffled(*_bench_mesh_with(dropped), 3)
    before, after = _clean_mesh(sv, sf, False), _clean_mesh(sv, sf, True)
    assert after.renumbered and not before.renumbered and before.adjacency is None
    order = before.from_input[after.to_input]  # new vertex k: old vertex order[k]
    assert sorted(order) == list(range(len(before.vertices)))
    assert after.vertices.tobytes() == before.vertices[order].tobytes()
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    assert after.faces.dtype == np.int64
    np.testing.assert_array_equal(after.faces, rank[before.faces])  # same faces, same corners
    kept = before.from_input >= 0
    np.testing.assert_array_equal(after.from_input[kept], rank[before.from_input[kept]])
    np.testing.assert_array_equal(after.from_input[~kept], -1)
    assert (~kept).sum() == dropped
    np.testing.assert_array_equal(after.to_input, before.to_input[order])
    adjacency = _kernels.adjacency(after.faces, len(after.vertices))
    assert not _kernels.scattered(*adjacency)  # the ring pass does not renumber again
    if dropped:  # the lists would not be the faces' own
        assert after.adjacency is None
    else:  # the lists handed on are the renumbered mesh's own, each in its order
        assert after.adjacency is not None
        for got, want in zip(after.adjacency, adjacency, strict=True):
            assert got.dtype == want.dtype and got.tobytes() == want.tobytes()
    values = np.arange(len(after.vertices), dtype=float)
    back = after.to_input_order(values, -1.0)
    np.testing.assert_array_equal(back[kept], rank[before.from_input[kept]])
    np.testing.assert_array_equal(back[~kept], -1.0)


@pytest.mark.parametrize(
    "mesh",
    [
        cad_mesh(80_000),  # local order
        shapes.shuffled_mesh(*shapes.cube_grid_mesh(3)),  # scattered but small
        (shapes.cube_grid_points(21), None),  # a cloud
    ],
)
def test_a_local_mesh_or_a_cloud_is_cleaned_as_without_the_option(mesh):
    plain = cleaning.clean(as_geometry(*mesh), backend="compiled")
    local = cleaning.clean(as_geometry(*mesh), backend="compiled", local_order=True)
    assert not local.renumbered and local.adjacency is None
    for field in ("vertices", "faces", "to_input", "from_input"):
        x, y = getattr(plain, field), getattr(local, field)
        assert (x is None) == (y is None)
        if x is not None:
            assert x.tobytes() == y.tobytes(), field


def test_the_numpy_backend_does_not_renumber():
    sv, sf, _ = _vertices_shuffled(*cad_mesh(80_000), 1)
    cleaned = cleaning.clean(as_geometry(sv, sf), backend="numpy", local_order=True)
    assert not cleaned.renumbered
    assert np.all(np.diff(cleaned.to_input) > 0)


def _detect_inputs() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    v, f = cad_mesh(80_000)
    fold_v, fold_f, _ = shapes.fold_mesh(60.0, m=200, steps=3)  # 80,601 vertices
    extra = np.concatenate([v, v[:5], [[9.0, 9.0, 9.0]]])  # duplicates, unreferenced
    return {
        "bench": (v, f),
        "noisy": shapes.noisy_mesh(v, f, 0.1, seed=2),
        "noisy-fold": shapes.noisy_mesh(fold_v, fold_f, 0.2, seed=3),
        "duplicates": (extra, np.concatenate([f, [[len(v) + 1, 1, 2], [0, 3, 0]]])),
    }


DETECT_INPUTS = _detect_inputs()


def _same_after_mapping(
    a: meshlab_sharp.DetectionResult,
    b: meshlab_sharp.DetectionResult,
    perm: np.ndarray,
    *,
    exact: bool = True,
) -> None:
    """``b`` (on the vertices ``perm`` of ``a``'s input) is ``a``, bit for bit; with
    ``exact`` False the distances and normals to round-off only (the compiled backend
    against the numpy one: tests/test_equivalence.py's tolerance)."""
    assert a.scales == b.scales and a.n_clean == b.n_clean
    for field in ("thresholds", "candidate_counts"):
        x, y = getattr(a, field), getattr(b, field)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), field
    for field in ("mask", "strength", "kept"):
        x, y = getattr(a, field)[perm], getattr(b, field)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), field
    for field in ("distances", "normals"):
        x, y = getattr(a, field), getattr(b, field)
        assert x is not None and y is not None
        if exact:
            assert x[:, perm].tobytes() == y.tobytes(), field
        else:
            np.testing.assert_allclose(x[:, perm], y, rtol=0, atol=1e-6, err_msg=field)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("mode", ["paper", "robust"])
@pytest.mark.parametrize("name", sorted(DETECT_INPUTS))
def test_detect_on_the_mesh_shuffled_is_detect_on_the_mesh(monkeypatch, name, mode, seed):
    v, f = DETECT_INPUTS[name]
    sv, sf, perm = _vertices_shuffled(v, f, seed)
    renumbered = []
    plain = cleaning.clean

    def spy(*args, **kwargs) -> cleaning.CleanGeometry:
        out = plain(*args, **kwargs)
        renumbered.append(out.renumbered)
        return out

    monkeypatch.setattr(reference_sequence, "clean", spy)
    options = dict(mode=mode, return_details=True, backend="compiled")
    a = reference_sequence.detect(v, f, **options)
    b = reference_sequence.detect(sv, sf, **options)
    assert renumbered == [False, True]
    _same_after_mapping(a, b, perm)
    assert a.n_features > 0
    # the library's sequence (which renumbers in its own cleaning): the same bits
    c = meshlab_sharp.detect(sv, sf, **options)
    assert "thresholds" in c.timings
    _same_after_mapping(a, c, perm)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["paper", "robust"])
@pytest.mark.parametrize("name", ["noisy", "duplicates"])
def test_detect_on_the_mesh_shuffled_is_the_numpy_reference(name, mode):
    """The numpy path (never renumbered) gives the same bits on the mesh and on it
    shuffled, and the compiled one on the shuffled mesh (renumbered) its decisions."""
    v, f = DETECT_INPUTS[name]
    sv, sf, perm = _vertices_shuffled(v, f, 4)
    a = meshlab_sharp.detect(v, f, mode=mode, return_details=True, backend="numpy")
    b = meshlab_sharp.detect(sv, sf, mode=mode, return_details=True, backend="numpy")
    c = meshlab_sharp.detect(sv, sf, mode=mode, return_details=True, backend="compiled")
    _same_after_mapping(a, b, perm)
    _same_after_mapping(a, c, perm, exact=False)
