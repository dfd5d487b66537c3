"""Each mode as a sequence of steps over the tiles.

A step is either *local*: a function of the exact neighbourhoods of the tile's points
(:class:`~meshlab_sharp.tiles.neighbours.Context`) that writes per-point values to the
store; or *pointwise*: a function of the store's values on the tile's positions. Both
return a small *partial* (dict of arrays) that the driver, or Dask, reduces over the
tiles: keys ending in ``_min``/``_max`` by minimum/maximum, the others by sum. Between
steps the reduced values (min-max ranges, the 256-bin histograms and so Otsu's
thresholds) are fixed, exactly as the in-memory run computes them from all points.

Every step's arithmetic is the native library's, the stages that ``ms_detect`` composes
in memory (``native/src/stages.c``: histograms, the decision, the isolation and acute
tests and robust mode's rules; the finishing kernels: acute tips, line directions and
support, the smoothed ranking, thinning), called on the tile's points through
:mod:`meshlab_sharp._kernels`. What is left here joins the tiles: reading and writing
the store (the values of a point's neighbours in other tiles), the partials, and which
kept points' pass runs again once isolated points are left out (:func:`robust_affected`,
a question the in-memory run, which runs the pass again over every kept point, does
not ask).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .. import _kernels, robust
from .._kernels import CandidateLists, FinishRules, RobustPlan
from .neighbours import Context, Query
from .store import Store

Partial = dict[str, np.ndarray]
#: Threads of a tile's finishing kernels (a few thousand candidates: milliseconds; the
#: tiles themselves run side by side).
TILE_THREADS = 1


@dataclass(frozen=True)
class Span:
    """The tile's positions ``a:b`` in the store, for a pointwise step."""

    store: Store
    a: int
    b: int

    def read(self, name: str) -> np.ndarray:
        """Store array ``name`` on the span."""
        return self.store.read(name, self.a, self.b)

    @property
    def distinct(self) -> np.ndarray:
        """Span-relative indices of the distinct points (first occurrences)."""
        return np.flatnonzero(self.read("rep") == np.arange(self.a, self.b))


@dataclass(frozen=True)
class Step:
    """One step: ``fn(ctx_or_span, **params) -> Partial``; ``query`` None: pointwise."""

    label: str
    fn: Callable[..., Partial]
    query: Query | None = None
    params: dict[str, Any] = field(default_factory=dict)


def combine(parts: list[Partial]) -> Partial:
    """Reduce partials: ``*_min`` by minimum, ``*_max`` by maximum, ``*_cat`` by
    concatenation, others by sum."""
    out: Partial = {}
    cat: dict[str, list[np.ndarray]] = {}
    for part in parts:
        for key, value in part.items():
            if key.endswith("_cat"):
                cat.setdefault(key, []).append(value)
            elif key not in out:
                out[key] = np.array(value)
            elif key.endswith("_min"):
                out[key] = np.minimum(out[key], value)
            elif key.endswith("_max"):
                out[key] = np.maximum(out[key], value)
            else:
                out[key] = out[key] + value
    out.update({key: np.concatenate(values) for key, values in cat.items()})
    return out


# ----------------------------------------------------------------------------- paper


def paper_distances(ctx: Context, *, s: int) -> Partial:
    """Projected distances (r, s) of the rows to ``pdis``; their per-scale min and max."""
    pdis = ctx.found["pdis"]
    ctx.store.write_at("pdis", ctx.own, pdis)
    return {"pdis_min": pdis.min(axis=0), "pdis_max": pdis.max(axis=0)}


def paper_histograms(span: Span, *, lo: np.ndarray, hi: np.ndarray, flat: float) -> Partial:
    """The histograms (s, BINS) of the distances normalised with the global ``lo``,
    ``hi`` and ``flat`` (``ms_stage_histograms``)."""
    pdis = span.read("pdis")[span.distinct]
    return {"hist": _kernels.stage_histograms(pdis, (lo, hi, flat))}


def paper_decide(
    span: Span, *, lo: np.ndarray, hi: np.ndarray, flat: float, thresholds: np.ndarray
) -> Partial:
    """Candidates at every scale: ``mask`` and ``strength``; candidates per scale."""
    d = span.distinct
    return _decided(span, d, span.read("pdis")[d], thresholds, (lo, hi, flat))


def _decided(
    span: Span,
    d: np.ndarray,
    values: np.ndarray,
    thresholds: np.ndarray,
    norm: _kernels.Normalisation = None,
) -> Partial:
    """The decision (``ms_stage_decide``) of the span's points ``d`` by their ``values``
    (m, s): ``mask``, ``strength``; the candidates per scale."""
    feature, strength, counts = _kernels.stage_decide(values, thresholds, norm)
    span.store.write_at("mask", span.a + d, feature)
    span.store.write_at("strength", span.a + d, strength)
    return {"counts": counts}


# ---------------------------------------------------------------------------- robust


