"""The whole detection, one way: load -> clean -> neighbourhoods -> normals ->
projected distance -> threshold -> decide, with every result in the input's order.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from typing import Any

import numpy as np

from . import _detect_native, _kernels
from .cleaning import CleanGeometry, clean
from .creases import sharp_vertices
from .curves import extract_curves
from .defaults import DEFAULT_MODE
from .errors import InputError
from .io import Geometry
from .multiscale import DEFAULT_KNN_SCALES, DEFAULT_RING_SCALES, decide, run_scales
from .neighbourhoods import (
    KnnNeighbourhoods,
    RingNeighbourhoods,
    build_neighbourhoods,
    far_points,
    unit_scale,
)
from .normals import DEFAULT_WEIGHTING, Weighting, face_average_normals
from .options import Source, as_input, check_mode_and_weighting, check_scales
from .preprocessing import (
    Preprocessing,
    PreprocessingReport,
    as_preprocessing,
    map_to_input,
    preprocess,
)
from .progress import Progress, cleared_on_error
from .result import DetectionResult
from .robust import RobustSetup


def detect(
    source: Source,
    faces: np.ndarray | None = None,
    *,
    scales: Sequence[int] | int | None = None,
    weighting: Weighting = DEFAULT_WEIGHTING,
    as_points: bool = False,
    return_details: bool = False,
    progress: bool | Progress = False,
    workers: int = -1,
    preprocessing: Preprocessing | dict[str, Any] | None = None,
    mode: str = DEFAULT_MODE,
    backend: str | None = None,
    curves: bool = False,
    max_memory: str | int | None = None,
    dask: Any = None,
    scratch: str | os.PathLike[str] | None = None,
) -> DetectionResult:
    """Find the sharp features of a point cloud or triangle mesh.

    Parameters
    ----------
    source : path, (n, 3) array, Geometry, pymeshlab.MeshSet or pymeshlab.Mesh
        The input. A path is read with :func:`meshlab_sharp.load`; a MeshSet contributes
        its current mesh.
    faces : (m, 3) int array, optional
        Triangles, when ``source`` is an array. None: a point cloud.
    scales : int or sequence of int, optional
        kNN sizes for clouds (default 12, 16, ..., 40) or rings for meshes (default
        1, 2, 3, 4); at most :data:`~meshlab_sharp.options.MAX_SCALES`. A single int is one scale.
    weighting : {"gaussian", "none"}, default "gaussian"
        Weights of the PCA normals (clouds, and mesh vertices without a face normal).
    as_points : bool, default False
        Ignore faces: process a mesh's vertices as a point cloud.
    return_details : bool, default False
        Also return per-scale normalised projected distances and normals.
    progress : bool or Progress, default False
        Draw a progress bar on stderr (True), or report to the given Progress.
    workers : int, default -1
        Threads for the kNN query (-1: all cores).
    preprocessing : Preprocessing or dict, optional
        pymeshlab filters run first (outlier removal, denoising, hole filling,
        simplification; see :mod:`meshlab_sharp.preprocessing`). Detection runs on the
        processed geometry; results are mapped back to the input's vertices (removed
        ones: not features, ``kept`` False; vertices added by hole filling: left out).
    mode : {"robust", "paper"}, default "robust"
        "robust" (the default): isolated points left
        out, scales grown with the measured noise, projected distances relative to the
        local spacing, a threshold floor (no features on smooth objects), support along
        and thinning across the lines, and on meshes the mesh's own sharp edges
        (:mod:`meshlab_sharp.robust`, docs/method.md); ``distances`` are then the
        relative distances and ``scales`` the scales used. "paper": ALGORITHM.md's
        reading of the paper, exactly.
    backend : {"compiled", "numpy"}, optional
        The compiled kernels (default when built) or the numpy reference path; both
        give the same answers. Default: ``MESHLAB_SHARP_BACKEND`` or "compiled".
    curves : bool, default False
        Also extract the feature curves and corners (``result.curves``,
        ``result.corners``; :mod:`meshlab_sharp.curves`): mesh edge chains on meshes,
        refined polylines on clouds. Off by default, so detection's time is unchanged.
        With ``max_memory``/``dask`` they are extracted after the tiled detection from
        the features and the points near them only (the same curves).
    max_memory : str or int, optional
        Out of core ("1GB"): a point cloud is processed in spatial tiles with halos
        (:mod:`meshlab_sharp.tiles`), keeping the peak memory under this; the result is
        the in-memory one. Point clouds only (a mesh needs ``as_points``); a path is
        streamed (binary PLY, LAS/LAZ, E57) instead of loaded whole.
    dask : str or dask.distributed.Client, optional
        Run the tiles as Dask tasks: "local:N" (N local worker processes),
        "tcp://HOST:PORT" (a running scheduler) or a Client. Same result.
    scratch : path, optional
        Folder for the tiles' on-disk arrays (with a cluster: one every worker reaches).

    Returns
    -------
    DetectionResult

    Raises
    ------
    InputError
        Unreadable input, non-finite coordinates, too few distinct points for the
        largest scale, invalid options. All points on one plane is not an error: the
        result has no features.
    """
    try:
        backend = _kernels.resolve(backend)
    except (ValueError, RuntimeError) as exc:
        raise InputError(str(exc)) from None
    if max_memory is not None or dask is not None:
        from .tiles import detect_out_of_core

        options = dict(scales=scales, weighting=weighting, as_points=as_points, mode=mode)
        with cleared_on_error():
            return detect_out_of_core(
                source,
                faces,
                **options,
                return_details=return_details,
                progress=progress,
                workers=workers,
                preprocessing=preprocessing,
                backend=backend,
                max_memory=max_memory,
                dask=dask,
                scratch=scratch,
                curves=curves,
            )
    with cleared_on_error():
        return _detect(
            source,
            faces,
            scales=scales,
            weighting=weighting,
            as_points=as_points,
            return_details=return_details,
            progress=progress,
            workers=workers,
            preprocessing=preprocessing,
            mode=mode,
            backend=backend,
            curves=curves,
        )


def _detect(
    source: Source,
    faces: np.ndarray | None,
    *,
    scales: Sequence[int] | int | None,
    weighting: Weighting,
    as_points: bool,
    return_details: bool,
    progress: bool | Progress,
    workers: int,
    preprocessing: Preprocessing | dict[str, Any] | None,
    mode: str,
    backend: str,
    curves: bool = False,
) -> DetectionResult:
    """:func:`detect` in memory, every step with ``backend`` (resolved: "compiled" or
    "numpy")."""
    check_mode_and_weighting(mode, weighting)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    geometry = as_input(source, faces, as_points)
    timings["load"] = time.perf_counter() - t0
    steps = as_preprocessing(preprocessing)
    if steps is not None and steps.active:
        t = time.perf_counter()
        log: list[dict[str, Any]] = []
        # pymeshlab's filters too run on coordinates of O(1) (some hang or empty the mesh
        # at 1e100 units); the processed geometry is reported in the input's unit.
        unit, exponent = unit_scale(geometry.vertices)
        given = Geometry(unit, None if as_points else geometry.faces, geometry.source)
        processed, to_input = preprocess(given, steps, log=log)
        in_unit = processed
        if exponent:
            in_unit = replace(processed, vertices=np.ldexp(processed.vertices, exponent))
        report = PreprocessingReport(log, in_unit, to_input, seconds=time.perf_counter() - t)
        inner = detect(
            processed,
            scales=scales,
            weighting=weighting,
            return_details=return_details,
            progress=progress,
            workers=workers,
            mode=mode,
            backend=backend,
        )
        result = map_to_input(inner, to_input, len(geometry.vertices), report)
        result.timings = {**inner.timings, "load": timings["load"], "preprocess": report.seconds}
        if curves:
            _add_curves(result, geometry, as_points, backend)
        result.timings["total"] = time.perf_counter() - t0
        return result

    is_mesh = geometry.is_mesh and not as_points
    kind = "mesh" if is_mesh else "points"
    scales_t = check_scales(scales, DEFAULT_RING_SCALES if is_mesh else DEFAULT_KNN_SCALES, kind)
    bar = (
        progress
        if isinstance(progress, Progress)
        else Progress(len(scales_t) + 3, enabled=progress)
    )
    if not return_details and backend == "compiled":
        # the native library's sequence (ms_detect); an input it refuses takes the path
        # below, which raises the error
        native = _detect_native.detect(
            geometry,
            is_mesh=is_mesh,
            scales=scales_t,
            mode=mode,
            weighting=weighting,
            workers=workers,
            bar=bar,
        )
        if native is not None:
            result = DetectionResult(
                mask=native.mask,
                strength=native.strength,
                kind=kind,
                scales=native.scales,
                thresholds=native.thresholds,
                candidate_counts=native.candidate_counts,
                kept=native.kept,
                weighting=weighting,
                n_clean=native.n_clean,
                timings={**timings, **native.timings},
                mode=mode,
                backend=backend,
            )
            return _finish(result, geometry, as_points, curves, bar, progress, t0)

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
        _check_cloud_size(len(geometry.vertices), len(points), max(scales_t), geometry.source)

    t = time.perf_counter()
    neighbourhoods, normals, sharp_edges = _neighbourhoods_and_normals(
        points,
        cleaned.faces if is_mesh else None,
        scales_t,
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
            scales_t,
            workers=workers,
            weighting=weighting,
            keep_normals=return_details,
            sharp_edges=sharp_edges,
        )
        del sharp_edges
        work, work_neighbourhoods = robust.points, robust.scale_neighbourhoods
        scales_t = robust.scales
    # no step reads the cleaned faces now (the neighbourhoods and the set-up keep none):
    # freed before the scales' pass, where the peak was (48 bytes a vertex)
    cleaned = replace(cleaned, faces=None)
    timings["neighbourhoods"] = time.perf_counter() - t
    bar.step("neighbourhoods")

    t = time.perf_counter()
    per_scale = run_scales(
        work,
        work_neighbourhoods,
        scales_t,
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
    mask, strength = decide(per_scale.votes, len(scales_t))
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
        scales=scales_t,
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
    return _finish(result, geometry, as_points, curves, bar, progress, t0)


def _finish(
    result: DetectionResult,
    geometry: Geometry,
    as_points: bool,
    curves: bool,
    bar: Progress,
    progress: bool | Progress,
    t0: float,
) -> DetectionResult:
    """The curves when asked for, the total time and the progress bar's end."""
    if curves:
        _add_curves(result, geometry, as_points, result.backend)
    result.timings["total"] = time.perf_counter() - t0
    bar.step("done")
    if not isinstance(progress, Progress):
        bar.close()
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


def _add_curves(result: DetectionResult, geometry: Geometry, as_points: bool, backend: str) -> None:
    """Extract the feature curves of ``result`` on the input geometry with the
    detection's ``backend`` (timed)."""
    t = time.perf_counter()
    faces = None if as_points else geometry.faces
    result.curves, result.corners = extract_curves(
        geometry.vertices, result.mask, faces, result.kept, backend=backend
    )
    result.timings["curves"] = time.perf_counter() - t


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
