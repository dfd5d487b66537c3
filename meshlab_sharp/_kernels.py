"""The compiled fast path: a small C library (``_ckernels.c``) loaded with ctypes.

``pip install .`` (or ``pip install -e .``) builds it with the system's C compiler; no
Python headers are needed, only ``gcc``. Without it, or with the environment variable
``MESHLAB_SHARP_BACKEND=numpy``, every stage runs the numpy reference path, which gives
the same answers (see ``tests/test_equivalence.py``), only slower.

ctypes releases the GIL while a C function runs, so chunks of points go to a pool of
Python threads, one per core.
"""

from __future__ import annotations

import ctypes
import importlib.machinery
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Backends: "compiled" (the C kernels) and "numpy" (the reference implementation).
BACKENDS: tuple[str, ...] = ("compiled", "numpy")
#: Points per task handed to a thread.
CHUNK = 8192
#: Bits per axis of the fine Morton grid.
MORTON_BITS = 21

_c_void_p, _i64, _f64, _int = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double, ctypes.c_int
_SIGNATURES = {
    "ms_morton_codes": (None, [_c_void_p, _i64, _f64, _f64, _f64, _f64, _c_void_p]),
    "ms_level_counts": (None, [_c_void_p, _i64, _c_void_p]),
    "ms_build_cells": (None, [_c_void_p, _i64, _int, _c_void_p, _c_void_p, _c_void_p, _i64]),
    "ms_eigvecs": (None, [_c_void_p, _i64, _c_void_p]),
    "ms_cloud_pdis": (
        _int,
        [_c_void_p, _c_void_p, _c_void_p, _i64, _f64, _f64, _f64, _f64, _int]
        + [_c_void_p, _c_void_p, _c_void_p, _i64, _c_void_p, _int, _int, _i64, _i64]
        + [_c_void_p, _c_void_p, _c_void_p],
    ),
    "ms_adjacency": (None, [_c_void_p, _i64, _i64, _c_void_p, _c_void_p]),
    "ms_ring_pdis": (
        _int,
        [_c_void_p, _i64, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _int, _int, _i64, _i64]
        + [_c_void_p, _c_void_p, _c_void_p],
    ),
    "ms_face_average_normals": (None, [_c_void_p, _i64, _c_void_p, _i64, _f64, _c_void_p]),
    "ms_dedup": (_i64, [_c_void_p, _i64, _c_void_p, _i64, _c_void_p, _c_void_p]),
    "ms_face_double_areas": (None, [_c_void_p, _c_void_p, _i64, _c_void_p]),
}


def _find_library() -> Path | None:
    here = Path(__file__).parent
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        candidate = here / f"_ckernels{suffix}"
        if candidate.is_file():
            return candidate
    return None


def _load() -> ctypes.CDLL | None:
    path = _find_library()
    if path is None:
        return None
    try:
        lib = ctypes.CDLL(str(path))
    except OSError:
        return None
    for name, (restype, argtypes) in _SIGNATURES.items():
        fn = getattr(lib, name, None)
        if fn is None:
            return None
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


_LIB = _load()
_override: list[str] = []


def available() -> bool:
    """True when the compiled library was built and loads."""
    return _LIB is not None


def default_backend() -> str:
    """The backend used when none is named: ``MESHLAB_SHARP_BACKEND`` or a
    :func:`use_backend` block if set, else "compiled" when available, else "numpy".

    Raises ValueError when ``MESHLAB_SHARP_BACKEND`` names no backend."""
    if _override:
        return _override[-1]
    env = os.environ.get("MESHLAB_SHARP_BACKEND", "").strip().lower()
    if env and env not in BACKENDS:
        raise ValueError(
            f"MESHLAB_SHARP_BACKEND={env!r} is not a backend; choose from {', '.join(BACKENDS)}"
        )
    if env == "numpy":
        return env
    return "compiled" if available() else "numpy"


def resolve(backend: str | None) -> str:
    """The backend to run: ``backend`` if given (checked), else :func:`default_backend`."""
    if backend is None:
        return default_backend()
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; choose from {', '.join(BACKENDS)}")
    if backend == "compiled" and not available():
        raise RuntimeError(
            "the compiled kernels are not built: reinstall with 'pip install .' (needs gcc)"
        )
    return backend


@contextmanager
def use_backend(backend: str):
    """Run the enclosed code with ``backend`` as the default (tests, benchmarks)."""
    resolve(backend)
    _override.append(backend)
    try:
        yield
    finally:
        _override.pop()


def _ptr(a: np.ndarray | None) -> int | None:
    return None if a is None else a.ctypes.data


def _workers(workers: int) -> int:
    if workers is None or workers <= 0:
        return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)
    return int(workers)