def robust_pass(ctx: Context, *, first: bool) -> Partial:
    """The compiled pass of robust mode on the rows (the query's ``robust`` pass: the
    sheet filter, the noise ratio, :class:`meshlab_sharp.reference.detect.RelativeRule`'s relative
    distances and score, as the in-memory :class:`~meshlab_sharp.reference.detect.RobustSetup`
    computes them): ``ratio``, ``r`` (r, s), ``score``; on the ``first`` pass (every
    distinct point) also each row's nearest neighbour (``nn1``, a position), k-th
    neighbour squared distance (``kd2``), input index (``kid``) and position (``kpos``),
    and the squared distances of its ``ISOLATED_NTH``-th and ``ISOLATED_REF``-th nearest
    (``nd2``, ``rd2``). The histograms of ``r``."""
    found, store = ctx.found, ctx.store
    if first:
        store.write_at("nn1", ctx.own, ctx.pos[found["near"]])
        store.write_at("kd2", ctx.own, found["kth_d2"])
        kpos = ctx.pos[found["kth_idx"]]
        store.write_at("kid", ctx.own, store.read_at("ids", kpos))
        store.write_at("kpos", ctx.own, kpos)
        store.write_at("nd2", ctx.own, found["nth_d2"])
        store.write_at("rd2", ctx.own, found["ref_d2"])
    r = found["relative"]
    store.write_at("ratio", ctx.own, found["noise"])
    store.write_at("r", ctx.own, r)
    store.write_at("score", ctx.own, found["score"])
    return {"hist": _kernels.stage_histograms(r)}


def robust_isolated(span: Span) -> Partial:
    """``ms_stage_isolated`` (:func:`meshlab_sharp.reference.robust.isolated_points`) of the
    span's distinct points, with their nearest's values read wherever it lies: ``i`` is
    isolated when it is not among the k nearest of its nearest ``j`` (``(d2(j, i), i)``
    after ``j``'s k-th neighbour in the (squared distance, index) order), or when its
    ``nd2`` exceeds ``ISOLATED_SPREAD**2`` times its k-th neighbour's ``rd2``. Writes
    ``kept``; the isolated points' coordinates (``lone_cat``)."""
    d = span.distinct
    store = span.store
    nn = store.read("nn1", span.a, span.b)[d]
    coords = span.read("coords")[d]
    isolated = _kernels.stage_isolated(
        coords,
        store.read_at("coords", nn),
        store.read_at("kd2", nn),
        store.read_at("kid", nn),
        span.read("ids")[d],
        span.read("nd2")[d],
        store.read_at("rd2", span.read("kpos")[d]),
        robust.ISOLATED_SPREAD,
    )
    inside = ~isolated
    store.write_at("kept", span.a + d, inside)
    return {"isolated": np.array(int((~inside).sum())), "lone_cat": coords[~inside]}


def robust_affected(span: Span, *, lone: np.ndarray) -> Partial:
    """The kept points whose k nearest (the first pass's: within the k-th neighbour
    distance ``kd2``) may hold an isolated point of ``lone`` (m, 3): their lists among
    the kept points differ, so the pass is run again on them (``redo``); every other
    kept point's list, and so its values, stays the same. A margin keeps the test on
    the safe side (recomputing a point gives its value again)."""
    d = span.distinct
    d = d[span.read("kept")[d]]
    if len(d) == 0:
        return {"redo": np.array(0)}
    reach = np.sqrt(span.read("kd2")[d]) * (1.0 + 1e-6) + 1e-300
    dist, _ = cKDTree(lone).query(span.read("coords")[d], 1)
    redo = d[dist <= reach]
    span.store.write_at("redo", span.a + redo, np.ones(len(redo), bool))
    return {"redo": np.array(len(redo))}


def robust_histograms(span: Span) -> Partial:
    """The histograms of ``r`` over the kept distinct points."""
    d = span.distinct
    return {"hist": _kernels.stage_histograms(span.read("r")[d[span.read("kept")[d]]])}


def robust_decide(span: Span, *, thresholds: np.ndarray) -> Partial:
    """Candidates at every scale (``mask``), strength, candidates per scale."""
    d = span.distinct
    d = d[span.read("kept")[d]]
    return _decided(span, d, span.read("r")[d], thresholds)


def robust_acute_tests(span: Span, *, plan: RobustPlan) -> Partial:
    """``ms_stage_acute_tests`` of the kept distinct points on the cloud of ``plan``
    (where ``plan.acute_tests``): writes ``tested``; their count."""
    d = span.distinct
    d = d[span.read("kept")[d]]
    score, mask = span.read("score")[d], span.read("mask")[d]
    test = _kernels.stage_acute_tests(score, mask, plan.mesh, plan.noise)
    span.store.write_at("tested", span.a + d[test], np.ones(len(test), bool))
    return {"tested": np.array(len(test))}


