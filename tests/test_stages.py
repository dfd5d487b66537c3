"""The native library's stages of a cloud's sequence and robust mode's rules
(native/src/stages.c): the rules say what docs/method.md says, the numpy reference
states the same rules, and the pointwise stages over parts of the points add up to
ms_scale_vote's answer over the whole."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp import _header, _kernels, robust
from meshlab_sharp.creases import sharp_vertices
from meshlab_sharp.reference import detect as reference_sequence
from meshlab_sharp.reference import robust as reference

pytestmark = pytest.mark.skipif(not _kernels.available(), reason="needs the compiled kernels")

NOISES = [0.0, 0.01, 0.05, np.nextafter(0.05, 1.0), 0.1, 0.15, 0.2, 0.25, 0.259, 0.26, 0.3, 2.0]
RULES = ["noise_factor", "thin_knn", "quiet_cloud", "otsu_splits", "thin_cone", "thin_side"]
RULES += ["ranking_smoothed", "support_free_score"]


def test_floor_is_the_straight_edge_value() -> None:
    """MS_R_MIN is (2 / pi) sin(CREASE_ANGLE / 2) to the nearest double."""
    floor = (2.0 / math.pi) * math.sin(math.radians(robust.CREASE_ANGLE / 2.0))
    assert floor == robust.R_MIN


def test_rules_known_answers() -> None:
    assert _kernels.noise_factor(0.0) == 1.0
    assert _kernels.noise_factor(0.3) == 3.0  # (0.3 / 0.15)^2 = 4, capped
    assert _kernels.noise_factor(0.2) == (0.2 / 0.15) ** 2
    assert _kernels.scale_growth(0.3, 10_000, 40) == 3.0
    assert _kernels.scale_growth(0.3, 100, 40) == 2.5  # the largest grown scale fits
    assert _kernels.scale_growth(0.0, 100, 40) == 1.0
    assert _kernels.grown_scale(12, 1.5) == 18 and _kernels.grown_scale(5, 1.5) == 8  # half up
    assert _kernels.thin_knn(1.0) == robust.THIN_KNN and _kernels.thin_knn(3.0) == 36
    assert _kernels.quiet_cloud(False, 0.05) and not _kernels.quiet_cloud(False, 0.06)
    assert not _kernels.quiet_cloud(True, 0.0) and _kernels.otsu_splits(True, 0.0)
    assert _kernels.thin_cone(False, 0.1) == robust.THIN_CONE_COS_NOISY
    assert _kernels.thin_cone(True, 0.1) == robust.THIN_CONE_COS
    assert _kernels.thin_side(False, 0.1) == robust.THIN_SIDE_NOISY
    assert _kernels.thin_side(False, 0.05) == _kernels.thin_side(True, 0.1) == robust.THIN_SIDE
    assert _kernels.ranking_smoothed(False, 0.3) and not _kernels.ranking_smoothed(True, 0.3)
    assert _kernels.support_free_score(False, 0.0) == robust.SUPPORT_FREE_SCORE
    assert _kernels.support_free_score(False, 0.1) is None


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("mesh", [False, True])
def test_reference_states_the_library_rules(rule: str, mesh: bool) -> None:
    """The numpy reference (an install without the library) answers as the library."""
    for noise in NOISES:
        args = (noise,) if rule in ("noise_factor", "thin_knn") else (mesh, noise)
        if rule == "thin_knn":
            args = (_kernels.noise_factor(noise),)
        assert getattr(_kernels, rule)(*args) == getattr(reference, rule)(*args), (rule, noise)


SCALE_SETS = [(12, 16, 20, 24, 28, 32, 36, 40), (8, 16, 24), (3,), (1, 2, 3, 4), (40, 600)]


@pytest.mark.parametrize("mesh", [False, True])
@pytest.mark.parametrize("scales", SCALE_SETS)
def test_reference_states_the_library_plan(mesh: bool, scales: tuple[int, ...]) -> None:
    """ms_robust_plan gives the numpy reference's decisions over a grid of noise ratios,
    kept counts (the growth's cap n / top included) and scales, and ms_plan_thresholds
    its thresholds of the same histograms."""
    rng = np.random.default_rng(len(scales))
    counts = rng.integers(0, 50, (len(scales), _header.integer("BINS")))
    counts[:, :20] += rng.integers(0, 2000, (len(scales), 20))
    for noise in NOISES:
        for n_kept in (max(scales), 2 * max(scales) + 1, 3 * max(scales), 10_000):
            plan = _kernels.robust_plan(noise, n_kept, scales, mesh)
            assert plan == reference.robust_plan(noise, n_kept, scales, mesh), (noise, n_kept)
            expected = reference_sequence.plan_thresholds(plan, counts)
            assert _kernels.plan_thresholds(plan, counts).tolist() == expected.tolist()
            if mesh:
                assert plan.scales == scales and not plan.grown and not plan.acute_tests


def test_plan_known_answers() -> None:
    """The plan of a noisy cloud grows the scales to the cap and smooths the ranking; a
    quiet cloud's looks for acute tips, exempts weak candidates and thresholds at the
    floor alone; a mesh's lists are its THIN_RING-ring."""
    scales = (12, 16, 20, 24, 28, 32, 36, 40)
    noisy = _kernels.robust_plan(0.3, 10_000, scales, False)
    assert noisy.grown and noisy.growth == 3.0 and noisy.scales == tuple(3 * k for k in scales)
    assert noisy.otsu and noisy.noise_floor and noisy.ranking_smoothed
    assert noisy.compare_knn == 36 and noisy.support_knn == robust.SUPPORT_KNN
    assert noisy.free_below is None and not noisy.acute_tests and not noisy.thin_between
    quiet = _kernels.robust_plan(0.01, 10_000, scales, False)
    assert not quiet.grown and quiet.scales == scales and not quiet.otsu
    assert quiet.acute_tests and quiet.thin_between
    assert quiet.free_below == robust.SUPPORT_FREE_SCORE
    assert quiet.compare_knn == robust.THIN_KNN
    mesh = _kernels.robust_plan(0.0, 10_000, (1, 2, 3, 4), True)
    assert mesh.otsu and not mesh.noise_floor and mesh.support_knn == robust.THIN_RING
    assert mesh.compare_knn == robust.THIN_RING and mesh.thin_cone == robust.THIN_CONE_COS
    assert noisy.thin_side == robust.THIN_SIDE_NOISY
    assert quiet.thin_side == mesh.thin_side == robust.THIN_SIDE
    assert mesh.curved_dropped and not quiet.curved_dropped and not noisy.curved_dropped


@pytest.mark.parametrize("normalise", [False, True])
@pytest.mark.parametrize("otsu", [False, True])
def test_stages_over_parts_equal_scale_vote(normalise: bool, otsu: bool) -> None:
    """Histograms of three parts summed, the threshold from them and each part's decision
    give ms_scale_vote's thresholds, votes, counts and values over the whole."""
    rng = np.random.default_rng(3)
    values = rng.random((3000, 4)) ** 3
    values[:, 3] = 0.25  # a flat scale
    floor = 0.0 if normalise else robust.R_MIN
    lo, hi = values.min(axis=0), values.max(axis=0)
    norm = (lo, hi, 1e-9) if normalise else None
    parts = np.array_split(np.arange(len(values)), 3)
    hist = sum(_kernels.stage_histograms(values[p], norm) for p in parts)
    thresholds = np.array([_kernels.stage_threshold(h, otsu, floor) for h in hist])
    votes = np.zeros(len(values), np.int64)
    whole, split = [], np.zeros((values.shape[1], len(values)))
    for s in range(values.shape[1]):
        t, count = _kernels.scale_vote(
            values[:, s], votes, flat_span=1e-9 if normalise else None, otsu=otsu, floor=floor,
            out=split[s],
        )  # fmt: skip
        assert thresholds[s] == t
        whole.append(count)
    outs = [np.full((len(p), values.shape[1]), np.nan) for p in parts]
    decided = [
        _kernels.stage_decide(values[p], thresholds, norm, o)
        for p, o in zip(parts, outs, strict=True)
    ]
    assert np.array_equal(np.concatenate(outs), split.T)
    assert np.array_equal(np.concatenate([d[0] for d in decided]), votes == 4)
    assert np.array_equal(np.concatenate([d[1] for d in decided]), votes / 4.0)
    counts = sum(d[2] for d in decided)
    assert list(counts) == whole and counts[3] in (0, len(values))
    assert _header.integer("BINS") == hist.shape[1] and hist.sum() == values.size


def test_flat_span_is_the_box_diagonal() -> None:
    tolerance = _header.real("FLAT_TOLERANCE")
    assert _kernels.flat_span(np.array([3.0, 4.0, 12.0])) == tolerance * 13.0
    assert _kernels.flat_span(np.zeros(3)) == 0.0
    with pytest.raises(ValueError):
        _kernels.flat_span(np.zeros(2))


def test_acute_tests_only_on_quiet_clouds() -> None:
    score = np.array([0.49, 0.5, 0.7, 0.8, 0.6])
    mask = np.array([False, False, False, False, True])
    assert list(_kernels.stage_acute_tests(score, mask, False, 0.0)) == [1, 2]
    assert len(_kernels.stage_acute_tests(score, mask, False, 0.1)) == 0
    assert len(_kernels.stage_acute_tests(score, mask, True, 0.0)) == 0
    assert list(reference.stage_acute_tests(score, mask, False, 0.0)) == [1, 2]


@pytest.mark.parametrize("ends", [(1, 4), (2, 3), (12, 40)])
def test_curved_stage_equals_reference(ends: tuple[int, int]) -> None:
    """ms_stage_curved drops the reference's points: a candidate whose relative distance
    grows at least as the square root of the ring; an exact tie is kept (strict)."""
    rng = np.random.default_rng(ends[1])
    first, last = rng.random(500), rng.random(500)
    first[:3] = last[:3] = 0.0
    last[3:6] = 0.5
    first[3:6] = 0.5 * math.sqrt(ends[0] / ends[1])  # about the tie, on either side
    first[6], last[6] = 0.25, 0.5  # exact: 0.25**2 * 4 == 0.5**2 * 1
    mask = rng.random(500) < 0.8
    mask[:7] = True
    got = _kernels.stage_curved(first, last, *ends, mask)
    assert got.tolist() == reference.stage_curved(first, last, *ends, mask).tolist()
    assert not (got & ~mask).any() and (got != mask).any()
    if ends == (1, 4):
        assert got[6]


def test_a_noisy_meshs_curved_candidates_are_dropped_by_both() -> None:
    """On a noisy cube's mesh the rule drops candidates at every scale (near the
    corners, where the third face joins the larger rings): the library's sequence and
    the numpy reference's give the same features."""
    vertices, faces = shapes.noisy_mesh(*shapes.cube_grid_mesh(4), 0.2)
    native = meshlab_sharp.detect(vertices, faces, return_details=True)
    numpy = meshlab_sharp.detect(vertices, faces, backend="numpy")
    r = native.distances
    assert r is not None
    every = (r >= np.asarray(native.thresholds)[:, None]).all(axis=0)
    scales = native.scales
    curved = every & (r[0] * r[0] * scales[-1] < r[-1] * r[-1] * scales[0])
    edges = np.asarray(sharp_vertices(np.asarray(vertices, np.float64), faces)[0], bool)
    assert curved.any() and not (native.mask & curved & ~edges).any()
    assert native.mask.tolist() == numpy.mask.tolist()


def test_isolated_stage_equals_reference() -> None:
    """ms_stage_isolated of every point, its nearest's values gathered per row, finds
    the reference's isolated points: a stray pair and a point beside a tight clump."""
    rng = np.random.default_rng(5)
    pts = rng.random((1500, 3)) * [1.0, 1.0, 0.0]
    clump = pts[0] + rng.normal(scale=1e-4, size=(20, 3)) * [1, 1, 0]
    pts = np.concatenate(
        [pts, clump, [pts[0] + [0.005, 0, 0]], [[0.5, 0.5, 0.3], [0.5, 0.51, 0.3]]]
    )
    k = 16
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(axis=2)
    idx = np.lexsort((np.broadcast_to(np.arange(len(pts)), d2.shape), d2), axis=1)[:, :k]
    kd2 = np.take_along_axis(d2, idx, axis=1)
    near, kth = idx[:, 1], idx[:, k - 1]
    nth, ref = kd2[:, min(robust.ISOLATED_NTH, k - 1)], kd2[:, min(robust.ISOLATED_REF, k - 1)]
    got = _kernels.stage_isolated(
        pts, pts[near], kd2[near, k - 1], kth[near], np.arange(len(pts)), nth, ref[kth],
        robust.ISOLATED_SPREAD,
    )  # fmt: skip
    expected = reference.isolated_points(pts, idx)
    assert expected[-2:].all() and expected.sum() >= 2
    assert np.array_equal(got, expected)