def _run_chunks(n: int, workers: int, task: Callable[[int, int], int]) -> None:
    """task(begin, end) over [0, n) in chunks, on ``workers`` threads."""
    ranges = [(s, min(s + CHUNK, n)) for s in range(0, n, CHUNK)]
    w = _workers(workers)
    if w == 1 or len(ranges) == 1:
        codes = [task(a, b) for a, b in ranges]
    else:
        with ThreadPoolExecutor(max_workers=w) as pool:
            codes = list(pool.map(lambda r: task(*r), ranges))
    if any(c != 0 for c in codes):
        raise MemoryError("out of memory in a compiled kernel")


# ---------------------------------------------------------------------------- clouds


@dataclass
class Grid:
    """Points sorted along a Morton curve, bucketed in cubic cells for kNN queries.

    The points keep their cleaned index in ``orig``: ties are broken by it and every
    output is written in the cleaned order.
    """

    points: np.ndarray  # (n, 3) sorted
    orig: np.ndarray  # (n,) int64 cleaned index of each sorted point
    codes: np.ndarray  # (n,) uint64 sorted fine Morton codes
    origin: np.ndarray  # (3,)
    fine: float  # fine cell size
    level: int  # cells of 2**level fine cells
    hkeys: np.ndarray
    hstart: np.ndarray
    hend: np.ndarray

    @property
    def n(self) -> int:
        return len(self.points)


def build_grid(points: np.ndarray, k: int) -> Grid:
    """Sort ``points`` (n, 3) along a Morton curve and choose cells for k-NN queries."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    lo = points.min(axis=0)
    extent = float((points.max(axis=0) - lo).max())
    cells = float(2**MORTON_BITS - 1)
    fine = extent / cells * (1.0 + 1e-9) if extent > 0 else 1.0
    codes = np.empty(n, dtype=np.uint64)
    lib.ms_morton_codes(_ptr(points), n, *map(float, lo), 1.0 / fine, _ptr(codes))
    order = np.argsort(codes, kind="stable")
    codes = codes[order]
    sorted_points = points[order]
    counts = np.zeros(MORTON_BITS + 1, dtype=np.int64)
    lib.ms_level_counts(_ptr(codes), n, _ptr(counts))
    # Cells about as wide as the k-NN radius: on a surface about 0.4 k points a cell.
    target = max(2.0, 0.4 * k)
    per_cell = n / np.maximum(counts, 1)
    level = int(np.argmin(np.abs(np.log(per_cell / target))))
    size = 1 << int(np.ceil(np.log2(max(2 * counts[level], 2))))
    hkeys = np.full(size, np.iinfo(np.uint64).max, dtype=np.uint64)
    hstart = np.empty(size, dtype=np.int64)
    hend = np.empty(size, dtype=np.int64)
    lib.ms_build_cells(_ptr(codes), n, level, _ptr(hkeys), _ptr(hstart), _ptr(hend), size - 1)
    return Grid(
        sorted_points,
        order.astype(np.int64, copy=False),
        codes,
        lo,
        fine,
        level,
        hkeys,
        hstart,
        hend,
    )


def _cloud_call(
    grid: Grid,
    ks: np.ndarray,
    gaussian: bool,
    workers: int,
    out_pdis: np.ndarray | None,
    out_normals: np.ndarray | None,
    out_idx: np.ndarray | None,
) -> None:
    lib = _LIB
    assert lib is not None
    g = grid
    args = (
        _ptr(g.points), _ptr(g.orig), _ptr(g.codes), g.n, *map(float, g.origin), g.fine,
        g.level, _ptr(g.hkeys), _ptr(g.hstart), _ptr(g.hend), len(g.hkeys) - 1, _ptr(ks),
        len(ks), int(gaussian),
    )  # fmt: skip
    tail = (_ptr(out_pdis), _ptr(out_normals), _ptr(out_idx))
    _run_chunks(g.n, workers, lambda a, b: lib.ms_cloud_pdis(*args, a, b, *tail))


def cloud_knn(grid: Grid, k: int, workers: int = -1) -> np.ndarray:
    """The k nearest neighbours of every point (cleaned order), (n, k) int64, rows
    sorted by (squared distance, index)."""
    out = np.empty((grid.n, k), dtype=np.int64)
    _cloud_call(grid, np.array([k], dtype=np.int64), False, workers, None, None, out)
    return out


def cloud_projected_distances(
    grid: Grid,
    scales: Sequence[int],
    weighting: str = "gaussian",
    *,
    keep_normals: bool = False,
    workers: int = -1,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Projected distances (s, n) at every kNN scale (cleaned order), and the normals
    (s, n, 3) when ``keep_normals``; one neighbour search at the largest scale."""
    ks = np.ascontiguousarray(scales, dtype=np.int64)
    pdis = np.empty((len(ks), grid.n))
    normals = np.empty((len(ks), grid.n, 3)) if keep_normals else None
    _cloud_call(grid, ks, weighting == "gaussian", workers, pdis, normals, None)
    return pdis, normals


