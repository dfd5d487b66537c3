"""The whole detection: load, optional preprocessing, then the sequence (clean ->
neighbourhoods -> normals -> projected distance -> threshold -> decide) run by the native
library (``ms_detect``, :mod:`meshlab_sharp._detect_native`) with the compiled backend,
or by its Python-driven reference (:mod:`meshlab_sharp.reference.detect`) with the
numpy backend; every result in the input's order.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from . import _detect_native, _kernels
from .curves import extract_curves
from .defaults import DEFAULT_MODE
from .errors import InputError
from .io import Geometry
from .neighbourhoods import unit_scale
from .normals import DEFAULT_WEIGHTING, Weighting
from .options import Source, input_scales, load_input
from .preprocessing import (
    Preprocessing,
    PreprocessingReport,
    as_preprocessing,
    map_to_input,
    preprocess,
)
from .progress import Progress, cleared_on_error
from .reference import detect as reference_sequence
from .result import DetectionResult


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
        Threads the detection runs on (-1: every core).
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
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    geometry = load_input(source, faces, as_points, mode, weighting, timings)
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

    is_mesh, scales_t = input_scales(geometry, as_points, scales)
    bar = (
        progress
        if isinstance(progress, Progress)
        else Progress(len(scales_t) + 3, enabled=progress)
    )
    if backend == "compiled":
        # the native library's sequence (ms_detect); an input it refuses takes the
        # Python-driven one below, which raises the error
        native = _detect_native.detect(
            geometry,
            is_mesh=is_mesh,
            scales=scales_t,
            mode=mode,
            weighting=weighting,
            workers=workers,
            bar=bar,
            details=return_details,
        )
        if native is not None:
            result = DetectionResult(
                mask=native.mask,
                strength=native.strength,
                kind="mesh" if is_mesh else "points",
                scales=native.scales,
                thresholds=native.thresholds,
                candidate_counts=native.candidate_counts,
                kept=native.kept,
                weighting=weighting,
                n_clean=native.n_clean,
                timings={**timings, **native.timings},
                mode=mode,
                backend=backend,
                distances=native.distances,
                normals=native.normals,
            )
            return _finish(result, geometry, as_points, curves, bar, progress, t0)

    result = reference_sequence.run(
        geometry,
        is_mesh=is_mesh,
        scales=scales_t,
        weighting=weighting,
        return_details=return_details,
        workers=workers,
        mode=mode,
        backend=backend,
        bar=bar,
        timings=timings,
    )
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


def _add_curves(result: DetectionResult, geometry: Geometry, as_points: bool, backend: str) -> None:
    """Extract the feature curves of ``result`` on the input geometry with the
    detection's ``backend`` (timed)."""
    t = time.perf_counter()
    faces = None if as_points else geometry.faces
    result.curves, result.corners = extract_curves(
        geometry.vertices, result.mask, faces, result.kept, backend=backend
    )
    result.timings["curves"] = time.perf_counter() - t
