"""The compiled fast path gives the reference path's answers: same masks, same thresholds.

The reference is the numpy implementation (``backend="numpy"``: pymeshlab cleaning,
cKDTree, rings listed with numpy, ``np.linalg.eigh``); the fast path is the C kernels
(``backend="compiled"``). Neighbourhoods, cleaning and face normals must be identical;
projected distances agree to round-off (the smallest eigenvector is computed in closed
form instead of LAPACK), which may only change a point whose normalised distance lies
within 1e-9 of a threshold: none does in these shapes. No timings here.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from shapes import (
    box_cylinder_points,
    cube_grid_mesh,
    cube_grid_points,
    flat_square,
    random_box_points,
    random_rotation,
)

from meshlab_sharp import _kernels, detect
from meshlab_sharp.cleaning import clean
from meshlab_sharp.io import as_geometry
from meshlab_sharp.multiscale import run_scales
from meshlab_sharp.neighbourhoods import (
    KnnNeighbourhoods,
    Neighbourhood,
    RingNeighbourhoods,
    face_order_adjacency,
    grow_rings,
    knn,
    squared_distances,
)
from meshlab_sharp.normals import face_average_normals
from meshlab_sharp.reference.detect import (
    RelativeRule,
    isolated_from_stats,
    local_scale,
    median_noise_factor,
    noise_scale_factor,
    pass_noise_median,
    robust_threshold,
    sheet_mask,
)
from meshlab_sharp.reference.robust import isolated_points
from meshlab_sharp.robust import R_MIN, sheet_parameters
from meshlab_sharp.threshold import normalise, otsu_threshold

pytestmark = pytest.mark.skipif(
    not _kernels.available(),
    reason="compiled kernels not built: pip install -e . (needs gcc)",
)


def _both(vertices, faces=None, **options):
    out = {}
    for backend in ("numpy", "compiled"):
        out[backend] = detect(vertices, faces, backend=backend, return_details=True, **options)
    return out["numpy"], out["compiled"]


def _assert_same(ref, fast, *, distances=True, moved=0):
    np.testing.assert_array_equal(fast.thresholds, ref.thresholds)
    np.testing.assert_array_equal(fast.candidate_counts, ref.candidate_counts)
    np.testing.assert_array_equal(fast.mask, ref.mask)
    np.testing.assert_array_equal(fast.strength, ref.strength)
    np.testing.assert_array_equal(fast.kept, ref.kept)
    ok = ~np.isnan(ref.distances)
    assert np.array_equal(ok, ~np.isnan(fast.distances))
    if not distances:
        return
    # Round-off, larger only where the smallest eigenvalue is nearly double (the
    # eigenvector is then ill-conditioned in both implementations), and at ``moved``
    # points at most (robust mode: a gap within round-off of the sheet filter's limit).
    far = np.abs(np.where(ok, fast.distances - ref.distances, 0.0)) >= 1e-6
    assert int(far.any(axis=0).sum()) <= moved


def _shuffled(points, seed=3):
    return points[np.random.default_rng(seed).permutation(len(points))]


def _cad_like_points(n=6000, seed=5):
    """Rotated box with a cylinder, with duplicates and a shuffled order."""
    p = box_cylinder_points(n, seed=seed) @ random_rotation(seed).T
    p = np.concatenate([p, p[:: max(1, n // 50)]])
    return _shuffled(p, seed)


CLOUDS = {
    "box_cylinder": lambda: box_cylinder_points(4000),
    "random_box": lambda: random_box_points(3000, seed=2),
    "grid_cube_ties": lambda: cube_grid_points(21),
    "grid_cube_ties_shuffled": lambda: _shuffled(cube_grid_points(17)),
    "rotated_duplicates_shuffled": _cad_like_points,
    "plane_grid": lambda: flat_square(30),
}


@pytest.mark.parametrize("weighting", ["gaussian", "none"])
@pytest.mark.parametrize("name", sorted(CLOUDS))
def test_clouds_same_answers(name, weighting):
    ref, fast = _both(CLOUDS[name](), weighting=weighting)
    _assert_same(ref, fast)


def _mesh_with_junk():
    """Cube mesh with duplicated vertices (split faces), an unreferenced vertex, a
    degenerate face, in a shuffled vertex order."""
    v, f = cube_grid_mesh(3)
    n = len(v)
    v = np.concatenate([v, v[:10], [[5.0, 5.0, 5.0]]])
    f = f.copy()
    f[:10, 0] = np.where(f[:10, 0] < 10, f[:10, 0] + n, f[:10, 0])
    f = np.concatenate([f, [[0, 1, 1]]])
    perm = np.random.default_rng(1).permutation(len(v))
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(v))
    return v[perm], inv[f]


MESHES = {
    "cube_grid": lambda: cube_grid_mesh(4),
    "cube_rotated": lambda: (
        cube_grid_mesh(3)[0] @ random_rotation(4).T,
        cube_grid_mesh(3)[1],
    ),
    "cube_junk_shuffled": _mesh_with_junk,
}


@pytest.mark.parametrize("weighting", ["gaussian", "none"])
@pytest.mark.parametrize("name", sorted(MESHES))
def test_meshes_same_answers(name, weighting):
    v, f = MESHES[name]()
    ref, fast = _both(v, f, weighting=weighting)
    _assert_same(ref, fast)
    if name != "cube_junk_shuffled":
        # As a cloud with small k on this coarse regular grid, some neighbourhoods have
        # a double smallest eigenvalue (ALGORITHM.md: the normal is then not unique):
        # the reference's own thresholds change with the vertex order, so only the
        # unshuffled grids are compared. Robust mode's sheet filter reads the normal of
        # the 16 nearest, not unique either at the grid's corners: the neighbourhoods,
        # hence the distances, may differ there; every decision agrees.
        ref, fast = _both(v, f, weighting=weighting, as_points=True, scales=(8, 12, 16))
        _assert_same(ref, fast, distances=False)
        ref, fast = _both(
            v, f, mode="paper", weighting=weighting, as_points=True, scales=(8, 12, 16)
        )
        _assert_same(ref, fast)


def test_mesh_pca_fallback_same_answers():
    """Vertices whose face normals cancel (two faces back to back) use PCA of the ring."""
    v, f = cube_grid_mesh(2)
    f = np.concatenate([f, f[:4, ::-1]])
    ref, fast = _both(v, f)
    _assert_same(ref, fast)


@pytest.mark.parametrize("name", ["grid_cube_ties", "rotated_duplicates_shuffled", "random_box"])
def test_knn_identical_with_ties(name):
    points = clean(as_geometry(CLOUDS[name]()), backend="numpy").vertices
    fast = KnnNeighbourhoods(points, 40, backend="compiled")
    np.testing.assert_array_equal(fast.indices, knn(points, 40))
    np.testing.assert_array_equal(fast.at(12).indices, knn(points, 12).reshape(-1))


def _sphere(n: int, seed: int = 0) -> np.ndarray:
    """n random points on the unit sphere. (n, 3)."""
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def _far_outlier(n: int) -> np.ndarray:
    p = _sphere(n)
    p[-1] = 1e12
    return p


def _two_clusters(n: int) -> np.ndarray:
    p = _sphere(n)
    p[n // 2 :] += [1e9, -3e8, 2e9]
    return p


def _line(n: int) -> np.ndarray:
    p = np.zeros((n, 3))
    p[:, 0] = np.random.default_rng(1).random(n)
    return p


def _plane(n: int) -> np.ndarray:
    p = np.zeros((n, 3))
    p[:, :2] = np.random.default_rng(2).random((n, 2))
    return p


#: Spatial distributions that defeat a grid sized from the bounding box.
SPREADS = {
    "far_outlier_1e12": _far_outlier,
    "two_clusters_1e9_apart": _two_clusters,
    "line": _line,
    "plane": _plane,
}


def _run_on_points(
    script: str,
    points: np.ndarray,
    result: Path,
    *,
    timeout: float,
    env: dict[str, str] | None = None,
):
    """Run ``script`` (argv: a .npy of ``points``, then ``result``) in a subprocess with a
    time limit against a hang, from the repository root, ``env`` added to the
    environment; ``np.load(result)``."""
    source = result.with_name("points.npy")
    np.save(source, points)
    root = Path(__file__).resolve().parent.parent
    subprocess.run(
        [sys.executable, "-c", script, source, result],
        check=True,
        timeout=timeout,
        cwd=root,
        env={**os.environ, "PYTHONPATH": str(root), **(env or {})},
    )
    return np.load(result)


_COMPILED_KNN = """
import sys
import numpy as np
from meshlab_sharp.neighbourhoods import KnnNeighbourhoods
np.save(sys.argv[2], KnnNeighbourhoods(np.load(sys.argv[1]), 40, backend="compiled").indices)
"""


@pytest.mark.parametrize("name", ["grid_cube_ties", "random_box"])
def test_knn_identical_without_the_avx2_scan(name, tmp_path):
    """The kNN's block scan on 4 lanes (AVX2, where the CPU has it) and the plain one
    (``MESHLAB_SHARP_NO_AVX2``) give the same table, the numpy one, ties included."""
    points = clean(as_geometry(CLOUDS[name]()), backend="numpy").vertices
    env = {"MESHLAB_SHARP_NO_AVX2": "1"}
    plain = _run_on_points(_COMPILED_KNN, points, tmp_path / "knn.npy", timeout=60, env=env)
    np.testing.assert_array_equal(plain, knn(points, 40))


def _grid_near_ties() -> np.ndarray:
    """A shuffled grid on a cube's faces, each coordinate moved by at most 1e-12 (the
    spacing is 1/7): its tied squared distances differ, by far less than a float's
    precision. (1178, 3)"""
    p = _shuffled(cube_grid_points(15))
    return p + np.random.default_rng(4).uniform(-1e-12, 1e-12, p.shape)


@pytest.mark.parametrize("plain", [False, True])
def test_knn_identical_with_near_ties(plain, tmp_path):
    """Squared distances alike as floats but not as doubles: the compiled kNN, which
    ranks its candidates by their squared distances rounded to float, falls back on the
    exact (squared distance, index) order, with the AVX2 paths and without them
    (``MESHLAB_SHARP_NO_AVX2``); the table is the numpy one."""
    points = clean(as_geometry(_grid_near_ties()), backend="numpy").vertices
    if plain:
        env = {"MESHLAB_SHARP_NO_AVX2": "1"}
        table = _run_on_points(_COMPILED_KNN, points, tmp_path / "knn.npy", timeout=60, env=env)
    else:
        table = KnnNeighbourhoods(points, 40, backend="compiled").indices
    np.testing.assert_array_equal(table, knn(points, 40))


_COMPILED_PASS = """
import sys
import numpy as np
from meshlab_sharp import _kernels
from meshlab_sharp.robust import sheet_parameters
tree = _kernels.build_tree(np.load(sys.argv[1]))
out = {}
for scales in ((12, 16, 20, 24, 28, 32, 36, 40), (2, 9, 33, 106, 131)):
    for weighting in ("gaussian", "none"):
        for sheet in (None, sheet_parameters()):
            run = _kernels.cloud_projected_distances(
                tree, scales, weighting, keep_normals=True, relative=True, keep_pdis=True,
                noise_k=7, sheet=sheet,
            )
            key = f"{len(scales)}_{weighting}_{sheet is not None}"
            out.update({key + "_pdis": run.pdis, key + "_normals": run.normals})
            out.update({key + "_relative": run.relative, key + "_score": run.score})
            for name in ("near", "kth_d2", "kth_idx", "noise"):
                out[f"{key}_{name}"] = getattr(run.stats, name)