def robust_acute_tips(ctx: Context, *, compare: int) -> Partial:
    """``ms_acute_tips`` (:func:`meshlab_sharp.reference.robust.acute_tips`) of the rows (the points
    tested) among the candidates ``mask`` of their ``compare`` nearest: writes ``tip``."""
    near = CandidateLists.knn(ctx.idx, compare)
    tips = _kernels.acute_tips(ctx.points, ctx.gather("mask"), ctx.rows, near, TILE_THREADS)
    ctx.store.write_at("tip", ctx.own, tips)
    return {}


def robust_acute_join(span: Span) -> Partial:
    """The tips join the candidates: ``mask`` or ``tip``."""
    span.store.write_at("mask", np.arange(span.a, span.b), span.read("mask") | span.read("tip"))
    return {}


def _rules(plan: RobustPlan, candidates: np.ndarray | None = None) -> FinishRules:
    """Robust mode's finishing rules as ``plan`` states them (the score that needs no
    support, thinning's cone and side rule and, with ``candidates`` given and
    ``plan.thin_between``, the points that are not candidates as thinning's blockers)."""
    between = None
    if candidates is not None and plan.thin_between:
        between = ~np.asarray(candidates, bool)
    return FinishRules(
        support_cone=robust.THIN_CONE_COS,
        minimum=robust.SUPPORT_MIN,
        free_below=plan.free_below,
        thin_cone=plan.thin_cone,
        thin_side=plan.thin_side,
        window=0,
        between=between,
    )


def robust_support(ctx: Context, *, plan: RobustPlan) -> Partial:
    """The rows' line directions over their nearest at the largest of ``plan.scales``
    (to ``e``) and support over their ``plan.support_knn`` nearest (to ``mask1``),
    ``ms_line_directions`` and ``ms_supported`` (:func:`meshlab_sharp._kernels.line_support`)
    by ``plan``'s rules."""
    top, around = max(plan.scales), plan.support_knn
    lists = (CandidateLists.knn(ctx.idx, top), CandidateLists.knn(ctx.idx, around))
    e, out, _ = _kernels.line_support(
        ctx.points, ctx.gather("mask"), ctx.gather("score"), ctx.rows, lists, _rules(plan),
        TILE_THREADS,
    )  # fmt: skip
    ctx.store.write_at("e", ctx.own, e)
    ctx.store.write_at("mask1", ctx.own, out[ctx.rows])
    return {}


def robust_rank(ctx: Context, *, plan: RobustPlan) -> Partial:
    """``ms_smoothed_ranking`` of the rows over the first ``THIN_KNN`` of their
    ``plan.compare_knn`` nearest (to ``rank``)."""
    near = CandidateLists.knn(ctx.idx, plan.compare_knn)
    score = ctx.gather("score")
    rank = _kernels.smoothed_ranking(score, ctx.rows, near, robust.THIN_KNN, TILE_THREADS)
    ctx.store.write_at("rank", ctx.own, rank[ctx.rows])
    return {}


def robust_thin(ctx: Context, *, plan: RobustPlan, ranking: str) -> Partial:
    """``ms_thin`` of the rows by the store array ``ranking`` (``score``, or ``rank``
    where ``plan.ranking_smoothed``) over their ``plan.compare_knn`` nearest, by
    ``plan``'s rules; writes ``final``."""
    out = _kernels.thin_candidates(
        ctx.points,
        ctx.gather("mask1"),
        ctx.rows,
        ctx.gather("e")[ctx.rows],
        CandidateLists.knn(ctx.idx, plan.compare_knn),
        ctx.gather(ranking),
        _rules(plan, ctx.gather("mask")),
        TILE_THREADS,
    )
    ctx.store.write_at("final", ctx.own, out[ctx.rows])
    return {}


def robust_line(ctx: Context, *, plan: RobustPlan, ranking: str) -> Partial:
    """``ms_line_test`` of the rows (``final``) by the store array ``ranking`` over their
    ``plan.compare_knn`` nearest, blocked as thinning is; writes ``lined``."""
    out = _kernels.line_test(
        ctx.points,
        ctx.gather("final"),
        ctx.rows,
        CandidateLists.knn(ctx.idx, plan.compare_knn),
        ctx.gather(ranking),
        robust.line_rules(),
        _rules(plan, ctx.gather("mask")).between,
        TILE_THREADS,
    )
    ctx.store.write_at("lined", ctx.own, out[ctx.rows])
    return {}


def finish(span: Span, *, mask: str, kept: str | None) -> dict[str, np.ndarray]:
    """The tile's results per input point: input index, mask, strength, kept (duplicates
    take their first occurrence's values)."""
    rep = span.read("rep") - span.a
    out = {
        "ids": span.read("ids"),
        "mask": span.read(mask)[rep],
        "strength": span.read("strength")[rep],
    }
    out["kept"] = np.ones(len(rep), bool) if kept is None else span.read(kept)[rep]
    return out
