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
from dataclasses import replace

import numpy as np

from .. import _kernels
from ..cleaning import CleanGeometry, clean
from ..creases import sharp_vertices
from ..defaults import DEFAULT_MODE
from ..errors import InputError
from ..io import Geometry
from ..multiscale import DEFAULT_KNN_SCALES, DEFAULT_RING_SCALES, decide, run_scales
from ..neighbourhoods import (
    KnnNeighbourhoods,
    RingNeighbourhoods,
    build_neighbourhoods,
    far_points,
    unit_scale,
)
from ..normals import DEFAULT_WEIGHTING, Weighting, face_average_normals
from ..options import Source, as_input, check_mode_and_weighting, check_scales
from ..progress import Progress
from ..result import DetectionResult
from ..robust import RobustSetup


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
    check_mode_and_weighting(mode, weighting)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    geometry = as_input(source, faces, as_points)
    timings["load"] = time.perf_counter() - t0
    is_mesh = geometry.is_mesh and not as_points
    kind = "mesh" if is_mesh else "points"
    scales_t = check_scales(scales, DEFAULT_RING_SCALES if is_mesh else DEFAULT_KNN_SCALES, kind)
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