np.savez(sys.argv[2], **out)
"""


def _parallel_sheets() -> np.ndarray:
    """Two parallel integer grids 1.5 apart, the second shifted by half a step, shuffled:
    tied distances and heights, and sheets the filter cuts apart."""
    g = np.stack(np.meshgrid(np.arange(30.0), np.arange(30.0), indexing="ij"), -1).reshape(-1, 2)
    lower = np.column_stack([g, np.zeros(len(g))])
    upper = np.column_stack([g + 0.5, np.full(len(g), 1.5)])
    return _shuffled(np.concatenate([lower, upper]))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["parallel_sheets", "noisy_box_cylinder", "outliers_grid_ties"])
def test_pass_identical_without_the_avx2_paths(name, tmp_path):
    """The compiled cloud pass with its AVX2 paths (where the CPU has AVX2, FMA and
    POPCNT: the kNN scan, the sheet test's heights and their sort by ranks, the local
    scales' sums, the PCA's 4 lanes with fused multiply-adds) and without them
    (``MESHLAB_SHARP_NO_AVX2``) gives the same bits: normals, projected and relative
    distances, scores, the noise statistics; both weightings, with and without the
    sheet filter, 8 scales (two groups of 4) and 5 (a group of 1)."""
    cloud = _parallel_sheets() if name == "parallel_sheets" else ROBUST_CLOUDS[name]()
    points = np.unique(cloud, axis=0)
    fast = _run_on_points(_COMPILED_PASS, points, tmp_path / "fast.npz", timeout=120)
    env = {"MESHLAB_SHARP_NO_AVX2": "1"}
    plain = _run_on_points(_COMPILED_PASS, points, tmp_path / "plain.npz", timeout=120, env=env)
    assert sorted(fast.files) == sorted(plain.files) and len(fast.files) == 64
    for key in fast.files:
        np.testing.assert_array_equal(fast[key], plain[key], err_msg=key)
        assert fast[key].tobytes() == plain[key].tobytes(), key


_COMPILED_RING_PASS = """
import sys
import numpy as np
sys.path.insert(0, "tests")
from shapes import fold_mesh, noisy_mesh
from meshlab_sharp import _kernels
from meshlab_sharp.cleaning import clean
from meshlab_sharp.io import as_geometry
from meshlab_sharp.normals import face_average_normals
vertices, faces, _ = fold_mesh(60.0, 12, 2)
mesh = clean(as_geometry(*noisy_mesh(vertices, faces, 0.05)))
points, faces = mesh.vertices, mesh.faces
adjacency = _kernels.adjacency(faces, len(points))
out = {}
for rings in ((1, 2, 3, 4), (1, 3, 5)):
    for weighting in ("gaussian", "none"):
        for fixed in (None, face_average_normals(points, faces)):
            run = _kernels.ring_projected_distances(
                points, *adjacency, rings, fixed, weighting, keep_normals=True, relative=True
            )
            key = f"{len(rings)}_{weighting}_{fixed is not None}"
            out.update({key + "_normals": run.normals, key + "_relative": run.relative})
            out[key + "_score"] = run.score
