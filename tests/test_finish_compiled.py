"""Robust mode's finishing steps in C (``ms_line_directions``, ``ms_supported``,
``ms_smoothed_ranking``, ``ms_thin``, ``ms_acute_tips``; ``_kernels.support_and_thin``
and ``_kernels.acute_tips``, ``reference.detect.RobustSetup._finish_compiled``) against their numpy
reference (``reference_robust.line_directions``, ``supported``, ``smoothed_ranking``, ``thin``,
``acute_tips``, ``RobustSetup._finish_numpy``): the same masks and ranks, bit for bit,
and the same line directions up to sign and rounding (the 3x3 solver of the normals,
not LAPACK)."""

from __future__ import annotations

import ctypes
import sys
from pathlib import Path

import numpy as np
import pytest
import shapes

from meshlab_sharp import _kernels
from meshlab_sharp.neighbourhoods import Neighbourhood
from meshlab_sharp.reference import detect as reference_sequence
from meshlab_sharp.reference import robust as reference_robust
from meshlab_sharp.sample import sample_part

pytestmark = pytest.mark.skipif(not _kernels.available(), reason="needs the compiled kernels")

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
from bench import cad_cloud, cad_mesh  # noqa: E402


def _setup_of(
    monkeypatch, vertices, faces=None
) -> tuple[reference_sequence.RobustSetup, np.ndarray]:
    """The RobustSetup of the Python-driven sequence with the compiled backend and the
    candidates it finished."""
    held = {}
    finish = reference_sequence.RobustSetup.finish

    def grab(self, mask, strength):
        held["setup"], held["mask"] = self, mask.copy()
        return finish(self, mask, strength)

    with monkeypatch.context() as m:
        m.setattr(reference_sequence.RobustSetup, "finish", grab)
        reference_sequence.detect(vertices, faces, mode="robust", backend="compiled")
    return held["setup"], held["mask"]


