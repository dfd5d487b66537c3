"""The native library's whole detection (``ms_detect``, the sequence of both modes that
the MeshLab plugin runs too) through ctypes: options in, the per-vertex and per-scale
results out, the progress callback fed to a :class:`~meshlab_sharp.progress.Progress`.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import numpy as np

from . import _header, _kernels
from .io import Geometry
from .progress import Progress

MAX_SCALES = _header.integer("MAX_SCALES")
_ENOMEM, _EINPUT = _header.integer("ENOMEM"), _header.integer("EINPUT")
_COUNTS = _header.integer("DETECTION_COUNTS")
_INPUT, _CLEAN = _header.integer("COUNT_INPUT"), _header.integer("COUNT_CLEAN")
_SCALES, _MESH = _header.integer("COUNT_SCALES"), _header.integer("COUNT_MESH")
_TIMINGS = _header.integer("COUNT_TIMINGS")
#: The largest scale a C int holds.
_INT_MAX = 2**31 - 1
_ERROR_BYTES = 512
#: The buffers of the error message and of a stage's name: their types made once (a type
#: made per call, as ``create_string_buffer`` makes it, is left in a reference cycle).
_ERROR_BUFFER = ctypes.c_char * _ERROR_BYTES
_NAME_BUFFER = ctypes.c_char * 64

#: The library's stage names that the report spells as the Python-driven path does.
_STAGE_NAMES = {"cleaning": "clean"}

#: int (*ms_progress_fn)(int percent, const char *message, void *ctx)
_PROGRESS = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_void_p)


class _Options(ctypes.Structure):
    """ms_detect_options."""

    _fields_ = [
        ("mode", ctypes.c_int),
        ("weighting", ctypes.c_int),
        ("as_points", ctypes.c_int),
        ("threads", ctypes.c_int),
        ("n_knn_scales", ctypes.c_int),
        ("knn_scales", ctypes.c_int * MAX_SCALES),
        ("n_ring_scales", ctypes.c_int),
        ("ring_scales", ctypes.c_int * MAX_SCALES),
        ("details", ctypes.c_int),
    ]


@dataclass
class NativeDetection:
    """What ``ms_detect`` returned: per input vertex ``mask``, ``strength`` and ``kept``;
    per scale used ``scales``, ``thresholds`` and ``candidate_counts``; ``n_clean``,
    ``mesh`` (processed as a mesh) and the seconds of each stage in order; when asked
    for, per scale and input vertex the ``distances`` (s, n) the thresholds split and the
    ``normals`` (s, n, 3) (NaN where a vertex took no part), else None."""

    mask: np.ndarray
    strength: np.ndarray
    kept: np.ndarray
    scales: tuple[int, ...]
    thresholds: np.ndarray
    candidate_counts: np.ndarray
    n_clean: int
    mesh: bool
    timings: dict[str, float]
    distances: np.ndarray | None = None
    normals: np.ndarray | None = None


def available() -> bool:
    """True when the compiled library (with ``ms_detect``) is loaded."""
    return _kernels.available()


def detect(
    geometry: Geometry,
    *,
    is_mesh: bool,
    scales: tuple[int, ...],
    mode: str,
    weighting: str,
    workers: int,
    bar: Progress,
    details: bool = False,
) -> NativeDetection | None:
    """Run ``ms_detect`` on ``geometry`` (its faces unless ``is_mesh`` is False) at
    ``scales`` (the kNN sizes or the rings, as ``is_mesh`` says), on ``workers`` threads
    (<= 0: every core), stepping ``bar`` as the library reports progress; with
    ``details`` the per-scale distances and normals too.

    Returns None when the library refuses the input as unusable (too few distinct
    points, every face of zero area, a scale beyond a C int): the caller's own path then
    raises its error message. Raises MemoryError out of memory."""
    if scales[-1] > _INT_MAX:
        return None
    lib = _kernels._LIB
    assert lib is not None
    options = _Options()
    lib.ms_detect_defaults(ctypes.byref(options))
    options.mode = 0 if mode == "paper" else 1
    options.weighting = 0 if weighting == "gaussian" else 1
    options.as_points = 0
    options.threads = max(0, int(workers))
    options.details = int(details)
    if is_mesh:
        options.n_ring_scales = len(scales)
        options.ring_scales[: len(scales)] = scales
    else:
        options.n_knn_scales = len(scales)
        options.knn_scales[: len(scales)] = scales
    vertices = np.ascontiguousarray(geometry.vertices, dtype=np.float64)
    faces = None
    if is_mesh and geometry.faces is not None:
        faces = np.ascontiguousarray(geometry.faces, dtype=np.int64)

    # An exception raised in the callback (KeyboardInterrupt from a signal handler, a
    # failing bar) would end in ctypes, printed and dropped: kept, and raised once
    # ms_detect returns.
    raised: list[BaseException] = []

    def report(percent: int, message: bytes, _ctx: int | None) -> int:
        # called by this thread only, inside ms_detect (the library's contract)
        if raised:
            return 0
        try:
            done = round(bar.total * percent / 100)
            if done > bar.done:
                stage = message.decode(errors="replace").removeprefix("Sharp features: ")
                bar.step(stage.rsplit(" ", 1)[0], done - bar.done)  # less its percentage
        except BaseException as exc:
            raised.append(exc)
        return 0

    callback = _PROGRESS(report)
    handle = ctypes.c_void_p()
    error = _ERROR_BUFFER()
    status = lib.ms_detect(
        vertices.ctypes.data,
        len(vertices),
        None if faces is None else faces.ctypes.data,
        0 if faces is None else len(faces),
        ctypes.byref(options),
        callback,
        None,
        ctypes.byref(handle),
        error,
        _ERROR_BYTES,
    )
    if raised:
        if status == 0:
            lib.ms_detection_free(handle)
        raise raised[0]
    if status == _EINPUT:
        return None
    if status == _ENOMEM:
        raise MemoryError(error.value.decode(errors="replace"))
    if status != 0:
        raise RuntimeError(f"ms_detect failed: {error.value.decode(errors='replace')}")
    try:
        return _results(lib, handle)
    finally:
        lib.ms_detection_free(handle)


def _results(lib: ctypes.CDLL, handle: ctypes.c_void_p) -> NativeDetection:
    """Copy a detection's results out of the library."""
    counts = np.zeros(_COUNTS, dtype=np.int64)
    lib.ms_detection_counts(handle, counts.ctypes.data)
    n, s = int(counts[_INPUT]), int(counts[_SCALES])
    strength = np.empty(n, dtype=np.float64)
    mask = np.empty(n, dtype=np.bool_)
    kept = np.empty(n, dtype=np.bool_)
    lib.ms_detection_vertices(handle, strength.ctypes.data, mask.ctypes.data, kept.ctypes.data)
    scales = np.empty(s, dtype=np.intc)
    thresholds = np.empty(s, dtype=np.float64)
    candidates = np.empty(s, dtype=np.int64)
    lib.ms_detection_scales(
        handle, scales.ctypes.data, thresholds.ctypes.data, candidates.ctypes.data
    )
    timings = {}
    name = _NAME_BUFFER()
    seconds = ctypes.c_double()
    for i in range(int(counts[_TIMINGS])):
        lib.ms_detection_timing(handle, i, name, len(name), ctypes.byref(seconds))
        stage = name.value.decode()
        timings[_STAGE_NAMES.get(stage, stage)] = seconds.value
    distances = normals = None
    if lib.ms_detection_details(handle, None, None):
        distances = np.empty((s, n), dtype=np.float64)
        normals = np.empty((s, n, 3), dtype=np.float64)
        lib.ms_detection_details(handle, distances.ctypes.data, normals.ctypes.data)
    return NativeDetection(
        mask=mask,
        strength=strength,
        kept=kept,
        scales=tuple(int(k) for k in scales),
        thresholds=thresholds,
        candidate_counts=candidates,
        n_clean=int(counts[_CLEAN]),
        mesh=bool(counts[_MESH]),
        timings=timings,
        distances=distances,
        normals=normals,
    )
