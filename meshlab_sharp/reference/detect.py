"""The detection sequence driven from Python, step by step (the reference of the native
library's ``ms_detect``, native/src/detect.cpp): load -> clean -> neighbourhoods ->
normals -> projected distance -> threshold -> decide, with every result in the input's
order. Each step runs with the backend given: "numpy" (the reference steps of this
package) or "compiled" (the library's kernels, step by step). :func:`meshlab_sharp.detect`
runs it for ``backend="numpy"`` and for an input the library refuses (whose error it
raises); the tests compare the library's sequence with it.

Unlike the other reference modules it imports the product modules whose steps it calls
(each dispatches to the compiled kernel or to the reference step by the backend).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from .. import _kernels
from .. import robust as robust_mode  # read when run: variants set its rules there
from ..cleaning import CleanGeometry, clean
from ..creases import sharp_vertices
from ..defaults import DEFAULT_MODE
from ..errors import InputError
from ..io import Geometry
from ..multiscale import decide, run_scales
from ..neighbourhoods import (
    KnnNeighbourhoods,
    Neighbourhood,
    RingNeighbourhoods,
    build_neighbourhoods,
    far_points,
    grow_rings,
    unit_scale,
)
from ..normals import DEFAULT_WEIGHTING, Weighting, face_average_normals
from ..options import Source, input_scales, load_input
from ..progress import Progress
from ..result import DetectionResult
from ..threshold import histogram, otsu_from_histogram, otsu_threshold
from . import robust as reference_robust
from .robust import (
    SheetNeighbourhoods,
    acute_tips,
    isolated_points,
    line_directions,
    line_test,
    noise_ratios,
    noise_ratios_lists,
    smoothed_ranking,
    supported,
    thin,
)


def detect(
    source: Source,
    faces: np.ndarray | None = None,
    *,
    scales: Sequence[int] | int | None = None,
    weighting: Weighting = DEFAULT_WEIGHTING,
    as_points: bool = False,
    return_details: bool = False,
    workers: int = -1,
    mode: str = DEFAULT_MODE,
    backend: str | None = None,
) -> DetectionResult:
    """:func:`meshlab_sharp.detect` in memory (no preprocessing, no curves) by the
    Python-driven sequence, every step with ``backend`` ("compiled" or "numpy"; default
    :func:`meshlab_sharp._kernels.resolve`'s): the same results as the library's
    sequence, bit for bit. The arguments are :func:`meshlab_sharp.detect`'s."""
    backend = _kernels.resolve(backend)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    geometry = load_input(source, faces, as_points, mode, weighting, timings)
    is_mesh, scales_t = input_scales(geometry, as_points, scales)
    result = run(
        geometry,
        is_mesh=is_mesh,
        scales=scales_t,
        weighting=weighting,
        return_details=return_details,
        workers=workers,
        mode=mode,
        backend=backend,
        bar=Progress(len(scales_t) + 3, enabled=False),
        timings=timings,
    )
    result.timings["total"] = time.perf_counter() - t0
    return result


def run(
    geometry: Geometry,
    *,
    is_mesh: bool,
    scales: tuple[int, ...],
    weighting: Weighting,
    return_details: bool,
    workers: int,
    mode: str,
    backend: str,
    bar: Progress,
    timings: dict[str, float],
) -> DetectionResult:
    """The sequence on ``geometry`` (loaded; its faces unless ``is_mesh`` is False) at
    ``scales`` (checked), every step with ``backend`` (resolved), stepping ``bar`` and
    adding each stage's seconds to ``timings``. The result has no curves and no total
    time."""
    kind = "mesh" if is_mesh else "points"
    t = time.perf_counter()
    # A cloud's far points (a corrupted coordinate) are dropped first, as isolated points
    # are: kept, they would set the unit of the rest.
    far = None if is_mesh else far_points(geometry.vertices)
    near = None if far is None else np.flatnonzero(~far)
    del far
    # Exact power-of-two scaling to O(1) where needed: the answer does not depend on the
    # unit (every output is unit-free), no squared distance or area underflows or
    # overflows.
    unit = unit_scale(geometry.vertices if near is None else geometry.vertices[near])[0]
    faces_in = geometry.faces if is_mesh else None
    same = unit is geometry.vertices and faces_in is geometry.faces
    to_clean = geometry if same else Geometry(unit, faces_in, geometry.source)
    cleaned, tree = (
        # a mesh renumbered when its order is scattered: every step reads nearby memory
        (clean(to_clean, backend=backend, workers=workers, local_order=True), None)
        if is_mesh
        else _clean_beside_tree(to_clean, workers, backend)
    )
    if near is not None:  # the maps to the input, the far points dropped
        from_input = np.full(len(geometry.vertices), -1, np.int64)
        from_input[near] = cleaned.from_input
        cleaned = CleanGeometry.with_maps(
            cleaned.vertices, None, near[cleaned.to_input], from_input
        )
    timings["clean"] = time.perf_counter() - t
    bar.step("cleaned")
    bar.stage("neighbourhoods")
    points = cleaned.vertices
    if not is_mesh:
        _check_cloud_size(len(geometry.vertices), len(points), max(scales), geometry.source)

    t = time.perf_counter()
    neighbourhoods, normals, sharp_edges = _neighbourhoods_and_normals(
        points,
        cleaned.faces if is_mesh else None,
        scales,
        workers,
        backend,
        mode == "robust",
        tree,
        cleaned.adjacency,
    )
    del tree
    cleaned = replace(cleaned, adjacency=None)  # the neighbourhoods' now, freed with them
    robust = None
    work, work_neighbourhoods = points, neighbourhoods
    if mode == "robust":
        robust = RobustSetup(
            points,
            cleaned.faces,
            neighbourhoods,
            scales,
            workers=workers,
            weighting=weighting,
            keep_normals=return_details,
            sharp_edges=sharp_edges,
        )
        del sharp_edges
        work, work_neighbourhoods = robust.points, robust.scale_neighbourhoods
        scales = robust.scales
    # no step reads the cleaned faces now (the neighbourhoods and the set-up keep none):
    # freed before the scales' pass, where the peak was (48 bytes a vertex)
    cleaned = replace(cleaned, faces=None)
    timings["neighbourhoods"] = time.perf_counter() - t
    bar.step("neighbourhoods")

    t = time.perf_counter()
    per_scale = run_scales(
        work,
        work_neighbourhoods,
        scales,
        normals=normals,
        weighting=weighting,
        keep_details=return_details,
        on_scale=lambda s: bar.step(f"scale {s}"),
        rule=None if robust is None else robust.rule,
        relative=robust is not None,
        fused=None if robust is None else robust.fused,
    )
    timings["normals_projected_distance_threshold"] = time.perf_counter() - t
    del normals  # a mesh's (n, 3) face normals: not needed by what follows

    t = time.perf_counter()
    mask, strength = decide(per_scale.votes, len(scales))
    per_scale.votes = np.zeros(0, dtype=np.int64)  # (n,) int64, counted in mask, strength
    if robust is not None:
        mask, strength = robust.finish(mask, strength)
        if per_scale.distances is not None and per_scale.normals is not None:
            per_scale.distances = np.stack([robust.expand(d, np.nan) for d in per_scale.distances])
            per_scale.normals = np.stack([robust.expand(n, np.nan) for n in per_scale.normals])
    # points that took part: all cleaned points, less robust mode's isolated ones
    taking_part = np.ones(len(points), bool)
    if robust is not None:
        taking_part = robust.expand(np.ones(len(robust.keep), bool), False)
    result = DetectionResult(
        mask=cleaned.to_input_order(mask, False),
        strength=cleaned.to_input_order(strength, 0.0),
        kind=kind,
        scales=scales,
        thresholds=per_scale.thresholds,
        candidate_counts=per_scale.candidate_counts,
        kept=cleaned.to_input_order(taking_part, False),
        weighting=weighting,
        n_clean=len(points),
        timings=timings,
        mode=mode,
        backend=neighbourhoods.backend,
    )
    if per_scale.distances is not None and per_scale.normals is not None:
        result.distances = np.stack(
            [cleaned.to_input_order(d, np.nan) for d in per_scale.distances]
        )
        result.normals = np.stack([cleaned.to_input_order(n, np.nan) for n in per_scale.normals])
    timings["decide"] = time.perf_counter() - t
    return result


def _clean_beside_tree(
    geometry: Geometry, workers: int, backend: str
) -> tuple[CleanGeometry, Future[_kernels.KdTree] | None]:
    """:func:`clean` of a cloud with ``backend`` and, meanwhile on a thread of its own,
    the kd-tree of its points (``backend`` "compiled", unless ``workers`` is 1):
    cleaning's duplicate merge is one serial C call, the tree's first levels nearly so,
    and they took one core each in turn. The tree (a future) is the cleaned cloud's
    when cleaning merged no point (the same points in the same order: cleaning keeps the
    order); else None, and the build stops before its next node."""
    if workers == 1 or backend != "compiled":
        return clean(geometry, backend=backend), None
    stop = threading.Event()
    pool = ThreadPoolExecutor(max_workers=1)
    tree = pool.submit(_kernels.build_tree, geometry.vertices, workers, stop.is_set)
    pool.shutdown(wait=False)  # its thread ends with the build
    try:
        cleaned = clean(geometry, backend=backend)
    except BaseException:
        stop.set()
        raise
    if len(cleaned.vertices) == len(geometry.vertices):
        return cleaned, tree
    stop.set()
    return cleaned, None


def _neighbourhoods_and_normals(
    points: np.ndarray,
    faces: np.ndarray | None,
    scales: tuple[int, ...],
    workers: int,
    backend: str,
    robust: bool,
    tree: Future[_kernels.KdTree] | None = None,
    adjacency: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[KnnNeighbourhoods | RingNeighbourhoods, np.ndarray | None, np.ndarray | None]:
    """:func:`build_neighbourhoods` and, on a mesh (``faces`` (m, 3) not None), the
    face-average normals (n, 3) and, when ``robust``, the sharp mesh edges' vertices
    (:func:`meshlab_sharp.creases.sharp_vertices`, (n,) bool); None for each on a cloud.
    ``tree``: a cloud's kd-tree, being built (:func:`_clean_beside_tree`); ``adjacency``:
    a mesh's, built already (by cleaning: ``CleanGeometry.adjacency``). Every step runs
    with ``backend``. Unless ``workers`` is 1, with the compiled backend (single-threaded C
    calls that release the GIL) the work is split between two threads: in paper mode the
    normals beside the adjacency; in robust mode the sharp edges (the longest: 0.12 s on
    the 1M bench mesh) beside the adjacency and then the normals (0.07 + 0.06 s). Three
    threads on two cores, each call on its own, made the sharp edges share a core for
    their first 0.1 s and end later (about 10-15 ms)."""
    if faces is None:
        built = None if tree is None else tree.result()
        neighbourhoods = build_neighbourhoods(
            points, None, scales, workers=workers, backend=backend, tree=built
        )
        return neighbourhoods, None, None
    lists = dict(workers=workers, backend=backend, adjacency=adjacency)
    if workers == 1 or backend != "compiled":
        return (
            build_neighbourhoods(points, faces, scales, **lists),
            face_average_normals(points, faces, backend=backend),
            sharp_vertices(points, faces, backend=backend)[0] if robust else None,
        )
    with ThreadPoolExecutor(max_workers=1) as pool:
        side = pool.submit(
            sharp_vertices if robust else face_average_normals, points, faces, backend=backend
        )
        neighbourhoods = build_neighbourhoods(points, faces, scales, **lists)
        if robust:
            normals = face_average_normals(points, faces, backend=backend)
            return neighbourhoods, normals, side.result()[0]
        return neighbourhoods, side.result(), None


def _check_cloud_size(n_input: int, n_clean: int, k_max: int, source: str) -> None:
    """A cloud needs at least ``k_max`` distinct points."""
    if n_clean == 1 and n_input > 1:
        raise InputError(f"{source}: all {n_input} points are identical")
    if n_clean < k_max:
        dup = f" ({n_input} before merging duplicates)" if n_input != n_clean else ""
        raise InputError(
            f"{source}: {n_clean} distinct points{dup}, fewer than the largest scale "
            f"k = {k_max}; use smaller --scales"
        )


#: Where robust mode's rules on the noise are defined: the native library
#: (``ms_noise_factor``, ``ms_quiet_cloud``, ... in ``native/src/stages.c``), or, in an
#: install without it, the numpy reference's statement of the same rules.
RULES = _kernels if _kernels.available() else reference_robust


def noise_scale_factor(points: np.ndarray, indices: np.ndarray, k: int) -> float:
    """How much larger the scales must be for the noise of the points.

    Parameters
    ----------
    points : (n, 3) float64
    indices : (n, k_max) int
        kNN lists sorted by distance, the point itself first, ``k_max >= k >= 2``.
    k : int
        The first ``k`` columns give each point's plane (unweighted PCA normal ``n_i``;
        ``NOISE_KNN``).

    Returns
    -------
    float
        ``min(max(1, (nu / NOISE_TOLERATED)**2), NOISE_MAX_FACTOR)``, ``nu`` the lower
        median over the points of :func:`noise_ratios`.
    """
    return median_noise_factor(noise_ratios(points, indices, k))


def robust_plan(
    noise: float, n_kept: int, scales: Sequence[int], mesh: bool
) -> _kernels.RobustPlan:
    """Robust mode's decisions once the noise ratio ``noise`` (the lower median of
    :func:`noise_ratios`, 0 on a mesh) of ``n_kept`` points (isolated ones left out) is
    measured, at the given increasing ``scales`` (``ms_robust_plan``; the numpy
    reference's :func:`~meshlab_sharp.reference.robust.robust_plan` in an install
    without the library):

    * the scales grow as ``min(max(1, (noise / NOISE_TOLERATED)**2), NOISE_MAX_FACTOR)``,
      at most ``n_kept / k_max``, rounded half up, and so does thinning's comparison list
      ``THIN_KNN``: the band of points that noise lifts beside a line widens with it;
    * on a cloud whose noise is at most ``NOISE_QUIET`` (a quiet cloud) the thresholds
      are the floor alone (measured: thin walls 1 / 2 / 3 spacings F1 0.736 / 0.675 /
      0.896 -> 0.744 / 0.711 / 0.913, no condition lower), candidates scoring below
      ``SUPPORT_FREE_SCORE`` need no support, acute tips are looked for, and the points
      that are not candidates block thinning (the two rims of a wall 2-3 spacings thick
      then do not thin each other away); elsewhere Otsu's split, with the largest
      scale's noise floor (:func:`scale_floor`) on a noisy cloud;
    * on a noisy cloud thinning's cone is ``THIN_CONE_COS_NOISY``: noise tilts the
      offsets between a line's own points, which then count as across the line
      (measured: thickness on the scan 0.79 -> 0.82, at noise 50 % 0.78 -> 0.83);
    * thinning's side rule is ``THIN_SIDE_NOISY`` on a noisy cloud, ``THIN_SIDE`` on
      meshes and quiet clouds: noise scatters the band of candidates along an edge, and
      the cone keeps a second point of it 1-1.5 spacings off the edge wherever its
      offset to the first runs along the line. Smaller fractions thin more: at 0.45 the
      evaluation's clean clouds gained 0.015 F1 (CAD parts, 50,000 points: 0.011), but
      the rims of walls 2 spacings thick (about 1.3 spacings apart in their bands)
      thinned each other (F1 -0.020), and on a noisy cloud below 0.65 a line thins to
      gaps;
    * where the noise grew the scales to the cap, thinning ranks by the smoothed score:
      beyond it the larger scales no longer dilute the noise of the score (measured:
      noise 50 % F1 0.752 -> 0.813, thickness 0.72 -> 0.78)."""
    return RULES.robust_plan(noise, n_kept, scales, mesh)


def median_noise_factor(ratio: np.ndarray) -> float:
    """The scales' growth (``ms_noise_factor``, before :func:`robust_plan`'s cap) for
    the lower median of the per-point ratios (n,), which are reordered in place (no copy
    of n values)."""
    return RULES.noise_factor(noise_median(ratio))


def noise_median(ratio: np.ndarray) -> float:
    """The lower median of the per-point noise ratios (n,), reordered in place."""
    at = (len(ratio) - 1) // 2
    ratio.partition(at)
    return float(ratio[at])


def sheet_mask(
    points: np.ndarray,
    indices: np.ndarray,
    normals: np.ndarray,
    parameters: _kernels.SheetParameters | None = None,
) -> np.ndarray:
    """The neighbours on each point's own sheet, (n, k) bool
    (:func:`meshlab_sharp.reference.robust.sheet_mask`, where the rules are written out),
    with ``parameters`` or, by default, :func:`sheet_parameters`."""
    chosen = robust_mode.sheet_parameters() if parameters is None else parameters
    return reference_robust.sheet_mask(points, indices, normals, chosen)


def local_scale(
    points: np.ndarray, neighbourhood: Neighbourhood, *, backend: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Mean distance from each point to its neighbourhood ``l`` (m,) and its centroid's
    distance ``o`` (m,), as :func:`meshlab_sharp.reference.robust.local_scale` defines
    them, with ``backend`` (default :func:`meshlab_sharp._kernels.default_backend`; both
    give the same bits). ``points`` (m, 3) float64; ``neighbourhood`` CSR lists, each
    point's own index included."""
    if _kernels.resolve(backend) == "compiled":
        return _kernels.local_scale_csr(points, neighbourhood.indptr, neighbourhood.indices)
    return reference_robust.local_scale(points, neighbourhood)


def relative_distances(pdis: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Projected distances relative to the local scale, clipped to [0, 1].

    Parameters
    ----------
    pdis : (m,) float64
        Projected distances ``|mean . n|``.
    scale : (m,) float64
        :func:`local_scale` at the same neighbourhoods.

    Returns
    -------
    (m,) float64
        ``min(pdis / scale, 1)``; 0 where ``scale == 0``.
    """
    r = np.zeros(np.shape(pdis))
    np.divide(pdis, scale, out=r, where=scale > 0)
    return np.minimum(r, 1.0, out=r)


def robust_threshold(r: np.ndarray, otsu: bool = True, floor: float = robust_mode.R_MIN) -> float:
    """Otsu's threshold of relative distances on [0, 1], never below ``floor``.

    Parameters
    ----------
    r : (m,) float64
        Relative projected distances in [0, 1] (isolated points left out).
    otsu : bool, default True
        False on a cloud without noise (:func:`robust_plan`): the floor alone.
    floor : float, default R_MIN
        :func:`scale_floor`.

    Returns
    -------
    float
        ``max(otsu_threshold(r), floor)``, or ``floor`` when not ``otsu`` (then no
        histogram is made); candidates are ``r >= T``.
    """
    return max(otsu_threshold(r), floor) if otsu else floor


def scale_floor(
    counts: np.ndarray, last: bool, mesh: bool, noise: float, backend: str | None = None
) -> float:
    """The floor of a scale's threshold: ``R_MIN``, and on the largest scale (``last``)
    of a cloud whose noise ratio ``noise`` exceeds ``NOISE_QUIET``, at least
    ``NOISE_FLOOR`` times the median of its relative distances (at most
    ``NOISE_FLOOR_MAX``), read from their histogram ``counts`` (B,) int
    (``ms_noise_floor``; the numpy reference with ``backend="numpy"``). Measured on the
    CAD parts with noise of 25 % of the spacing (50,000 points): the end mill 0.258 ->
    0.942, filleted parts 4.19 / 4.43 % flagged -> 0.66 / 2.78 %; parts with many edges
    keep Otsu's split, which lies higher."""
    rules = reference_robust if backend == "numpy" else RULES
    return rules.scale_floor(counts, last, mesh, noise)


def acute_tests(score: np.ndarray, mask: np.ndarray, mesh: bool, noise: float) -> np.ndarray:
    """The points :func:`acute_tips` tests: on a cloud whose noise ratio ``noise`` (as
    :func:`robust_plan` takes it) is at most ``NOISE_QUIET``, those not in ``mask`` (m,)
    bool (the candidates at every scale) whose ``score`` (m,) lies in ``[ACUTE_SCORE,
    ACUTE_SCORE_MAX)``; none on meshes and noisier clouds. Returns (t,) int64,
    increasing."""
    return RULES.stage_acute_tests(score, mask, mesh, noise)


def curved_dropped(
    mask: np.ndarray,
    ends: list[np.ndarray],
    scales: tuple[int, ...],
    plan: _kernels.RobustPlan,
    backend: str | None = None,
) -> np.ndarray:
    """``mask`` (m,) bool less, where ``plan.curved_dropped`` (a mesh), the points whose
    relative distance grows from the smallest of ``scales`` to the largest (``ends``:
    their relative distances, (m,) each) at least as the square root of the ring
    (``ms_stage_curved``; the numpy reference with ``backend="numpy"``). Measured on
    CAD tessellations of 24 segments a turn (50,000-point parts): a filleted box 1.74 %
    flagged -> 0, a filleted cross 0.16 -> 0.07 % (what is left: the vertices of its
    tessellation's own creases), the rounded box of the smooth meshes at 6,000 points
    1.12 -> 0 %; no crease of the evaluation's meshes is found by the rings alone."""
    if not plan.curved_dropped or len(scales) < 2:
        return mask
    rules = reference_robust if backend == "numpy" else RULES
    return rules.stage_curved(ends[0], ends[-1], scales[0], scales[-1], mask)


def plan_thresholds(plan: _kernels.RobustPlan, counts: np.ndarray) -> np.ndarray:
    """Each scale's threshold (s,) from its histogram ``counts`` (s, B) by ``plan``'s
    rules, in numpy: Otsu's split when ``plan.otsu``, never below the reference's
    :func:`~meshlab_sharp.reference.robust.scale_floor` (``ms_plan_thresholds``)."""
    last = len(plan.scales) - 1
    out = [
        reference_robust.scale_floor(c, s == last, plan.mesh, plan.noise)
        for s, c in enumerate(np.asarray(counts))
    ]
    if plan.otsu:
        out = [max(otsu_from_histogram(c), floor) for c, floor in zip(counts, out, strict=True)]
    return np.array(out, dtype=np.float64)


def support_exempt(score: np.ndarray, plan: _kernels.RobustPlan) -> np.ndarray:
    """The points that :func:`~meshlab_sharp.reference.robust.supported` keeps without
    support: those whose ``score`` (m,) is below ``plan.free_below`` (none where the plan
    has no such score: meshes and noisy clouds). Returns (m,) bool."""
    score = np.asarray(score, np.float64)
    if plan.free_below is None:
        return np.zeros(len(score), bool)
    return score < plan.free_below


def thin_blockers(candidates: np.ndarray, plan: _kernels.RobustPlan) -> np.ndarray | None:
    """:func:`~meshlab_sharp.reference.robust.thin`'s ``between``: where
    ``plan.thin_between`` (a quiet cloud), the points that are not ``candidates`` (m,)
    bool (at every scale); None (no blocking) otherwise. The end face's middle between
    the two rims of a thin wall is not a candidate, or ranks below both (a valley of the
    score, which ``thin`` also reads as a parting)."""
    if not plan.thin_between:
        return None
    return ~np.asarray(candidates, bool)


def pass_noise_median(ratio: np.ndarray, workers: int = -1) -> float:
    """:func:`noise_median` of the compiled pass's ratios (n,), the
    same value, on ``workers`` threads (:func:`meshlab_sharp._kernels.lower_median`)."""
    median = _kernels.lower_median(ratio, workers)
    return noise_median(ratio) if median is None else median


def isolated_from_stats(
    points: np.ndarray, stats: _kernels.CloudStats, workers: int = -1
) -> np.ndarray:
    """:func:`isolated_points` from the pass's :class:`~meshlab_sharp._kernels.CloudStats` at
    ``k_max`` (no kNN table): ``i`` is among the k_max nearest of ``j = near[i]`` when
    ``(|p_i - p_j|^2, i)`` does not come after ``j``'s k_max-th neighbour in the
    lists' order (squared distance, then index), and the second rule (ISOLATED_SPREAD).
    (n,) bool, computed in C (:func:`meshlab_sharp._kernels.isolated_from_stats`)."""
    return _kernels.isolated_from_stats(points, stats, robust_mode.ISOLATED_SPREAD, workers)


@dataclass
class RelativeRule:
    """Per-scale rule of robust mode for :func:`meshlab_sharp.multiscale.run_scales`.

    Called as ``rule(i, scale, pdis)`` for the i-th scale (the compiled pass, which does
    this arithmetic itself, hands its score to ``rule.from_pass`` instead): returns
    the relative distances (m,) and the threshold; it also accumulates ``score``, the mean over the
    scales of ``o / l`` (:func:`local_scale`: the centroid's distance relative to the
    local scale), the ranking used by :func:`thin`. Not ``r``: at an acute edge the
    normal turns, the projected distance peaks beside the edge, the centroid's distance
    at the edge.

    Parameters
    ----------
    points : (m, 3) float64
    lists : callable
        ``lists(scale) -> Neighbourhood``, the neighbourhoods of that scale (called in
        increasing order of scale).
    n_scales : int
    sheet : (float, int, float, float, float, float) or None
        :func:`sheet_parameters` when ``lists`` leave out the other sheets
        (:class:`SheetNeighbourhoods`): the compiled pass over a cloud then does too.
    otsu : bool, default True
        Whether Otsu's split raises the thresholds above the floor (:func:`otsu_splits`;
        :func:`robust_threshold`).
    noise : float, default 0.0
        The cloud's noise ratio, read by :func:`scale_floor` (0 on a mesh).
    backend : {"compiled", "numpy"}, optional
        :func:`local_scale`'s; default :func:`meshlab_sharp._kernels.default_backend`.
    keep_ends : bool, default False
        Keep the relative distances of the smallest and the largest scale in ``ends``
        (read by :func:`curved_dropped`).
    """

    points: np.ndarray
    lists: object
    n_scales: int
    sheet: _kernels.SheetParameters | None = None
    otsu: bool = True
    noise: float = 0.0
    backend: str | None = None
    keep_ends: bool = False

    def __post_init__(self) -> None:
        self.score = np.zeros(len(self.points))
        #: The relative distances (m,) of the smallest and the largest scale, with
        #: ``keep_ends``.
        self.ends: list[np.ndarray] = []

    def _keep(self, i: int, r: np.ndarray) -> None:
        """Keep the i-th scale's relative distances ``r`` (m,) when they are an end."""
        if self.keep_ends and i in (0, self.n_scales - 1):
            self.ends.append(np.array(r, np.float64))

    def __call__(self, i: int, scale: int, pdis: np.ndarray) -> tuple[np.ndarray, float]:
        """Relative distances (m,) and threshold of the i-th scale, ``scale``."""
        lists = self.lists(scale)  # type: ignore[operator]
        ell, offset = local_scale(self.points, lists, backend=self.backend)
        r = relative_distances(np.asarray(pdis, np.float64), ell)
        self.score += relative_distances(offset, ell) / self.n_scales
        self._keep(i, r)
        # one histogram for Otsu's split and the largest scale's floor
        last = i == self.n_scales - 1
        counts = histogram(r) if self.otsu or last else None
        floor = scale_floor(counts, last, False, self.noise, self.backend)
        return r, max(otsu_from_histogram(counts), floor) if self.otsu else floor

    def floor(self, i: int, r: np.ndarray) -> float:
        """:func:`scale_floor` of the i-th scale's relative distances ``r`` (m,)."""
        last = i == self.n_scales - 1
        counts = histogram(r) if last else None  # read on the largest scale only
        return scale_floor(counts, last, False, self.noise, self.backend)

    def from_pass(self, score: np.ndarray, i: int, r: np.ndarray) -> tuple[bool, float]:
        """Take the final ``score`` (m,) of the compiled pass (over a cloud or a mesh's
        rings), which computed it and every scale's relative distances with this rule's
        arithmetic (:class:`meshlab_sharp._kernels.ScalePass`); returns how
        :func:`robust_threshold` thresholds the i-th scale's, ``r``
        (m,), ``(otsu, floor)``, for :func:`meshlab_sharp._kernels.scale_vote` (the same
        threshold)."""
        self.score = score
        self._keep(i, r)
        return self.otsu, self.floor(i, r)


class RobustSetup:
    """What robust mode adds around :func:`meshlab_sharp.multiscale.run_scales`.

    Parameters
    ----------
    points : (m, 3) float64
        Cleaned points.
    faces : (f, 3) int or None
        Cleaned triangles of a mesh; None for a cloud.
    neighbourhoods : KnnNeighbourhoods or RingNeighbourhoods
        Those of ``points`` (built by the pipeline).
    scales : tuple of int
        Increasing scales.
    workers : int, default -1
        Threads for a kNN query when isolated points are left out, and for the line
        directions.
    weighting : {"gaussian", "none"}, default "gaussian"
    keep_normals : bool, default False
        How :func:`meshlab_sharp.multiscale.run_scales` will be called (the compiled
        pass that finds the isolated points and the noise also computes what it needs).
    sharp_edges : (m,) bool, optional
        A mesh's :func:`meshlab_sharp.creases.sharp_vertices` mask when the caller has
        found it already (``detect`` finds it on a thread beside the adjacency); None:
        found here.

    Attributes
    ----------
    keep : (p,) int64
        Indices (into ``points``) of the points processed: all for a mesh, the
        non-isolated ones for a cloud.
    points, neighbourhoods
        The points processed and their neighbourhoods (rebuilt without the isolated
        points when there are any).
    rule : RelativeRule
        The per-scale rule to pass to ``run_scales``.
    fused : ScalePass or None
        The compiled pass over ``points`` at ``scales`` to pass to ``run_scales``, when
        the set-up's search already made it (compiled backend, a cloud whose noise did
        not grow the scales); None otherwise, and once :meth:`finish` starts (its
        per-scale arrays, read by ``run_scales``, are released before support and
        thinning).
    sharp_edges : (m,) bool or None
        A mesh's vertices on its own sharp edges
        (:func:`meshlab_sharp.creases.sharp_vertices`): the ``sharp_edges`` given, or
        found here before the ring pass's arrays exist; None for a cloud.
    """

    def __init__(
        self,
        points: np.ndarray,
        faces: np.ndarray | None,
        neighbourhoods: KnnNeighbourhoods | RingNeighbourhoods,
        scales: tuple[int, ...],
        *,
        workers: int = -1,
        weighting: Weighting = DEFAULT_WEIGHTING,
        keep_normals: bool = False,
        sharp_edges: np.ndarray | None = None,
    ) -> None:
        self.n = len(points)
        #: A mesh's set-up (the faces themselves are not kept: 48 bytes a vertex).
        self.mesh = faces is not None
        self.workers = workers
        self.scales = tuple(scales)
        self.keep = np.arange(self.n, dtype=np.int64)
        self.points = points
        self.neighbourhoods = neighbourhoods
        self.weighting = weighting
        self.keep_normals = keep_normals
        #: The neighbourhoods' backend, which every step of the set-up and of
        #: :meth:`finish` runs with.
        self.backend = neighbourhoods.backend
        self.fused: _kernels.ScalePass | None = None
        #: How much the noise grew the scales (1: not at all).
        self.growth = 1.0
        #: Every decision once the noise is measured (:func:`robust_plan`).
        self.plan: _kernels.RobustPlan
        #: The cloud's noise ratio (the lower median of :func:`noise_ratios`; 0 on a mesh).
        self.noise = 0.0
        #: The neighbourhoods the scales use: ``neighbourhoods`` (meshes; clouds with
        #: the compiled pass, which leaves the other sheets out itself), or their
        #: :class:`SheetNeighbourhoods` (clouds, numpy).
        self.scale_neighbourhoods: KnnNeighbourhoods | RingNeighbourhoods | SheetNeighbourhoods
        self.scale_neighbourhoods = neighbourhoods
        sheet = None
        if faces is None:
            assert isinstance(neighbourhoods, KnnNeighbourhoods)
            sheet = robust_mode.sheet_parameters()
            top = max(self.scales)
            k0 = min(robust_mode.NOISE_KNN, top)
            compiled = neighbourhoods.tree is not None
            if compiled:
                self.fused = self._pass(k0, sheet)
                assert self.fused.stats is not None
                isolated = isolated_from_stats(points, self.fused.stats, workers)
            else:
                isolated = isolated_points(
                    points,
                    neighbourhoods.indices,
                    nth=robust_mode.ISOLATED_NTH,
                    ref=robust_mode.ISOLATED_REF,
                    spread=robust_mode.ISOLATED_SPREAD,
                )
            if isolated.any():
                self.fused = None  # freed before the pass over the points kept
                self.keep = np.flatnonzero(~isolated)
                self.points = np.ascontiguousarray(points[self.keep])
                self.neighbourhoods = build_neighbourhoods(
                    self.points, None, self.scales, workers=workers, backend=self.backend
                )
                if compiled:
                    self.fused = self._pass(k0, sheet)
            del isolated
            if self.fused is not None and self.fused.stats is not None:
                self.noise = pass_noise_median(self.fused.stats.noise, workers)
                self.fused.stats = None  # read: its (n,) arrays are not kept
                self.scale_neighbourhoods = self.neighbourhoods
            else:
                self.scale_neighbourhoods = self._sheets()
                self.noise = noise_median(
                    noise_ratios_lists(self.points, self.scale_neighbourhoods.first(k0))
                )
            self.plan = robust_plan(self.noise, len(self.points), self.scales, False)
            if self.plan.grown:
                self.growth = self.plan.growth
                self.scales = self.plan.scales
                self.neighbourhoods = build_neighbourhoods(
                    self.points, None, self.scales, workers=workers, backend=self.backend
                )
                self.fused = None
                self.scale_neighbourhoods = self.neighbourhoods if compiled else self._sheets()
        else:
            self.plan = robust_plan(0.0, self.n, self.scales, True)
        if faces is None:
            self.sharp_edges = None
        elif sharp_edges is None:
            self.sharp_edges = sharp_vertices(points, faces, backend=self.backend)[0]
        else:
            self.sharp_edges = np.asarray(sharp_edges, bool)
        # the lists' own method, not one of self: a rule that referred back to this
        # setup made a reference cycle, so the arrays of every call (the kd-tree, the
        # pass's outputs: about 55 bytes a point) stayed until the garbage collector ran
        lists = self.scale_neighbourhoods.at
        self.rule = RelativeRule(
            self.points,
            lists,
            len(self.scales),
            sheet,
            self.plan.otsu,
            self.noise,
            self.backend,
            keep_ends=self.plan.curved_dropped,
        )

    def _sheets(self) -> SheetNeighbourhoods:
        """:class:`SheetNeighbourhoods` of ``neighbourhoods`` (numpy kNN lists)."""
        assert isinstance(self.neighbourhoods, KnnNeighbourhoods)
        return SheetNeighbourhoods(
            self.points, self.neighbourhoods, self.weighting, robust_mode.sheet_parameters()
        )

    def _pass(self, noise_k: int, sheet: _kernels.SheetParameters) -> _kernels.ScalePass:
        """The compiled pass at ``scales`` over ``points`` (whose kd-tree
        ``neighbourhoods`` holds): projected distances, local scales, and the isolated
        points' and the noise's statistics from the same search. It is the pass
        ``run_scales`` needs when it finds no isolated points and no noise to grow the
        scales for (``fused``)."""
        assert isinstance(self.neighbourhoods, KnnNeighbourhoods)
        assert self.neighbourhoods.tree is not None
        return _kernels.cloud_projected_distances(
            self.neighbourhoods.tree,
            self.scales,
            self.weighting,
            keep_normals=self.keep_normals,
            relative=True,
            noise_k=noise_k,
            isolated=(robust_mode.ISOLATED_NTH, robust_mode.ISOLATED_REF),
            sheet=sheet,
            workers=self.neighbourhoods.workers,
            tree_order=True,  # read by scale_vote, isolated_from_stats and a median only
        )

    def _compiled(self) -> bool:
        """Whether :meth:`finish` runs its steps in C: the neighbourhoods are the compiled
        backend's (a cloud's kd-tree, a mesh's adjacency)."""
        lists = self.neighbourhoods
        if isinstance(lists, KnnNeighbourhoods):
            return lists.tree is not None
        return lists.adjacency is not None

    def _candidate_lists(self, rows: np.ndarray, ks: tuple[int, ...]) -> list[Neighbourhood]:
        """The kNN lists at each of ``ks`` (at most ``k_max``) for the points ``rows``
        (increasing) only, the other rows empty: what support and thinning read (numpy)."""
        assert isinstance(self.neighbourhoods, KnnNeighbourhoods)
        table = np.asarray(self.neighbourhoods.indices)[rows, : max(ks)]
        before = np.zeros(len(self.points) + 1, dtype=np.int64)  # rows before each point
        before[np.asarray(rows, dtype=np.int64) + 1] = 1
        np.cumsum(before, out=before)
        return [
            Neighbourhood(before * k, np.ascontiguousarray(table[:, :k]).reshape(-1)) for k in ks
        ]

    def _ring_rows(self, rows: np.ndarray, rings: tuple[int, ...]) -> list[Neighbourhood]:
        """The k-rings, k in ``rings`` (increasing), of the vertices ``rows`` only (the
        other rows empty), each listed as ``RingNeighbourhoods.at(k)`` lists it (a row
        depends only on its vertex: :func:`meshlab_sharp.neighbourhoods.grow_rings`)."""
        assert isinstance(self.neighbourhoods, RingNeighbourhoods)
        grown = grow_rings(self.neighbourhoods.lists(), rows)
        listed = dict(zip(range(1, max(rings) + 1), grown, strict=False))
        out = []
        for k in rings:
            indptr = np.zeros(self.n + 1, dtype=np.int64)  # the sizes, summed in place
            indptr[np.asarray(rows, dtype=np.int64) + 1] = listed[k].sizes
            np.cumsum(indptr, out=indptr)
            out.append(Neighbourhood(indptr, listed[k].indices))
        return out

    def _list_sizes(self) -> tuple[int, int, int]:
        """The sizes of each candidate's support, comparison and direction lists: the
        plan's (clouds: the SUPPORT_KNN and thinning's nearest; meshes: the
        THIN_RING-ring twice) and the largest scale."""
        return self.plan.support_knn, self.plan.compare_knn, max(self.scales)

    def _acute_tests(self, mask: np.ndarray) -> np.ndarray:
        """The points tested as acute tips where the plan looks for them
        (:func:`acute_tests`), (t,) int64; else none."""
        if not self.plan.acute_tests:
            return np.zeros(0, np.int64)
        return acute_tests(self.rule.score, mask, self.mesh, self.noise)

    def finish(self, mask: np.ndarray, strength: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Meshes) the candidates on a curved surface dropped (:func:`curved_dropped`),
        acute tips (clouds without noise), support, thinning and (meshes) the sharp
        mesh edges, on all cleaned points: in C with the compiled backend
        (:meth:`_finish_compiled`), in numpy otherwise (:meth:`_finish_numpy`), the same
        masks.

        Parameters
        ----------
        mask : (p,) bool
            Candidates at every scale, per processed point (:func:`acute_tips` adds
            the tips of acute edges on a cloud without noise).
        strength : (p,) float64
            Fraction of scales at which each processed point was a candidate.

        Returns
        -------
        mask, strength : (m,) bool, (m,) float64
            Per cleaned point (isolated points: False, 0). On a mesh, vertices of a
            sharp edge (:func:`meshlab_sharp.creases.sharp_vertices`) are features with
            strength 1.
        """
        self.fused = None
        mask = curved_dropped(mask, self.rule.ends, self.scales, self.plan, self.backend)
        self.rule.ends = []  # read: its (m,) arrays are not kept
        if mask.any():
            mask = self._finish_compiled(mask) if self._compiled() else self._finish_numpy(mask)
        if self.sharp_edges is not None:
            mask = mask | self.sharp_edges
            strength = np.where(self.sharp_edges, 1.0, strength)
        return self.expand(mask, False), self.expand(strength, 0.0)

    def _finish_numpy(self, mask: np.ndarray) -> np.ndarray:
        """:meth:`finish`'s acute tips, support and thinning of ``mask`` (p,) bool in
        numpy (the reference): the thinned mask (p,) bool."""
        mesh = self.mesh
        around_k, compare_k, top = self._list_sizes()
        tests = self._acute_tests(mask)
        if len(tests):
            (near,) = self._candidate_lists(tests, (compare_k,))
            mask = mask.copy()
            mask[tests[acute_tips(self.points, mask, tests, near)]] = True
        if mesh:
            around, direction = self._ring_rows(np.flatnonzero(mask), (around_k, top))
            compare = around
        else:
            around, compare, direction = self._candidate_lists(
                np.flatnonzero(mask), (around_k, compare_k, top)
            )
        e = line_directions(self.points, mask, direction, self.workers)
        free = support_exempt(self.rule.score, self.plan)
        block = thin_blockers(mask, self.plan)
        rank = self.rule.score
        if self.plan.ranking_smoothed:
            rank = smoothed_ranking(rank, compare, robust_mode.THIN_KNN)
        mask = supported(
            self.points,
            mask,
            e,
            around,
            robust_mode.SUPPORT_MIN,
            cone_cos=robust_mode.THIN_CONE_COS,
            exempt=free,
        )
        mask = thin(
            self.points,
            mask,
            rank,
            e,
            compare,
            cone_cos=self.plan.thin_cone,
            side=self.plan.thin_side,
            between=block,
        )
        if self.plan.thin_line:
            mask = line_test(self.points, mask, rank, compare, between=block)
        return mask

    def _finish_compiled(self, mask: np.ndarray) -> np.ndarray:
        """:meth:`_finish_numpy` in C (:func:`meshlab_sharp._kernels.acute_tips` and
        :func:`~meshlab_sharp._kernels.support_and_thin`), the candidates taken in tree
        order (clouds; each step independent per candidate, the order changes nothing)
        with their lists from the kd-tree (one table of the k_max nearest of the
        candidates and the points tested as tips, read at every k) or the adjacency (the
        largest ring, its THIN_RING-ring a prefix): the same mask."""
        around_k, compare_k, top = self._list_sizes()
        lists = self.neighbourhoods
        if isinstance(lists, KnnNeighbourhoods):
            assert lists.tree is not None
            tests = self._acute_tests(mask)
            todo = mask
            if len(tests):
                todo = mask.copy()
                todo[tests] = True
            # one search for the candidates and the points tested as acute tips, in tree
            # order (no inverse of the tree's order, the rows of a leaf searched together)
            rows, table = _kernels.cloud_knn_of_mask(lists.tree, todo, top, lists.workers)
            del todo
            slots = None  # every row of the table
            if len(tests):
                tested = np.flatnonzero(~mask[rows])
                near = _kernels.CandidateLists.knn(table, compare_k, tested)
                tips = _kernels.acute_tips(self.points, mask, rows[tested], near, self.workers)
                mask = mask.copy()
                mask[rows[tested[tips]]] = True
                slots = np.flatnonzero(mask[rows])
                rows = rows[slots]
            around, compare, direction = (
                _kernels.CandidateLists.knn(table, k, slots) for k in (around_k, compare_k, top)
            )
        else:
            assert lists.adjacency is not None
            rows = np.flatnonzero(mask)
            members = _kernels.ring_members(lists.adjacency, rows, (around_k, top), self.workers)
            around, direction = _kernels.CandidateLists.rings(members)
            compare = around
        rules = _kernels.FinishRules(
            support_cone=robust_mode.THIN_CONE_COS,
            minimum=robust_mode.SUPPORT_MIN,
            free_below=self.plan.free_below,
            thin_cone=self.plan.thin_cone,
            thin_side=self.plan.thin_side,
            window=robust_mode.THIN_KNN if self.plan.ranking_smoothed else 0,
            between=thin_blockers(mask, self.plan),
            line=robust_mode.line_rules() if self.plan.thin_line else None,
        )
        return _kernels.support_and_thin(
            self.points,
            mask,
            self.rule.score,
            rows,
            (direction, around, compare),
            rules,
            self.workers,
        )

    def expand(self, values: np.ndarray, fill: object) -> np.ndarray:
        """Per-processed-point values (p, ...) to all cleaned points (m, ...), ``fill``
        for the isolated ones."""
        if len(self.keep) == self.n:
            return values
        out = np.full((self.n,) + values.shape[1:], fill, dtype=values.dtype)
        out[self.keep] = values
        return out
