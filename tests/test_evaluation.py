"""Metrics on synthetic cases with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from meshlab_sharp.evaluation import distance_to_segments, evaluate, local_spacing, sample_segments

S = 0.5  # grid spacing
L = 40.0  # edge length


@pytest.fixture(scope="module")
def grid():
    """Regular grid on the plane z = 0, x in [0, L], y in [-5 S, 5 S]; edge along y = 0."""
    x = np.arange(0, L + S / 2, S)
    y = np.arange(-5, 6) * S
    xx, yy = np.meshgrid(x, y, indexing="ij")
    pts = np.c_[xx.ravel(), yy.ravel(), np.zeros(xx.size)]
    edge = np.array([[[0.0, 0.0, 0.0], [L, 0.0, 0.0]]])
    return pts, edge


def test_perfect_detection(grid):
    pts, edge = grid
    sc = evaluate(pts, np.isclose(pts[:, 1], 0), edge, S)
    assert sc.precision == 1.0 and sc.coverage == 1.0 and sc.f1 == 1.0
    assert sc.thickness == pytest.approx(1.0, abs=0.02)
    assert sc.fp_rate == 0.0


def test_two_point_band(grid):
    pts, edge = grid
    sc = evaluate(pts, np.isclose(pts[:, 1], 0) | np.isclose(pts[:, 1], S), edge, S)
    assert sc.precision == 1.0 and sc.coverage == 1.0
    assert sc.thickness == pytest.approx(2.0, abs=0.05)


def test_empty_and_wrong_detection(grid):
    pts, edge = grid
    empty = evaluate(pts, np.zeros(len(pts), bool), edge, S)
    assert (empty.precision, empty.coverage, empty.f1, empty.n_detected) == (0.0, 0.0, 0.0, 0)
    assert math.isnan(empty.thickness)
    far = evaluate(pts, np.isclose(pts[:, 1], 5 * S), edge, S)
    assert far.precision == 0.0 and far.coverage == 0.0
    assert far.fp_rate == pytest.approx(np.isclose(pts[:, 1], 5 * S).mean())


def test_half_coverage(grid):
    pts, edge = grid
    mask = np.isclose(pts[:, 1], 0) & (pts[:, 0] <= L / 2)
    sc = evaluate(pts, mask, edge, S)
    # covered up to 1.5 spacings past the last detected point
    assert sc.coverage == pytest.approx((L / 2 + 1.5 * S) / L, abs=0.01)
    assert sc.precision == 1.0


def test_no_truth_gives_fp_rate(grid):
    pts, _ = grid
    mask = np.zeros(len(pts), bool)
    mask[:7] = True
    sc = evaluate(pts, mask, np.zeros((0, 2, 3)), S)
    assert math.isnan(sc.precision) and math.isnan(sc.f1)
    assert sc.fp_rate == pytest.approx(7 / len(pts))


def test_per_point_spacing_matches_scalar(grid):
    pts, edge = grid
    mask = np.isclose(pts[:, 1], 0) | np.isclose(pts[:, 1], 2 * S)
    a = evaluate(pts, mask, edge, S)
    b = evaluate(pts, mask, edge, np.full(len(pts), S))
    assert a == b
    assert np.allclose(local_spacing(pts)[np.abs(pts[:, 1]) < 3 * S], S)


def test_distance_to_segments_brute_force():
    rng = np.random.default_rng(0)
    seg = rng.uniform(-5, 5, (30, 2, 3))
    pts = rng.uniform(-6, 6, (500, 3))
    a = seg[None, :, 0]
    ab = seg[None, :, 1] - a
    t = np.clip(
        np.einsum("nkj,nkj->nk", pts[:, None] - a, np.broadcast_to(ab, (500, 30, 3)))
        / np.einsum("kj,kj->k", ab[0], ab[0]),
        0,
        1,
    )
    brute = np.linalg.norm(pts[:, None] - a - t[..., None] * ab, axis=2).min(axis=1)
    got = distance_to_segments(pts, seg, step=0.05)
    assert np.all(got >= brute - 1e-12)
    assert np.all(got <= brute + 0.025)


def test_sample_segments_lengths():
    seg = np.array([[[0, 0, 0], [3, 0, 0]], [[0, 0, 0], [0, 0.1, 0]]], float)
    pts, piece, sid = sample_segments(seg, 1.0)
    assert piece.sum() == pytest.approx(3.1)
    assert list(sid) == [0, 0, 0, 1]
    assert np.allclose(pts[:3, 0], [0.5, 1.5, 2.5])