np.savez(sys.argv[2], **out)
"""


def test_ring_pass_identical_without_the_avx2_paths(tmp_path):
    """The mesh twin of the test above: the compiled ring pass of robust mode (the local
    scales' sums on AVX2 lanes, where the CPU has AVX2) and without the AVX2 paths
    (``MESHLAB_SHARP_NO_AVX2``) gives the same bits: normals, relative distances and
    scores, both weightings, fixed face normals and PCA, 4 and 3 rings."""
    points = np.zeros((1, 3))  # the script builds its own mesh
    fast = _run_on_points(_COMPILED_RING_PASS, points, tmp_path / "fast.npz", timeout=120)
    env = {"MESHLAB_SHARP_NO_AVX2": "1"}
    plain = _run_on_points(
        _COMPILED_RING_PASS, points, tmp_path / "plain.npz", timeout=120, env=env
    )
    assert sorted(fast.files) == sorted(plain.files) and len(fast.files) == 24
    for key in fast.files:
        assert fast[key].tobytes() == plain[key].tobytes(), key


@pytest.mark.parametrize("name", ["grid_cube_ties_shuffled", "rotated_duplicates_shuffled"])
def test_tree_built_on_threads_is_the_one_call_tree(name):
    """``build_tree`` (the top levels' nodes, then the subtrees, on threads; the plugin
    builds it the same way) gives the tree of the kernel's one call ``ms_kdtree_build``:
    the same points in the same order and the same node boxes, ties included."""
    points = clean(as_geometry(CLOUDS[name]()), backend="numpy").vertices
    tree = _kernels.build_tree(points, workers=2)
    n = len(points)
    tp, orig, boxes = np.empty_like(points), np.empty(n, np.int64), np.empty_like(tree.boxes)
    _kernels._LIB.ms_kdtree_build(
        _kernels._ptr(points),
        n,
        tree.depth,
        _kernels._ptr(tp),
        _kernels._ptr(orig),
        _kernels._ptr(boxes),
    )
    assert tree.depth >= 4  # the threaded top levels and subtrees both run
    np.testing.assert_array_equal(tree.orig, orig)
    np.testing.assert_array_equal(tree.points, tp)
    np.testing.assert_array_equal(tree.boxes, boxes)


@pytest.mark.parametrize("name", ["grid_cube_ties_shuffled", "rotated_duplicates_shuffled"])
def test_tree_splits_at_medians_with_tight_boxes(name):
    """Every node of the kd-tree down to the leaves holds the median halves of its
    points along one axis (the sampled pivots of large ranges and the median of three
    of small ones: ties included), each leaf is split once more the same way, and each
    node's box is the tight box of its points."""
    points = clean(as_geometry(CLOUDS[name]()), backend="numpy").vertices
    points = np.concatenate([points, points * 2.0 + 0.5, points[::-1] * 3.0 - 1.0])
    tree = _kernels.build_tree(points, workers=2)
    assert tree.depth >= 6 and len(points) >= 2 * 512  # sampled pivots at the top
    np.testing.assert_array_equal(np.sort(tree.orig), np.arange(len(points)))
    np.testing.assert_array_equal(tree.points, points[tree.orig])
    spans = [(0, 0, len(points))]
    for d in range(tree.depth + 1):
        deeper = []
        for t, s, e in spans:
            part = tree.points[s:e]
            if d <= tree.depth:
                np.testing.assert_array_equal(tree.boxes[t], np.r_[part.min(0), part.max(0)])
            if e - s < 2:
                continue
            m = s + (e - s) // 2
            assert np.any(tree.points[s:m].max(0) <= tree.points[m:e].min(0)), (d, t)
            deeper += [(2 * t + 1, s, m), (2 * t + 2, m, e)]
        spans = deeper


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SPREADS))
def test_knn_any_spatial_distribution(name, tmp_path):
    """100k points. A far outlier or distant clusters made the former grid search
    quadratic (minutes); the kd-tree answers in about a second of CPU, so the compiled
    search runs in a subprocess with a generous time limit. Both backends give the same table,
    which agrees with brute force on sampled rows (the far point among them)."""
    points = np.unique(SPREADS[name](100_000), axis=0)
    compiled = _run_on_points(_COMPILED_KNN, points, tmp_path / "knn.npy", timeout=60)
    np.testing.assert_array_equal(compiled, knn(points, 40))
    rows = np.random.default_rng(0).choice(len(points), 100, replace=False)
    rows[0] = np.argmax(np.abs(points).max(axis=1))
    for i in rows:
        d2 = squared_distances(points, points[i])
        np.testing.assert_array_equal(compiled[i], np.lexsort((np.arange(len(points)), d2))[:40])


_COMPILED_DETECT = """
import sys
import numpy as np
from meshlab_sharp import detect
points = np.load(sys.argv[1])
masks = {m: detect(points, mode=m, backend="compiled").mask for m in ("paper", "robust")}
np.savez(sys.argv[2], **masks)
"""


@pytest.mark.slow
def test_detect_with_a_far_outlier_both_modes(tmp_path):
    """A scan with one stray point at 1e12, end to end, both modes
    (robust mode searches neighbours again for thinning), with the numpy reference's
    answer, in a subprocess with a time limit against a hang (a grid search is
    quadratic here; test_knn_any_spatial_distribution measures the search at 100k)."""
    points = _far_outlier(20_000)
    masks = _run_on_points(_COMPILED_DETECT, points, tmp_path / "masks.npz", timeout=150)
    for mode in ("paper", "robust"):
        reference = detect(points, mode=mode, backend="numpy").mask
        np.testing.assert_array_equal(masks[mode], reference, err_msg=mode)


def test_rings_identical():
    v, f = cube_grid_mesh(3)
    ref = RingNeighbourhoods(f, len(v), backend="numpy")
    fast = RingNeighbourhoods(f, len(v), backend="compiled")
    for ring in (1, 2, 3):
        a, b = ref.at(ring), fast.at(ring)
        np.testing.assert_array_equal(a.indptr, b.indptr)
        np.testing.assert_array_equal(a.indices, b.indices)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_cleaning_and_face_normals_identical(name):
    v, f = MESHES[name]()
    g = as_geometry(v, f)
    ref, fast = clean(g, backend="numpy"), clean(g, backend="compiled")
    for attr in ("vertices", "faces", "to_input", "from_input"):
        np.testing.assert_array_equal(getattr(fast, attr), getattr(ref, attr))
    a = face_average_normals(ref.vertices, ref.faces, backend="numpy")
    b = face_average_normals(ref.vertices, ref.faces, backend="compiled")
    assert np.array_equal(a, b)  # bit for bit