def cloud_knn_projected_distances(
    grid: Grid, scales: Sequence[int], weighting: str = "gaussian", workers: int = -1
) -> tuple[np.ndarray, np.ndarray]:
    """The k = max(scales) nearest neighbours (n, k) int64 and the projected distances
    (s, n) of every point (cleaned order) from one neighbour search."""
    ks = np.ascontiguousarray(scales, dtype=np.int64)
    idx = np.empty((grid.n, int(ks[-1])), dtype=np.int64)
    pdis = np.full((len(ks), grid.n), np.nan)
    _cloud_call(grid, ks, weighting == "gaussian", workers, pdis, None, idx)
    if grid.n and np.isnan(pdis[:, 0]).any():  # a library built before this function
        raise RuntimeError("the compiled kernels are out of date: rebuild (pip install -e .)")
    return idx, pdis


# ---------------------------------------------------------------------------- meshes


def adjacency(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """1-ring adjacency in CSR form (repeats allowed): indptr (n + 1,), indices (6 m,)."""
    lib = _LIB
    assert lib is not None
    if n >= 2**31:
        raise ValueError("the compiled ring kernel handles fewer than 2**31 vertices")
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    ptr = np.empty(n + 1, dtype=np.int64)
    idx = np.empty(6 * len(faces), dtype=np.int32)
    lib.ms_adjacency(_ptr(faces), len(faces), n, _ptr(ptr), _ptr(idx))
    return ptr, idx


def ring_projected_distances(
    points: np.ndarray,
    indptr: np.ndarray,
    indices: np.ndarray,
    rings: Sequence[int],
    normals: np.ndarray | None,
    weighting: str = "gaussian",
    *,
    keep_normals: bool = False,
    workers: int = -1,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Projected distances (s, n) at every ring, by breadth-first search; ``normals``
    (n, 3) fixed (zero rows: PCA of the ring) or None (PCA everywhere)."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    rs = np.ascontiguousarray(rings, dtype=np.int64)
    fixed = None if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
    pdis = np.empty((len(rs), n))
    out_normals = np.empty((len(rs), n, 3)) if keep_normals else None
    w = _workers(workers)
    stamps: dict[int, np.ndarray] = {}
    import threading

    def task(a: int, b: int) -> int:
        tid = threading.get_ident()
        stamp = stamps.get(tid)
        if stamp is None:
            stamp = stamps[tid] = np.full(n, -1, dtype=np.int32)
        return lib.ms_ring_pdis(
            _ptr(points), n, _ptr(indptr), _ptr(indices), _ptr(fixed), _ptr(rs), len(rs),
            int(weighting == "gaussian"), a, b, _ptr(stamp), _ptr(pdis), _ptr(out_normals),
        )  # fmt: skip

    _run_chunks(n, w, task)
    return pdis, out_normals


def face_average_normals(points: np.ndarray, faces: np.ndarray, zero: float) -> np.ndarray:
    """Face-average vertex normals, bit for bit as the numpy reference computes them."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    acc = np.zeros_like(points)
    lib.ms_face_average_normals(_ptr(points), len(points), _ptr(faces), len(faces), zero, _ptr(acc))
    return acc


def face_double_areas(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``|(p1 - p0) x (p2 - p0)|`` of every face, as vcg's DoubleArea computes it."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    out = np.empty(len(faces))
    lib.ms_face_double_areas(_ptr(points), _ptr(faces), len(faces), _ptr(out))
    return out


def merge_duplicates(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exactly equal points merged into their first occurrence.

    Returns
    -------
    to_input : (m,) int64
        Input index of each distinct point, increasing.
    from_input : (n,) int64
        Distinct index of each input point.
    """
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    size = 1 << int(np.ceil(np.log2(max(2 * n, 2))))
    table = np.full(size, -1, dtype=np.int64)
    from_input = np.empty(n, dtype=np.int64)
    to_input = np.empty(n, dtype=np.int64)
    m = lib.ms_dedup(_ptr(points), n, _ptr(table), size - 1, _ptr(from_input), _ptr(to_input))
    del table
    return to_input[:m].copy() if m < n else to_input, from_input


def smallest_eigenvectors(cov: np.ndarray) -> np.ndarray:
    """Unit eigenvector of the smallest eigenvalue of each symmetric (c, 3, 3) matrix."""
    lib = _LIB
    assert lib is not None
    c = np.ascontiguousarray(cov[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]], dtype=np.float64)
    out = np.empty((len(c), 3))
    lib.ms_eigvecs(_ptr(c), len(c), _ptr(out))
    return out