def _rng_noisy(points: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    return points + np.random.default_rng(seed).normal(0, sigma, points.shape)


INPUTS = {
    # the benchmark's part: a quiet cloud (acute tips, support's exemption, blocking)
    "bench-cloud": lambda: (cad_cloud(150_000), None),
    "sample-part": lambda: (sample_part("points", n_points=20_000).vertices, None),
    # noise that grows the scales (the wider cone), and that grows them to the cap
    # (the smoothed ranking)
    "noisy-cloud": lambda: (_rng_noisy(cad_cloud(60_000), 0.05, 1), None),
    "very-noisy-cloud": lambda: (_rng_noisy(cad_cloud(60_000), 0.3, 2), None),
    "outliers": lambda: (shapes.with_outliers(shapes.box_cylinder_points(6000), 40), None),
    "bench-mesh": lambda: cad_mesh(100_000),
    "sample-mesh": lambda: (lambda p: (p.vertices, p.faces))(sample_part("mesh")),
    "noisy-mesh": lambda: shapes.noisy_mesh(*cad_mesh(20_000), 0.1),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", INPUTS)
def test_compiled_finish_is_the_numpy_finish(monkeypatch, name):
    """Acute tips, support and thinning in C give numpy's mask, bit for bit, with the
    lists from the kd-tree or the adjacency (every rule of robust.py exercised: the
    quiet cloud's, the noisy cloud's, the mesh's)."""
    vertices, faces = INPUTS[name]()
    setup, mask = _setup_of(monkeypatch, vertices, faces)
    assert setup._compiled()
    got = setup._finish_compiled(mask)
    want = setup._finish_numpy(mask)
    assert got.dtype == bool and np.array_equal(got, want)
    assert got.any()
    if name == "bench-cloud":  # acute tips join the candidates, and some stay
        assert (got & ~mask).any()
    if name == "outliers":
        assert len(setup.keep) < setup.n  # isolated points were removed
    if name == "very-noisy-cloud":
        assert setup.plan.ranking_smoothed


@pytest.mark.parametrize("kind", ["one", "every", "lone-pair"])
def test_compiled_finish_edge_cases(monkeypatch, kind):
    """One candidate, every point a candidate, two candidates far apart: C and numpy
    agree."""
    points = shapes.box_cylinder_points(4000)
    setup, mask = _setup_of(monkeypatch, points)
    mask = np.zeros_like(mask)
    if kind == "one":
        mask[17] = True
    elif kind == "every":
        mask[:] = True
    else:
        mask[[3, 3000]] = True
    got = setup._finish_compiled(mask)
    assert np.array_equal(got, setup._finish_numpy(mask))
    assert got.sum() <= mask.sum()


def _random_lists(n: int, c: int, k: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``c`` candidate rows of ``n`` points and a (c, k) table of distinct members, each
    row's own point first (as kNN lists and rings list it)."""
    rng = np.random.default_rng(seed)
    rows = np.sort(rng.choice(n, c, replace=False))
    table = np.empty((c, k), np.int64)
    for r, i in enumerate(rows):
        others = rng.choice(np.delete(np.arange(n), i), k - 1, replace=False)
        table[r] = np.r_[i, others]
    return rows, table


def _csr_of(n: int, rows: np.ndarray, table: np.ndarray, k: int) -> Neighbourhood:
    """The numpy reference's lists: rows ``rows`` of ``table``'s first ``k`` columns."""
    indptr = np.zeros(n + 1, np.int64)
    indptr[rows + 1] = k
    return Neighbourhood(np.cumsum(indptr), np.ascontiguousarray(table[:, :k]).reshape(-1))


@pytest.mark.parametrize("wide", [True, False])
def test_the_kernels_steps_one_by_one(wide):
    """Each C step on lists given both ways (a table's columns, a CSR list's prefixes of
    int32 members) against its numpy function: directions up to sign within 1e-12 where
    the largest eigenvalue is distinct, ranks and masks exactly."""
    lib = _kernels._LIB
    n, c, k = 400, 150, 12
    rng = np.random.default_rng(5)
    points = rng.normal(size=(n, 3))
    rows, table = _random_lists(n, c, k, 3)
    mask = np.zeros(n, bool)
    mask[rows] = True
    score = rng.integers(0, 8, n) / 8.0  # ties: the strict comparisons matter
    if wide:
        views = [_kernels.CandidateLists.knn(table, m) for m in (k, 8, 6)]
    else:
        start = np.arange(c + 1, dtype=np.int64) * k
        flat = table.reshape(-1).astype(np.int32)
        views = [_kernels.CandidateLists(flat, start=start, len=np.full(c, m)) for m in (k, 8, 6)]
    direction, around, compare = views
    d_ref, a_ref, c_ref = (_csr_of(n, rows, table, m) for m in (k, 8, 6))
    p, f0, r = (_kernels._ptr(x) for x in (points, mask, rows))

    e = np.empty((c, 3))
    assert (
        lib.ms_line_directions(p, f0, r, ctypes.byref(direction.spec()), 0, c, _kernels._ptr(e))
        == 0
    )
    want = reference_robust.line_directions(points, mask, d_ref)[rows]
    sign = np.where((e * want).sum(axis=1) < 0, -1.0, 1.0)
    line = mask[table].sum(axis=1) >= 2  # one point alone has no direction
    assert line.mean() > 0.5
    assert np.abs(e * sign[:, None] - want)[line].max() < 1e-12
    assert np.allclose((e * e).sum(axis=1), 1.0)

    rank = score.copy()
    lib.ms_smoothed_ranking(
        _kernels._ptr(score), r, ctypes.byref(compare.spec()), 4, 0, c, _kernels._ptr(rank)
    )
    assert rank.tobytes() == reference_robust.smoothed_ranking(score, c_ref, 4).tobytes()

    e_full = np.zeros((n, 3))
    e_full[rows] = e
    for minimum, free in ((1, None), (2, 0.3), (3, None)):
        f1 = np.zeros(n, bool)
        lib.ms_supported(
            p, f0, r, _kernels._ptr(e), ctypes.byref(around.spec()), 0.5, minimum,
            None if free is None else _kernels._ptr(score), 0.0 if free is None else free,
            0, c, _kernels._ptr(f1),
        )  # fmt: skip
        exempt = None if free is None else score < free
        assert np.array_equal(
            f1, reference_robust.supported(points, mask, e_full, a_ref, minimum, exempt=exempt)
        )
    half = mask & (rng.uniform(size=n) < 0.7)
    for between in (None, ~mask, rng.uniform(size=n) < 0.3):
        f2 = np.zeros(n, bool)
        lib.ms_thin(
            p, _kernels._ptr(half), r, _kernels._ptr(e), ctypes.byref(compare.spec()),
            _kernels._ptr(rank), 0.45, 0.65, _kernels._ptr(between), 0, c, _kernels._ptr(f2),
        )  # fmt: skip
        want = reference_robust.thin(
            points, half, rank, e_full, c_ref, cone_cos=0.45, side=0.65, between=between
        )
        assert np.array_equal(f2, want)

    tips = _kernels.acute_tips(points, half, rows, compare)
    assert np.array_equal(tips, reference_robust.acute_tips(points, half, rows, c_ref))
    assert 0 < tips.sum() < c


def test_no_candidates():
    """Nothing to finish: empty answers, no kernel call on an empty range."""
    points = np.random.default_rng(0).normal(size=(50, 3))
    none = np.zeros(0, np.int64)
    lists = _kernels.CandidateLists.knn(np.zeros((0, 4), np.int64), 4)
    rules = _kernels.FinishRules(0.5, 2, None, 0.5, 0.7, 0, None)
    out = _kernels.support_and_thin(
        points, np.zeros(50, bool), np.zeros(50), none, (lists,) * 3, rules
    )
    assert out.shape == (50,) and not out.any()
    assert _kernels.acute_tips(points, np.zeros(50, bool), none, lists).shape == (0,)