def _mesh_to_clean() -> tuple[np.ndarray, np.ndarray]:
    """A box of grids whose faces are stored apart (cleaning welds their seams), with
    zero-area faces early and late, unreferenced and duplicated vertices, a face using a
    merged vertex twice."""
    v, f = cube_grid_mesh(12)
    rng = np.random.default_rng(3)
    v = np.concatenate([v, v[:40], rng.normal(size=(5, 3))])  # duplicates, loose vertices
    n = len(v)
    dup = n - 45  # a duplicate of vertex 0, used by a face: merged into vertex 0
    flat = [[0, 1, 0], [2, 2, 3], [dup, 0, 1]]  # zero area (the last after merging)
    last = [[dup, 5, 6], [n - 5, n - 4, n - 3]]  # the last face's vertices used by it alone
    f = np.concatenate([flat, f[: len(f) // 3], flat, f[len(f) // 3 :], flat, last])
    return v, f


@pytest.mark.parametrize("smallest", [1, 7, 1 << 16])
def test_compiled_cleaning_identical_on_two_threads(smallest, monkeypatch):
    """The face pass split between two threads (the faces moved after the first half's
    dropped ones, the used vertices of both halves) gives pymeshlab's cleaning; the split
    is forced on this small mesh by lowering the size that starts it."""
    monkeypatch.setattr(_kernels, "_PARALLEL_FACES", smallest)
    g = as_geometry(*_mesh_to_clean())
    ref = clean(g, backend="numpy")
    assert len(ref.vertices) < len(g.vertices) and len(ref.faces) < len(g.faces)
    for workers in (1, 2, -1):
        fast = clean(g, backend="compiled", workers=workers)
        for attr in ("vertices", "faces", "to_input", "from_input"):
            np.testing.assert_array_equal(getattr(fast, attr), getattr(ref, attr))


@pytest.mark.parametrize("where", ["none", "second", "middle", "last", "signed zero"])
def test_merge_duplicates_copies_the_distinct_points(where):
    """``merge_duplicates``' distinct points (copied in its C pass, the rows before the
    first merged point at its end) are ``points[to_input]``; with no point merged, the
    points themselves."""
    p = np.random.default_rng(5).normal(size=(1000, 3))
    at = {"second": [1], "middle": [500, 501, 900], "last": [999], "signed zero": [700]}
    for i in at.get(where, []):
        p[i] = p[i // 3]
    if where == "signed zero":
        p[10] = 0.0
        p[700] = -0.0
    to_input, from_input, distinct = _kernels.merge_duplicates(p)
    assert len(to_input) == 1000 - len(at.get(where, []))
    np.testing.assert_array_equal(distinct, p[to_input])
    np.testing.assert_array_equal(
        to_input[from_input], [np.flatnonzero((p == q).all(1))[0] for q in p]
    )
    assert (distinct is p) == (where == "none")


def _first_occurrences(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference duplicate merge of the finite points ``p`` (n, 3): ``to_input`` (m,)
    and ``from_input`` (n,) from numpy's ``unique`` (its first index of each group is the
    first occurrence; ``+ 0.0`` makes -0.0 equal 0.0, as ``==`` has it)."""
    _, first, group = np.unique(p + 0.0, axis=0, return_index=True, return_inverse=True)
    survivor = first[group.reshape(-1)]
    to_input = np.unique(survivor)
    return to_input, np.searchsorted(to_input, survivor)


def _inputs_to_merge() -> dict[str, np.ndarray]:
    """Points to merge: duplicates near and far apart in the input, none, all equal, few
    values, signed zeros, tiny inputs."""
    rng = np.random.default_rng(11)
    x = rng.normal(size=(3000, 3))
    signed = rng.integers(-1, 2, size=(4000, 3)).astype(float)
    signed[rng.random(signed.shape) < 0.3] *= -1.0  # -0.0 where it was 0.0
    return {
        "far apart": np.concatenate([x, x[::-1], x[:700], x[2900:]]),
        "none": x,
        "all equal": np.full((5000, 3), 0.25),
        "few values": rng.integers(0, 3, size=(6000, 3)).astype(float),
        "signed zeros": signed,
        "mesh seams": _mesh_to_clean()[0],
        "empty": np.zeros((0, 3)),
        "one": x[:1],
        "two equal": np.zeros((2, 3)),
        "three": np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-0.0, 0.0, 0.0]]),
    }


@pytest.mark.parametrize("name", sorted(_inputs_to_merge()))
def test_merge_duplicates_matches_numpy(name):
    """``merge_duplicates`` gives numpy's first occurrences, in order, and their rows bit
    for bit (a -0.0 kept as -0.0 where it came first)."""
    p = _inputs_to_merge()[name]
    to_input, from_input, distinct = _kernels.merge_duplicates(p)
    ref_to, ref_from = _first_occurrences(p)
    np.testing.assert_array_equal(to_input, ref_to)
    np.testing.assert_array_equal(from_input, ref_from)
    assert to_input.dtype == from_input.dtype == np.int64
    assert distinct.tobytes() == p[ref_to].tobytes()
    assert (distinct is p) == (len(ref_to) == len(p))


def test_merge_duplicates_keeps_each_nan_point():
    """A point with a NaN equals no point (``==``), itself included: each one is a first
    occurrence (``detect`` rejects such input before cleaning)."""
    p = np.array([[np.nan, 0.0, 0.0], [np.nan, 0.0, 0.0], [1.0, 2.0, 3.0], [1.0, 2.0, 3.0]])
    to_input, from_input, distinct = _kernels.merge_duplicates(p)
    np.testing.assert_array_equal(to_input, [0, 1, 2])
    np.testing.assert_array_equal(from_input, [0, 1, 2, 2])
    assert distinct.tobytes() == p[:3].tobytes()


def test_cloud_cleaning_identical():
    p = _cad_like_points(3000)
    p[:5] = -0.0  # -0.0 and 0.0 are equal, as for pymeshlab
    p[5:8] = 0.0
    g = as_geometry(p)
    ref, fast = clean(g, backend="numpy"), clean(g, backend="compiled")
    for attr in ("vertices", "to_input", "from_input"):
        np.testing.assert_array_equal(getattr(fast, attr), getattr(ref, attr))


def test_eigenvectors_match_lapack():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(20000, 30, 3)) * np.array([1.0, 0.3, 1e-3])
    pts = pts @ random_rotation(1).T
    r = pts - pts.mean(axis=1, keepdims=True)
    cov = np.einsum("nij,nik->njk", r, r)
    ref = np.linalg.eigh(cov)[1][:, :, 0]
    fast = _kernels.smallest_eigenvectors(cov)
    err = np.minimum(np.abs(fast - ref).max(axis=1), np.abs(fast + ref).max(axis=1))
    assert err.max() < 1e-12


# ---------------------------------------------------------------------------- robust mode


def _noisy(points, fraction=0.5, seed=7):
    """Gaussian noise of ``fraction`` times the typical spacing along every axis: the
    noise estimate grows the scales."""
    rng = np.random.default_rng(seed)
    spacing = float(np.median(np.sqrt(squared_distances(points[knn(points, 2)[:, 1]], points))))
    return points + rng.normal(0.0, fraction * spacing, points.shape)


def _with_outliers(points, count=25, seed=8):
    rng = np.random.default_rng(seed)
    lo, hi = points.min(axis=0), points.max(axis=0)
    far = lo + (rng.random((count, 3)) * 3.0 - 1.0) * (hi - lo)
    return np.concatenate([points, far])


ROBUST_CLOUDS = {
    "noisy_box_cylinder": lambda: _noisy(box_cylinder_points(4000)),
    "outliers_random_box": lambda: _with_outliers(random_box_points(3000, seed=2)),
    "outliers_grid_ties": lambda: _with_outliers(_shuffled(cube_grid_points(15))),
    "noisy_outliers": lambda: _with_outliers(_noisy(_cad_like_points(4000))),
}


@pytest.mark.parametrize("name", sorted(ROBUST_CLOUDS))
def test_robust_clouds_same_answers(name):
    """Robust mode, both backends: the same isolated points, the same (noise-grown)
    scales, thresholds, candidates, masks and strengths."""
    ref, fast = _both(ROBUST_CLOUDS[name](), mode="robust")
    assert fast.scales == ref.scales
    _assert_same(ref, fast, moved=len(ref.mask) // 1000)


def test_robust_inputs_exercise_isolated_points_and_noise():
    """The cases above do what their names say (a guard on the inputs)."""
    noisy = detect(ROBUST_CLOUDS["noisy_box_cylinder"](), mode="robust", backend="compiled")
    assert max(noisy.scales) > 40
    outliers = detect(ROBUST_CLOUDS["outliers_random_box"](), mode="robust", backend="compiled")
    assert 0 < int((~outliers.kept).sum()) <= 25


@pytest.mark.parametrize("noisy", [False, True])
def test_robust_meshes_same_answers(noisy):
    vertices, faces = cube_grid_mesh(6)
    if noisy:
        vertices = vertices + np.random.default_rng(4).normal(0.0, 0.01, vertices.shape)
    ref, fast = _both(vertices, faces, mode="robust")
    _assert_same(ref, fast)


def _local_scale_both(points, lists):
    ref = local_scale(points, lists, backend="numpy")
    fast = local_scale(points, lists, backend="compiled")
    for a, b in zip(ref, fast, strict=True):
        assert np.array_equal(a, b)  # bit for bit: numpy's summation order


@pytest.mark.parametrize("k", [1, 2, 8, 9, 17, 40, 129, 130, 200])
def test_local_scale_identical_on_knn_lists(k):
    """The C sums reproduce numpy's add.reduceat (the first term plus a pairwise sum:
    sequential below 8 terms, 8 partial sums up to 128, split in two above)."""
    points = box_cylinder_points(1500) * 37.3
    _local_scale_both(points, KnnNeighbourhoods(points, k, backend="numpy").at(k))


def test_local_scale_identical_on_rings_and_empty_lists():
    vertices, faces = cube_grid_mesh(6)
    rings = RingNeighbourhoods(np.asarray(faces, np.int64), len(vertices), backend="numpy")
    for ring in (1, 2, 3):
        _local_scale_both(vertices, rings.at(ring))
    lists = Neighbourhood(np.array([0, 0, 2, 2, 5]), np.array([1, 0, 2, 0, 3]))
    _local_scale_both(vertices[:4], lists)


def test_pass_normals_of_a_subnormal_neighbourhood():
    """Neighbourhoods about 2^-515 across: their squared radii h2 are subnormal and 1 / h2
    overflows, yet the Gaussian weights exp(-d2 / h2) stay in (0, 1] (the pass divides,
    as numpy does): unit normals, the plane's, and zero projected distances."""
    rng = np.random.default_rng(3)
    plane = np.column_stack([rng.random((500, 2)), np.zeros(500)])
    tree = _kernels.build_tree(np.ldexp(plane, -515))
    run = _kernels.cloud_projected_distances(tree, (12, 16, 20, 24, 28), keep_normals=True)
    assert run.normals is not None and run.pdis is not None
    np.testing.assert_allclose(np.abs(run.normals[..., 2]), 1.0, atol=1e-6)
    assert np.all(run.pdis == 0.0)


@pytest.mark.parametrize("scales", [(12, 16, 20, 24, 28, 32, 36, 40), (2, 9, 33, 106, 131)])
def test_relative_distances_in_the_pass_identical(scales):
    """The relative distances and the score computed inside the kNN pass (local scales
    of the prefixes of one sorted list, the 8 partial sums shared between scales) are
    RelativeRule's arithmetic on the same projected distances, bit for bit."""
    points = _noisy(box_cylinder_points(2000))
    tree = _kernels.build_tree(points)
    fused = _kernels.cloud_projected_distances(tree, scales, relative=True, keep_pdis=True)
    assert fused.pdis is not None and fused.relative is not None
    lists = KnnNeighbourhoods(points, max(scales), backend="numpy")
    rule = RelativeRule(points, lists.at, len(scales))
    for i, k in enumerate(scales):
        r, threshold = rule(i, k, fused.pdis[i])
        assert np.array_equal(fused.relative[i], r)
        otsu, floor = rule.from_pass(rule.score, i, fused.relative[i])
        votes = np.zeros(len(points), np.int64)
        assert _kernels.scale_vote(fused.relative[i], votes, otsu=otsu, floor=floor) == (
            threshold,
            int((r >= threshold).sum()),
        )
    assert np.array_equal(fused.score, rule.score)


@pytest.mark.parametrize("relative", [False, True])
def test_scales_voted_in_tree_order_are_voted_in_cleaned_order(relative):
    """The pass's per-scale arrays left in the kd-tree's order (``tree_order``, what
    run_scales asks for) are the cleaned-order arrays permuted by ``order``, and
    run_scales votes, thresholds and keeps the same details from them: the votes and
    details moved to cleaned order after."""
    points = _noisy(box_cylinder_points(3000))
    scales = (12, 16, 20, 24, 28)
    lists = KnnNeighbourhoods(points, max(scales))
    tree = lists.tree
    assert tree is not None
    kw = {"keep_normals": True, "relative": relative}
    cleaned = _kernels.cloud_projected_distances(tree, scales, **kw)
    moved = _kernels.cloud_projected_distances(tree, scales, tree_order=True, **kw)
    assert cleaned.order is None and moved.order is tree.orig
    assert not np.array_equal(tree.orig, np.arange(len(points)))
    for name in ("pdis", "normals", "relative"):
        a, b = getattr(cleaned, name), getattr(moved, name)
        assert (a is None) == (b is None) == (name == ("pdis" if relative else "relative"))
        if a is not None:
            assert np.array_equal(a[:, tree.orig], b)
    if relative:
        assert np.array_equal(cleaned.score, moved.score)
    runs = []
    for fused in (cleaned, moved, None):
        rule = RelativeRule(points, lists.at, len(scales)) if relative else None
        how = {"keep_details": True, "rule": rule, "relative": relative, "fused": fused}
        runs.append(run_scales(points, lists, scales, **how))
    for got in runs[1:]:
        assert got.votes.tobytes() == runs[0].votes.tobytes()
        assert got.thresholds.tobytes() == runs[0].thresholds.tobytes()
        assert got.candidate_counts.tolist() == runs[0].candidate_counts.tolist()
        assert got.distances.tobytes() == runs[0].distances.tobytes()
        assert got.normals.tobytes() == runs[0].normals.tobytes()
    assert runs[0].votes.max() > 0 and runs[0].votes.min() < len(scales)


@pytest.mark.parametrize("name", ["outliers_random_box", "outliers_grid_ties", "noisy_outliers"])
def test_isolated_points_and_noise_from_one_search(name):
    """The pass's per-point statistics give isolated_points' answer without the kNN
    table (ties included), and the noise ratios agree with LAPACK's to round-off."""
    points = np.unique(ROBUST_CLOUDS[name](), axis=0)
    k_max = 40
    fused = _kernels.cloud_projected_distances(_kernels.build_tree(points), (12, k_max), noise_k=7)
    assert fused.stats is not None
    assert fused.stats.near.dtype == fused.stats.kth_idx.dtype == np.int32  # 8 B a point less
    table = knn(points, k_max)
    np.testing.assert_array_equal(fused.stats.near, table[:, 1])
    expected = isolated_points(points, table)
    assert expected.any()
    np.testing.assert_array_equal(isolated_from_stats(points, fused.stats), expected)
    assert median_noise_factor(fused.stats.noise) == pytest.approx(
        noise_scale_factor(points, table, 7), rel=1e-12
    )


@pytest.mark.parametrize(
    "name", ["outliers_random_box", "outliers_grid_ties", "noisy_outliers", "no_outliers"]
)
def test_statistics_left_in_tree_order(name):
    """The pass's statistics left in the kd-tree's order (``tree_order``, what robust
    mode's set-up asks for) are the cleaned-order ones permuted by the tree's ``orig``,
    ``near`` and ``kth_idx`` as tree positions; isolated_from_stats gives the same flags
    from them (ties included, and none when no point is isolated) and the noise median is
    the same."""
    cloud = ROBUST_CLOUDS.get(name, lambda: _noisy(box_cylinder_points(3000)))
    points = np.unique(cloud(), axis=0)
    tree = _kernels.build_tree(points)
    kw = {"relative": True, "noise_k": 7, "sheet": sheet_parameters()}
    cleaned = _kernels.cloud_projected_distances(tree, (12, 24, 40), **kw)
    moved = _kernels.cloud_projected_distances(tree, (12, 24, 40), tree_order=True, **kw)
    a, b = cleaned.stats, moved.stats
    assert a is not None and b is not None and a.tree is None and b.tree is tree
    assert not np.array_equal(tree.orig, np.arange(len(points)))
    np.testing.assert_array_equal(tree.orig[b.near], a.near[tree.orig])
    np.testing.assert_array_equal(tree.orig[b.kth_idx], a.kth_idx[tree.orig])
    for field in ("kth_d2", "nth_d2", "ref_d2", "noise"):
        assert getattr(b, field).tobytes() == getattr(a, field)[tree.orig].tobytes()
    expected = isolated_from_stats(points, a)
    assert expected.any() == (name != "no_outliers")
    np.testing.assert_array_equal(isolated_from_stats(points, b), expected)
    assert pass_noise_median(b.noise) == pass_noise_median(a.noise)


@pytest.mark.parametrize(
    ("dtype", "shape"),
    [(np.int32, ()), (np.float64, ()), (np.float64, (3,)), (np.int32, (3,)), (np.uint8, (5,))],
)
def test_to_cleaned_order_moves_rows_of_any_size(dtype, shape):
    """to_cleaned_order moves rows of 4 bytes (the statistics' int32 indices), 8 bytes
    and any other size (a normal's 24) to row orig[t], as numpy's scatter does."""
    rng = np.random.default_rng(3)
    n = 5000
    orig = rng.permutation(n).astype(np.int64)
    rows = rng.integers(-(2**31), 2**31 - 1, size=(n, *shape)).astype(dtype)
    expected = np.empty_like(rows)
    expected[orig] = rows
    _kernels.to_cleaned_order([rows], orig, workers=2)
    assert rows.tobytes() == expected.tobytes()


def _median_cases() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(4)
    return {
        "random": rng.random(100_001),
        "mostly_zero": np.concatenate([np.zeros(700), rng.random(300)]),
        "zero_at_the_median": np.concatenate([np.zeros(501), rng.random(500)]),
        "one_bin": 0.25 + rng.random(5000) * 1e-9,
        "subnormal_inf_nan": np.array([0.0, 5e-324, 1e-310, 1.0, np.inf, np.nan, np.nan]),
        "single": np.array([0.125]),
    }


@pytest.mark.parametrize("name", sorted(_median_cases()))
def test_lower_median_is_numpys(name):
    """The pass's noise median by a threaded histogram of bit patterns is the value
    np.partition puts at (n - 1) // 2 (NaN last); None for negative values and -0.0,
    whose bits do not sort."""
    values = _median_cases()[name]
    at = (len(values) - 1) // 2
    expected = np.partition(values, at)[at]
    for workers in (1, 2):
        got = _kernels.lower_median(values, workers)
        assert got is not None
        assert np.array_equal(got, expected, equal_nan=True)
    assert _kernels.lower_median(np.array([0.5, -0.0, 1.0])) is None
    assert _kernels.lower_median(np.array([0.5, -1.0, 1.0])) is None


def _fan_and_grid_mesh() -> tuple[np.ndarray, np.ndarray]:
    """A grid mesh plus a cone of 60 faces around one apex: valences 6 and 60 (rings of
    more than 129 vertices, whose sums numpy splits in two)."""
    vertices, faces = cube_grid_mesh(5)
    vertices, faces = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    t = np.linspace(0.0, 2.0 * np.pi, 60, endpoint=False)
    rim = np.stack([3.0 + np.cos(t), np.sin(t), np.zeros(60)], axis=1)
    apex = np.array([[3.0, 0.0, 1.5]])
    base = len(vertices)
    ring = base + 1 + np.arange(60)
    fan = np.stack([np.full(60, base), ring, np.roll(ring, -1)], axis=1)
    return np.vstack([vertices, apex, rim]), np.vstack([faces, fan])


def _relative_reference(vertices, faces, rings, normals):
    """RelativeRule's relative distances (s, n) and score (n,) over the numpy ring lists
    (``RingNeighbourhoods.at``), from the compiled pass's projected distances."""
    lists = RingNeighbourhoods(faces, len(vertices), backend="numpy")
    indptr, indices = _kernels.adjacency(faces, len(vertices))
    pdis = _kernels.ring_projected_distances(vertices, indptr, indices, rings, normals).pdis
    assert pdis is not None
    rule = RelativeRule(vertices, lists.at, len(rings))
    relative = np.stack([rule(s, k, pdis[s])[0] for s, k in enumerate(rings)])
    return relative, rule.score


def test_compiled_ring_pass_local_scales_identical_to_the_ring_lists():
    """The compiled ring pass sums each k-ring's local scale in breadth-first order,
    the order ``RingNeighbourhoods.at`` lists it, so its relative distances and score
    are the reference's, bit for bit (PCA and face normals, the valence-60 apex)."""
    vertices, faces = _fan_and_grid_mesh()
    indptr, indices = _kernels.adjacency(faces, len(vertices))
    for normals in (None, face_average_normals(vertices, faces, backend="compiled")):
        fused = _kernels.ring_projected_distances(
            vertices, indptr, indices, (1, 2, 4), normals, relative=True
        )
        assert fused.pdis is None and fused.relative is not None
        relative, score = _relative_reference(vertices, faces, (1, 2, 4), normals)
        assert np.array_equal(fused.relative, relative)
        assert np.array_equal(fused.score, score)


def _delaunay_mesh(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A bumpy height field over the Delaunay triangulation of n random points in the
    unit square, vertices in random order: valences from 3 to about 12 and rings whose
    order owes nothing to a grid."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    faces = Delaunay(xy).simplices.astype(np.int64)
    z = 0.1 * np.sin(7.0 * xy[:, 0]) * np.cos(5.0 * xy[:, 1])
    vertices = np.column_stack([xy, z])
    order = rng.permutation(n)  # vertex i of the mesh is old vertex order[i]
    new_index = np.empty(n, dtype=np.int64)
    new_index[order] = np.arange(n)
    return vertices[order], new_index[faces]


@pytest.mark.slow
def test_compiled_ring_pass_local_scales_identical_on_irregular_valences():
    """The ring pass's relative distances and score equal the reference's (numpy's ring
    lists and sums) bit for bit on an irregular mesh in random vertex order, over
    several chunks on two threads (each reusing its visit marks) and rings that skip
    one; the local scales there see the order (summed over the sorted rings instead,
    thousands of them change)."""
    vertices, faces = _delaunay_mesh(20000, seed=11)
    n = len(vertices)
    indptr, indices = _kernels.adjacency(faces, n)
    valences = np.diff(indptr)
    assert valences.min() <= 3 and valences.max() >= 10
    assert n > 2 * _kernels.CHUNK
    scales = (1, 2, 3, 5)
    fused = _kernels.ring_projected_distances(
        vertices, indptr, indices, scales, None, relative=True, workers=2
    )
    relative, score = _relative_reference(vertices, faces, scales, None)
    assert fused.relative is not None and fused.score is not None
    assert fused.relative.tobytes() == relative.tobytes()
    assert fused.score.tobytes() == score.tobytes()
    ring = RingNeighbourhoods(faces, n, backend="numpy").at(3)
    rows = np.repeat(np.arange(n), np.diff(ring.indptr))
    ordered = np.lexsort((ring.indices, rows))
    ell = local_scale(vertices, ring, backend="numpy")[0]
    by_index = local_scale(
        vertices, Neighbourhood(ring.indptr, ring.indices[ordered]), backend="numpy"
    )[0]
    assert int((ell != by_index).sum()) > 1000


def test_rings_in_breadth_first_order():
    """A fan of three triangles around vertex 0, adjacency in face order: each ring is
    the last one, then the vertices met walking its new members' lists."""
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    indptr, indices = face_order_adjacency(faces, 5)
    lists = [indices[indptr[v] : indptr[v + 1]].tolist() for v in range(5)]
    assert lists == [[1, 2, 3, 4], [0, 2], [0, 1, 3], [0, 2, 4], [0, 3]]
    for backend in ("numpy", "compiled"):
        rings = RingNeighbourhoods(faces, 5, backend=backend)
        one, two = rings.at(1), rings.at(2)
        with pytest.raises(ValueError, match="increasing order"):
            rings.at(1)
        assert one.indices[one.indptr[4] : one.indptr[5]].tolist() == [4, 0, 3]
        assert two.indices[two.indptr[4] : two.indptr[5]].tolist() == [4, 0, 3, 1, 2]
        assert two.indices[two.indptr[1] : two.indptr[2]].tolist() == [1, 0, 2, 3, 4]


def test_compiled_ring_members_identical_to_grow_rings():
    """_kernels.ring_members (robust mode's support, thinning and direction lists of the
    candidates) lists the rings of a few rows as grow_rings does, each a prefix of the
    largest, a ring asked for twice included."""
    vertices, faces = _delaunay_mesh(3000, seed=12)
    adjacency = _kernels.adjacency(faces, len(vertices))
    rows = np.sort(np.random.default_rng(2).choice(len(vertices), 400, replace=False))
    start, lengths, indices = _kernels.ring_members(adjacency, rows, (2, 2, 4))
    grown = grow_rings(face_order_adjacency(faces, len(vertices)), rows)
    expected = [next(grown) for _ in range(4)]
    assert lengths.shape == (3, len(rows))
    for length, k in zip(lengths, (2, 2, 4), strict=True):
        want = expected[k - 1]
        assert np.array_equal(length, want.sizes)
        got = [indices[s : s + n] for s, n in zip(start[:-1], length, strict=True)]
        assert np.array_equal(np.concatenate(got), want.indices)


def _adjacency_with_repeats(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's neighbours as its faces list them, repeats kept (both other corners
    of each face in face order): the lists the search read before they were deduplicated."""
    lists: list[list[int]] = [[] for _ in range(n)]
    for a, b, c in faces.tolist():
        lists[a] += [b, c]
        lists[b] += [a, c]
        lists[c] += [a, b]
    indptr = np.cumsum([0] + [len(x) for x in lists]).astype(np.int64)
    return indptr, np.array([w for x in lists for w in x], dtype=np.int32)


def test_adjacency_keeps_the_first_occurrence_and_the_search_order():
    """ms_adjacency lists each neighbour once, where its faces first list it; the
    breadth-first search over these lists meets the vertices in the order it meets them
    over the lists with repeats, so every ring's projected distance is the same, bit for
    bit, with face normals and with PCA (the fan's valence-60 apex included)."""
    vertices, faces = _fan_and_grid_mesh()
    n = len(vertices)
    indptr, indices = _kernels.adjacency(faces, n)
    full_ptr, full = _adjacency_with_repeats(faces, n)
    for v in range(n):
        row = full[full_ptr[v] : full_ptr[v + 1]].tolist()
        first = [w for t, w in enumerate(row) if w not in row[:t]]
        assert indices[indptr[v] : indptr[v + 1]].tolist() == first
    reference = face_order_adjacency(faces, n)
    assert np.array_equal(reference[0], indptr) and np.array_equal(reference[1], indices)
    normals = face_average_normals(vertices, faces, backend="compiled")
    for fixed in (normals, None):
        got = _kernels.ring_projected_distances(vertices, indptr, indices, (1, 2, 3, 5), fixed)
        ref = _kernels.ring_projected_distances(vertices, full_ptr, full, (1, 2, 3, 5), fixed)
        assert np.array_equal(got.pdis, ref.pdis)


def test_robust_mesh_with_a_high_valence_vertex_same_answers():
    vertices, faces = _fan_and_grid_mesh()
    ref, fast = _both(vertices, faces, mode="robust")
    _assert_same(ref, fast)


def test_dihedral_angles_identical():
    """The compiled pairing of faces gives the reference's edges and angles: two-face
    edges only (boundaries and a three-face, non-manifold edge left out), sorted."""
    from meshlab_sharp.creases import dihedral_angles

    vertices, faces = _fan_and_grid_mesh()
    extra = np.array([[0.5, 0.5, 3.0]])
    fin = np.array([[faces[0, 0], faces[0, 1], len(vertices)]])  # a third face on an edge
    vertices, faces = np.vstack([vertices, extra]), np.vstack([faces, fin])
    ref = dihedral_angles(vertices, faces, backend="numpy")
    fast = dihedral_angles(vertices, faces, backend="compiled")
    assert np.array_equal(ref[0], fast[0]) and np.array_equal(ref[1], fast[1])
    a, b = sorted(faces[0, :2])
    assert not ((ref[0][:, 0] == a) & (ref[0][:, 1] == b)).any()


def _threshold_inputs() -> dict[str, np.ndarray]:
    """Projected distances of several kinds: skewed, values on the bin edges (v * 256
    an integer after normalisation), ties, two values, one value, none, a flat scale."""
    rng = np.random.default_rng(13)
    edges = np.concatenate([np.arange(257) / 256.0, np.arange(257)[::3] / 256.0])
    return {
        "skewed": rng.exponential(0.01, 5000) * 37.0,
        "bin_edges": rng.permutation(edges) * 3.0 + 5.0,
        "ties": rng.integers(0, 7, 3000).astype(np.float64) * 0.125,
        "two": np.array([0.0, 1.0]),
        "one": np.array([2.5]),
        "none": np.zeros(0),
        "flat": 4.0 + rng.normal(0.0, 1e-12, 400),
    }


@pytest.mark.parametrize("name", sorted(_threshold_inputs()))
def test_compiled_threshold_and_votes_identical(name):
    """``_kernels.scale_vote`` (min-max normalisation, the 256-bin histogram, Otsu's
    split and the votes in one C call) gives threshold.py's values, threshold, counts
    and votes bit for bit; robust mode's form (no normalisation, a floor, or the floor
    alone) gives robust_threshold's."""
    x = _threshold_inputs()[name]
    flat_span = 1e-9
    v = normalise(x, flat_span=flat_span)
    t = otsu_threshold(v)
    votes = np.arange(len(x), dtype=np.int64)
    out = np.full(len(x), np.nan)
    assert _kernels.scale_vote(x, votes, flat_span=flat_span, out=out) == (t, int((v >= t).sum()))
    assert np.array_equal(out, v)
    assert np.array_equal(votes, np.arange(len(x)) + (v >= t))
    for otsu in (True, False):
        expected = robust_threshold(v, otsu)
        votes = np.zeros(len(x), np.int64)
        assert _kernels.scale_vote(v, votes, otsu=otsu, floor=R_MIN) == (
            expected,
            int((v >= expected).sum()),
        )
        assert np.array_equal(votes, v >= expected)


@pytest.mark.parametrize("noise", [0.0, 0.02])
def test_sharp_vertices_identical(noise):
    """The compiled sharp mesh edges (``crease_vertices``: each vertex's faces, no edge
    list) give the numpy reference's mask and threshold, on a mesh with creases, boundary
    edges and edges of three faces; with noise the lower quartile sets the threshold."""
    from meshlab_sharp.creases import CREASE_ANGLE, sharp_vertices

    vertices, faces = cube_grid_mesh(3)
    vertices = vertices + np.random.default_rng(3).normal(0.0, noise, vertices.shape)
    # a fin of two faces on one edge of the first face (three faces there), and a lone
    # face (three boundary edges)
    a, b = faces[0][:2]
    extra = len(vertices)
    vertices = np.vstack(
        [vertices, [[3.0, 3.0, 3.0], [5.0, 5.0, 6.0], [5.0, 6.0, 5.0], [6.0, 5.0, 5.0]]]
    )
    faces = np.vstack([faces, [[a, b, extra], [extra + 1, extra + 2, extra + 3]]])
    ref_mask, ref_threshold = sharp_vertices(vertices, faces, backend="numpy")
    mask, threshold = sharp_vertices(vertices, faces, backend="compiled")
    assert threshold == ref_threshold
    assert (threshold > np.radians(CREASE_ANGLE)) == (noise > 0)
    assert ref_mask.any() and not ref_mask.all()
    np.testing.assert_array_equal(mask, ref_mask)


@pytest.mark.parametrize("shuffle", [False, True])
@pytest.mark.parametrize("noise", [1e-3, 0.0])
def test_crease_dots_are_the_face_pairs_dots(shuffle, noise):
    """``ms_crease_dots`` (its face normals through a direct-mapped cache of 8192 faces)
    gives the dot products of ``ms_two_face_edges`` (each normal computed where it is
    used), bit for bit, as a multiset: those not >= 1 listed, the others counted as flat;
    on a mesh of 49,152 faces (noisy: few flat edges; clean: mostly flat), in their order
    and shuffled (neighbouring faces far apart: evictions and collisions in the cache)."""
    vertices, faces = cube_grid_mesh(6)
    vertices = vertices + np.random.default_rng(5).normal(0.0, noise, vertices.shape)
    if shuffle:
        faces = faces[np.random.default_rng(6).permutation(len(faces))]
    seen = []

    def keep(dots, flat):
        seen.append((dots.copy(), flat))
        return dots, np.inf

    _kernels.crease_vertices(vertices, faces, keep)
    _, expected = _kernels.two_face_edges(faces, vertices)
    assert len(expected) == len(faces) * 3 // 2
    dots, flat = seen[0]
    turned = expected[~(expected >= 1.0)]
    assert flat == len(expected) - len(turned) and (flat > len(turned)) == (noise == 0)
    assert np.sort(dots).tobytes() == np.sort(turned).tobytes()


@pytest.mark.parametrize("n", [1, 2, 1000])
def test_compiled_extent_is_numpy_ptp(n):
    """``_kernels.extent``, the flat rule's bounding box in one C pass, is numpy's ``ptp``
    of each column, bit for bit."""
    points = np.random.default_rng(n).normal(0.0, 1.0, (n, 3)) * [1e-3, 7.0, 1e5] - 2.5
    expected = [np.ptp(points[:, a]) for a in range(3)]
    np.testing.assert_array_equal(_kernels.extent(points), expected)


def test_sharp_vertices_identical_on_a_wide_fan():
    """A vertex with 150 faces (more than the compiled walk's small table holds, so its
    faces are read from the face array) and bumps on its rim: the same mask and threshold
    as the numpy reference, a part of the vertices sharp."""
    from meshlab_sharp.creases import sharp_vertices

    k = 150
    angle = np.linspace(0.0, 2.0 * np.pi, k, endpoint=False)
    rim = np.c_[np.cos(angle), np.sin(angle), np.where(np.arange(k) % 10 == 0, 0.3, 0.0)]
    points = np.vstack([[0.0, 0.0, 0.0], rim])
    faces = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)])
    ref_mask, ref_threshold = sharp_vertices(points, faces, backend="numpy")
    mask, threshold = sharp_vertices(points, faces, backend="compiled")
    assert threshold == ref_threshold
    assert 0 < ref_mask.sum() < len(points)
    np.testing.assert_array_equal(mask, ref_mask)


def _no_gap(v: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The compiled filter's ``no_gap`` per row of values v (r, k) with gaps g (r,): whether
    it shows that no step between sorted values exceeds g without sorting (buckets 0.18 g
    wide, none 4 in a row empty), and whether it fell back on ``max - min <= g`` (63
    buckets or more)."""
    lo, hi = v.min(axis=1), v.max(axis=1)
    with np.errstate(all="ignore"):
        s = 1.0 / (0.18 * g)
        few = (hi - lo) * s < 63.0
        b = np.where(few[:, None], (v - lo[:, None]) * s[:, None], 0.0).astype(np.int64)
    close = (np.diff(np.sort(b, axis=1), axis=1) <= 4).all(axis=1)
    return np.where(few, close, hi - lo <= g), ~few


def _sheet_branches(points: np.ndarray, idx: np.ndarray, normals: np.ndarray) -> dict[str, int]:
    """How many rows of the sheet filter's first pass (heights along ``normals``) take each
    branch of the compiled filter: kept whole by sheet_keep's first test, by no_gap on
    both rules (no sort), rule 1 without a gap but the column sorted, rule 1 sorted,
    no_gap's fallback on the range."""
    gap, _, _, column, column_gap, _, trim, _ = sheet_parameters()
    q = points[idx] - points[: len(idx), None, :]
    h = q[..., 0] * normals[:, 0:1] + q[..., 1] * normals[:, 1:2] + q[..., 2] * normals[:, 2:3]
    d2 = q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1] + q[..., 2] * q[..., 2]
    dist = np.sqrt(d2)
    a = dist[:, 1].copy()
    for j in range(2, 7):
        a = a + dist[:, j]
    a = a / 6
    span = h.max(axis=1) - h.min(axis=1)
    first = (span <= gap * a) & (span <= column_gap * a) & (span <= trim * a)
    rule1, fell1 = _no_gap(h, gap * a)
    c = column * a
    col, fell2 = _no_gap(np.where(d2 - h * h <= (c * c)[:, None], h, 0.0), column_gap * a)
    past = ~first
    return {
        "first test": int(first.sum()),
        "no sort": int((past & rule1 & col).sum()),
        "column sorted": int((past & rule1 & ~col).sum()),
        "rule 1 sorted": int((past & ~rule1).sum()),
        "range fallback": int((past & (fell1 | (rule1 & fell2))).sum()),
    }


def _sheet_cases() -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Clouds with their kNN lists (k = 40) and normals for the sheet filter: the
    normals of the compiled pass, and (``turned``) the same turned by a random rotation
    of up to ~30 degrees (heights spread without gaps, lists past every shortcut)."""
    rng = np.random.default_rng(11)
    out = {}
    for name, cloud in (
        ("parallel_sheets", _parallel_sheets),
        ("noisy_box_cylinder", ROBUST_CLOUDS["noisy_box_cylinder"]),
        ("outliers_grid_ties", ROBUST_CLOUDS["outliers_grid_ties"]),
        ("box_cylinder", CLOUDS["box_cylinder"]),
    ):
        points = np.unique(cloud(), axis=0)
        tree = _kernels.build_tree(points)
        normals = _kernels.cloud_projected_distances(tree, (40,), keep_normals=True).normals[0]
        idx = knn(points, 40)
        out[name] = (points, idx, normals)
        turned = normals + rng.normal(0.0, 0.3, normals.shape)
        turned /= np.sqrt((turned * turned).sum(axis=1))[:, None]
        out[name + "_turned"] = (points, idx, turned)
    # a column of points along the normal 0.38 apart beside a ring of 6 nearer ones: the
    # heights span more than 63 of no_gap's buckets without a gap (its range fallback)
    turn = np.arange(6) / 6 * 2 * np.pi
    ring = np.column_stack([np.cos(turn), np.sin(turn), np.zeros(6)])
    line = np.column_stack([np.full(33, 1.2), np.zeros(33), 0.38 * (np.arange(33) - 16.0)])
    points = np.concatenate([[[0.0, 0.0, 0.0]], ring, line])
    idx = np.argsort(((points - points[0]) ** 2).sum(axis=1), kind="stable")[None, :]
    out["column_beside_ring"] = (points, idx, np.array([[0.0, 0.0, 1.0]]))
    return out


def test_sheet_filter_is_numpys():
    """The compiled pass's sheet filter (``ms_sheet_mask``: sheet_keep, its first test, the
    no_gap shortcuts that skip sorting the heights, the sorts by ranks) keeps exactly
    the neighbours that reference_sequence.sheet_mask keeps, on lists that take every branch: kept
    whole by the first test, by no_gap on both rules, the column sorted after rule 1
    showed no gap, rule 1 sorted (gaps: parallel sheets, ties of a grid, far outliers),
    no_gap's fallback on the range; rows dropping neighbours and rows kept whole."""
    totals: dict[str, int] = {}
    dropping = whole = 0
    for name, (points, idx, normals) in _sheet_cases().items():
        expected = sheet_mask(points, idx, normals)
        got = _kernels.sheet_mask(points, idx, normals, sheet_parameters())
        np.testing.assert_array_equal(got, expected, err_msg=name)
        dropping += int((~expected).any(axis=1).sum())
        whole += int(expected.all(axis=1).sum())
        for key, count in _sheet_branches(points, idx, normals).items():
            totals[key] = totals.get(key, 0) + count
    assert dropping > 0 and whole > 0
    assert all(count > 0 for count in totals.values()), totals


@pytest.mark.parametrize("n_faces", [0, 1, 40])
def test_adjacency_with_vertices_no_face_lists(n_faces):
    """ms_adjacency (its cursors kept in the CSR starts themselves, moved up one place
    after the fill) gives face_order_adjacency's lists where the first, a middle and the
    last vertex have no face, with no face, one face, and faces of a shuffled grid."""
    vertices, faces = cube_grid_mesh(3)
    faces = faces[np.random.default_rng(7).permutation(len(faces))][:n_faces]
    n = len(vertices) + 3
    faces = np.where(faces >= len(vertices) // 2, faces + 2, faces + 1)  # 0, mid, n - 1 unused
    indptr, indices = _kernels.adjacency(faces, n)
    reference = face_order_adjacency(faces, n)
    assert np.array_equal(reference[0], indptr) and np.array_equal(reference[1], indices)
    assert indptr[1] == 0 and indptr[-1] == indptr[-2]
