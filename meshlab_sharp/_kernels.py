"""The compiled fast path: the native library (``native/``) loaded with ctypes.

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
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from . import _header
from .errors import InputError

#: Backends: "compiled" (the C kernels) and "numpy" (the reference implementation).
BACKENDS: tuple[str, ...] = ("compiled", "numpy")
#: Points per task handed to a thread.
CHUNK = _header.integer("CHUNK")
#: Most points in a leaf of the kd-tree.
KD_LEAF = _header.integer("KD_LEAF")
#: Levels of the kd-tree built before its subtrees (which are built on threads).
KD_TOP = _header.integer("KD_TOP")
#: Rows per chunk of :func:`ring_members`: their rings (a few hundred kilobytes of the
#: adjacency) stay in the cache from the search of their lengths to that of their members.
RING_CHUNK = 512

_c_void_p, _i64, _f64, _int = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double, ctypes.c_int
_SIGNATURES = {
    "ms_kdtree_build": (None, [_c_void_p, _i64, _int, _c_void_p, _c_void_p, _c_void_p]),
    "ms_kdtree_build_level": (
        None,
        [_c_void_p, _c_void_p, _i64, _int, _int, _i64, _i64, _c_void_p],
    ),
    "ms_kdtree_build_subtrees": (
        None,
        [_c_void_p, _c_void_p, _i64, _int, _i64, _i64, _c_void_p],
    ),
    "ms_eigvecs": (None, [_c_void_p, _i64, _c_void_p]),
    "ms_cloud_pdis": (
        _int,
        [_c_void_p, _c_void_p, _i64, _c_void_p, _int, _c_void_p, _int, _int, _i64, _i64]
        + [_c_void_p],
    ),
    "ms_knn_rows": (
        _int,
        [_c_void_p, _c_void_p, _i64, _c_void_p, _int, _c_void_p, _i64, _i64, _i64, _c_void_p],
    ),
    "ms_scatter_rows": (None, [_c_void_p, _c_void_p, _i64, _i64, _i64, _c_void_p]),
    "ms_isolated": (
        None,
        [_c_void_p] * 6 + [ctypes.c_double, _i64, _i64, _c_void_p],
    ),
    "ms_isolated_tree": (
        None,
        [_c_void_p] * 7 + [ctypes.c_double, _i64, _i64, _c_void_p],
    ),
    "ms_sheet_mask": (
        _int,
        [_c_void_p, _c_void_p, _i64, _c_void_p, _c_void_p, _i64, _i64, _c_void_p],
    ),
    "ms_bit_histogram": (_i64, [_c_void_p, _i64, _i64, _c_void_p]),
    "ms_local_scale_csr": (
        _int,
        [_c_void_p, _c_void_p, _c_void_p, _int, _i64, _i64, _c_void_p, _c_void_p],
    ),
    "ms_adjacency": (_int, [_c_void_p, _i64, _i64, _c_void_p, _c_void_p]),
    "ms_scattered": (_int, [_c_void_p, _c_void_p, _i64]),
    "ms_scattered_faces": (_int, [_c_void_p, _i64, _c_void_p, _i64]),
    "ms_bfs_renumber": (
        None,
        [_c_void_p, _c_void_p, _i64, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p]
        + [_c_void_p, _c_void_p, _c_void_p],
    ),
    "ms_shifted_lists": (None, [_c_void_p, _c_void_p, _i64, _i64, _i64, _c_void_p]),
    "ms_ring_pdis": (
        _int,
        [_c_void_p, _i64, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _int, _int, _i64, _i64]
        + [_c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p],
    ),
    "ms_ring_lists": (
        _int,
        [_c_void_p, _c_void_p, _c_void_p, _i64, _c_void_p, _int, _c_void_p, _c_void_p]
        + [_c_void_p, _c_void_p],
    ),
    "ms_line_directions": (
        _int,
        [_c_void_p, _c_void_p, _c_void_p, _c_void_p, _i64, _i64, _c_void_p],
    ),
    "ms_supported": (
        None,
        [_c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _f64, _i64, _c_void_p, _f64]
        + [_i64, _i64, _c_void_p],
    ),
    "ms_smoothed_ranking": (
        None,
        [_c_void_p, _c_void_p, _c_void_p, _i64, _i64, _i64, _c_void_p],
    ),
    "ms_thin": (
        None,
        [_c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _f64, _f64, _c_void_p]
        + [_i64, _i64, _c_void_p],
    ),
    "ms_line_test": (
        _int,
        [_c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p]
        + [_i64, _i64, _c_void_p],
    ),
    "ms_acute_tips": (
        None,
        [_c_void_p, _c_void_p, _c_void_p, _c_void_p, _i64, _i64, _c_void_p],
    ),
    "ms_face_average_normals": (_i64, [_c_void_p, _i64, _c_void_p, _i64, _f64, _c_void_p]),
    "ms_face_average_normals_at": (
        _i64,
        [_c_void_p, _i64, _c_void_p, _i64, _c_void_p, _f64, _c_void_p],
    ),
    "ms_face_windings": (_i64, [_c_void_p, _i64, _i64, _c_void_p]),
    "ms_face_windings_at": (_i64, [_c_void_p, _i64, _i64, _c_void_p, _c_void_p, _c_void_p]),
    "ms_dedup": (_i64, [_c_void_p, _i64, _c_void_p, _i64, _c_void_p, _c_void_p, _c_void_p]),
    "ms_keep_faces": (_i64, [_c_void_p, _c_void_p, _i64, _c_void_p, _c_void_p, _c_void_p]),
    "ms_extent": (None, [_c_void_p, _i64, _c_void_p]),
    "ms_noise_floor": (_f64, [_c_void_p]),
    "ms_scale_vote": (
        _f64,
        [_c_void_p, _i64, _int, _f64, _int, _f64, _c_void_p, _c_void_p, _c_void_p],
    ),
    "ms_noise_factor": (_f64, [_f64]),
    "ms_scale_growth": (_f64, [_f64, _i64, _int]),
    "ms_grown_scale": (_int, [_int, _f64]),
    "ms_thin_knn": (_int, [_f64]),
    "ms_quiet_cloud": (_int, [_int, _f64]),
    "ms_otsu_splits": (_int, [_int, _f64]),
    "ms_scale_floor": (_f64, [_c_void_p, _int, _int, _f64]),
    "ms_thin_cone": (_f64, [_int, _f64]),
    "ms_thin_side": (_f64, [_int, _f64]),
    "ms_ranking_smoothed": (_int, [_int, _f64]),
    "ms_support_free_score": (_int, [_int, _f64, _c_void_p]),
    "ms_robust_plan": (_int, [_f64, _i64, _c_void_p, _int, _int, _c_void_p]),
    "ms_plan_thresholds": (None, [_c_void_p, _c_void_p, _c_void_p]),
    "ms_flat_span": (_f64, [_c_void_p]),
    "ms_stage_histograms": (
        None,
        [_c_void_p, _i64, _i64, _int, _i64, _i64, _c_void_p, _c_void_p, _f64, _c_void_p],
    ),
    "ms_stage_threshold": (_f64, [_c_void_p, _int, _f64]),
    "ms_stage_decide": (
        None,
        [_c_void_p, _i64, _i64, _int, _i64, _i64, _c_void_p, _c_void_p, _f64, _c_void_p]
        + [_c_void_p, _c_void_p, _c_void_p, _c_void_p],
    ),
    "ms_stage_acute_tests": (_i64, [_c_void_p, _c_void_p, _i64, _i64, _int, _f64, _c_void_p]),
    "ms_stage_curved": (_i64, [_c_void_p, _c_void_p, _i64, _i64, _int, _int, _c_void_p]),
    "ms_stage_isolated": (None, [_c_void_p] * 7 + [_f64, _i64, _i64, _c_void_p]),
    "ms_two_face_edges": (_i64, [_c_void_p, _c_void_p, _i64, _i64, _c_void_p, _c_void_p]),
    "ms_vertex_faces": (_int, [_c_void_p, _i64, _i64, _c_void_p, _c_void_p]),
    "ms_crease_dots": (
        _i64,
        [_c_void_p, _c_void_p, _i64, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _c_void_p],
    ),
    "ms_crease_mask": (
        None,
        [_c_void_p, _c_void_p, _i64, _c_void_p, _c_void_p, _c_void_p, _c_void_p, _f64, _c_void_p],
    ),
    # the whole detection (meshlab_sharp._detect_native)
    "ms_detect_defaults": (None, [_c_void_p]),
    "ms_detect": (
        _int,
        [_c_void_p, _i64, _c_void_p, _i64, _c_void_p, _c_void_p, _c_void_p, _c_void_p]
        + [_c_void_p, _int],
    ),
    "ms_detection_counts": (None, [_c_void_p, _c_void_p]),
    "ms_detection_vertices": (None, [_c_void_p, _c_void_p, _c_void_p, _c_void_p]),
    "ms_detection_scales": (None, [_c_void_p, _c_void_p, _c_void_p, _c_void_p]),
    "ms_detection_timing": (None, [_c_void_p, _int, _c_void_p, _int, _c_void_p]),
    "ms_detection_details": (_int, [_c_void_p, _c_void_p, _c_void_p]),
    "ms_detection_free": (None, [_c_void_p]),
    "ms_parse_scales": (_int, [_c_void_p, _int, _c_void_p, _int, _c_void_p, _int]),
    "ms_format_scales": (_int, [_c_void_p, _int, _c_void_p, _int]),
}


def load_library(stem: str, signatures: dict[str, tuple[Any, list[Any]]]) -> ctypes.CDLL | None:
    """The package's compiled library ``<stem><extension suffix>`` with the functions of
    ``signatures`` (name -> (return type, argument types)) declared; None when it is not
    built, does not load, or lacks one of them."""
    here = Path(__file__).parent
    paths = (here / f"{stem}{suffix}" for suffix in importlib.machinery.EXTENSION_SUFFIXES)
    path = next((p for p in paths if p.is_file()), None)
    if path is None:
        return None
    try:
        lib = ctypes.CDLL(str(path))
    except OSError:
        return None
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name, None)
        if fn is None:
            return None
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


_LIB = load_library("_ckernels", _SIGNATURES)


def available() -> bool:
    """True when the compiled library was built and loads."""
    return _LIB is not None


def default_backend() -> str:
    """The backend used when none is named: ``MESHLAB_SHARP_BACKEND`` if set, else
    "compiled" when available, else "numpy". Every call names its backend or takes this
    default: no state of the process chooses it.

    Raises ValueError when ``MESHLAB_SHARP_BACKEND`` names no backend."""
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


def _ptr(a: np.ndarray | None) -> int | None:
    return None if a is None else a.ctypes.data


def _workers(workers: int) -> int:
    if workers is None or workers <= 0:
        return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)
    return int(workers)


def _thread_scratch(n: int, dtype: type) -> Callable[[], np.ndarray]:
    """A getter of the calling thread's own (n,) scratch array, all -1 when first made
    (the ring kernels' visit marks, which a thread reuses across its chunks)."""
    arrays: dict[int, np.ndarray] = {}

    def get() -> np.ndarray:
        tid = threading.get_ident()
        if tid not in arrays:
            arrays[tid] = np.full(n, -1, dtype=dtype)
        return arrays[tid]

    return get


class _Pool:
    """The process's worker threads, started at the first parallel call and reused by
    every later one (an executor per call started two threads each time: about 40 per
    ``detect``); a forked child starts its own. Its tasks never wait on the pool: a task
    that ran :func:`_run_chunks` there would wait for its own chunks queued behind it, and a
    few such tasks at once fill every thread and deadlock (tried and seen: kd-tree
    builds abandoned by cleaning, in a run of fuzzed detects). Work that calls
    :func:`_run_chunks` beside the caller runs on a thread of its own
    (:func:`meshlab_sharp.pipeline._clean_beside_tree`)."""

    lock = threading.Lock()
    executor: ThreadPoolExecutor | None = None

    @classmethod
    def get(cls) -> ThreadPoolExecutor:
        with cls.lock:
            if cls.executor is None:
                cls.executor = ThreadPoolExecutor(thread_name_prefix="meshlab_sharp")
            return cls.executor

    @classmethod
    def forget(cls) -> None:
        """In a forked child: the parent's threads are not there."""
        cls.lock = threading.Lock()
        cls.executor = None


os.register_at_fork(after_in_child=_Pool.forget)


def _run_chunks(
    n: int,
    workers: int,
    task: Callable[[int, int], int],
    chunk: int = CHUNK,
    spans: Sequence[tuple[int, int]] | None = None,
) -> None:
    """task(begin, end) over [0, n) (or over each ``[begin, end)`` of ``spans``) in
    chunks of ``chunk``, on ``workers`` threads: the calling thread and ``workers - 1``
    of the process's pool (:class:`_Pool`), each taking the next chunk when it is
    done with one."""
    spans = [(0, n)] if spans is None else spans
    ranges = [(s, min(s + chunk, e)) for a, e in spans for s in range(a, e, chunk)]
    w = min(_workers(workers), len(ranges))
    codes: list[int] = []
    todo = iter(ranges)  # shared: next() on a list iterator is atomic under the GIL

    def run() -> None:
        for a, b in todo:
            codes.append(task(a, b))

    if w <= 1:
        run()
    else:
        pool = _Pool.get()
        others = [pool.submit(run) for _ in range(w - 1)]
        try:
            run()
        finally:
            for _ in todo:  # on an error here, the other threads stop after their chunk
                pass
            for f in others:
                f.result()
    if any(c != 0 for c in codes):
        raise MemoryError("out of memory in a compiled kernel")


# ---------------------------------------------------------------------------- clouds


@dataclass
class KdTree:
    """A balanced kd-tree of a cloud for exact k-NN queries (built in C).

    Stored implicitly: node 0 is the root, the children of node ``t`` are ``2t + 1``
    and ``2t + 2``, every leaf is at depth ``depth``. The points are kept in tree order
    with their cleaned index in ``orig``: ties are broken by it and every output is
    written in the cleaned order. Median splits keep the tree balanced whatever the
    spatial distribution (far outliers, distant clusters, points on a line).
    """

    points: np.ndarray  # (n, 3) in tree order
    orig: np.ndarray  # (n,) int64 cleaned index of each point in tree order
    boxes: np.ndarray  # (2**(depth + 1) - 1, 6) tight box of each node: lo xyz, hi xyz
    depth: int

    @property
    def n(self) -> int:
        return len(self.points)


class TreeStopped(Exception):
    """A kd-tree build stopped by its ``stop`` (:func:`build_tree`)."""


def build_tree(
    points: np.ndarray, workers: int = -1, stop: Callable[[], bool] | None = None
) -> KdTree:
    """The kd-tree of ``points`` (n, 3), leaves of at most :data:`KD_LEAF` points: its
    top :data:`KD_TOP` levels one after the other, the nodes of each on ``workers``
    threads, then the subtrees below them (the same tree as ``ms_kdtree_build``).
    Raises :class:`TreeStopped` when ``stop()`` turned true: the build stops before
    its next node (a speculative build, :func:`meshlab_sharp.pipeline._clean_beside_tree`)."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    depth = max(0, int(np.ceil(np.log2(max(n, 1) / KD_LEAF))))
    tree_points = points.copy()
    orig = np.arange(n, dtype=np.int64)
    boxes = np.empty((2 ** (depth + 1) - 1, 6))
    tp, to, tb = _ptr(tree_points), _ptr(orig), _ptr(boxes)
    top = min(depth, KD_TOP)
    stopped = stop if stop is not None else lambda: False
    for level in range(top):

        def split(a: int, b: int, level: int = level) -> int:
            if not stopped():
                lib.ms_kdtree_build_level(tp, to, n, depth, level, a, b, tb)
            return 0

        _run_chunks(2**level, workers, split, chunk=1)

    def task(a: int, b: int) -> int:
        if not stopped():
            lib.ms_kdtree_build_subtrees(tp, to, n, depth, a, b, tb)
        return 0

    _run_chunks(2**top, workers, task, chunk=1)
    if stopped():
        raise TreeStopped
    return KdTree(tree_points, orig, boxes, depth)


class _CloudOut(ctypes.Structure):
    """What one pass of ``ms_cloud_pdis`` writes (``cloud_out_t``; NULL: nothing)."""

    _fields_ = [
        ("pdis", _c_void_p),
        ("normals", _c_void_p),
        ("idx", _c_void_p),
        ("relative", _c_void_p),
        ("score", _c_void_p),
        ("noise", _c_void_p),
        ("noise_k", _i64),
        ("near", _c_void_p),
        ("kth_d2", _c_void_p),
        ("kth_idx", _c_void_p),
        ("nth_d2", _c_void_p),
        ("ref_d2", _c_void_p),
        ("isolated_nth", _i64),
        ("isolated_ref", _i64),
        ("sheet_gap", ctypes.c_double),
        ("sheet_min", _i64),
        ("sheet_own", ctypes.c_double),
        ("sheet_column", ctypes.c_double),
        ("sheet_column_gap", ctypes.c_double),
        ("sheet_far_span", ctypes.c_double),
        ("sheet_trim", ctypes.c_double),
        ("sheet_trim_cos", ctypes.c_double),
        ("tree_order", _i64),
    ]


#: The fields of :class:`_CloudOut` that are numbers, not arrays.
_NUMBERS = (
    "noise_k",
    "isolated_nth",
    "isolated_ref",
    "sheet_gap",
    "sheet_min",
    "sheet_own",
    "sheet_column",
    "sheet_column_gap",
    "sheet_far_span",
    "sheet_trim",
    "sheet_trim_cos",
)
#: The arrays of :class:`_CloudOut` with a leading scale axis, (s, n, ...).
_PER_SCALE = ("pdis", "normals", "relative")
#: The arrays of :class:`_CloudOut` that make a :class:`CloudStats`.
_STATS = ("near", "kth_d2", "kth_idx", "nth_d2", "ref_d2", "noise")


def _to_cleaned_order(
    rows: np.ndarray, orig: np.ndarray, scratch: np.ndarray, workers: int = -1
) -> None:
    """``rows`` (n, ...), C-contiguous, written at tree positions, moved in place to
    cleaned order (``orig``: the cleaned index of each position) on ``workers``
    threads; ``scratch``: bytes, at least ``rows.nbytes`` of them."""
    lib = _LIB
    assert lib is not None and rows.flags.c_contiguous
    copy = scratch[: rows.nbytes].view(rows.dtype).reshape(rows.shape)
    np.copyto(copy, rows)
    n = len(rows)
    args = (_ptr(orig), _ptr(copy), rows.nbytes // n if n else 0)
    w = _workers(workers)

    def task(a: int, b: int) -> int:
        lib.ms_scatter_rows(*args, a, b, _ptr(rows))
        return 0

    _run_chunks(n, w, task, chunk=max(CHUNK, -(-n // w)))


def to_cleaned_order(arrays: Sequence[np.ndarray], orig: np.ndarray, workers: int = -1) -> None:
    """Each of ``arrays`` (n, ...), C-contiguous, written at tree positions, moved in
    place to cleaned order (``orig`` (n,) int64: the cleaned index of each position), one
    scratch array for all of them."""
    scratch = np.empty(max((a.nbytes for a in arrays), default=0), np.uint8)
    for a in arrays:
        _to_cleaned_order(a, orig, scratch, workers)


def _tree_spans(tree: KdTree, rows: np.ndarray) -> list[tuple[int, int]]:
    """Ranges ``[begin, end)`` of tree positions that hold the points ``rows`` (cleaned
    indices), runs less than a leaf apart merged (a few other points come with them)."""
    where = np.empty(tree.n, dtype=np.int64)
    where[tree.orig] = np.arange(tree.n, dtype=np.int64)
    at = np.sort(where[np.asarray(rows, dtype=np.int64)])
    if len(at) == 0:
        return []
    cut = np.flatnonzero(np.diff(at) > KD_LEAF) + 1
    starts, ends = np.r_[0, cut], np.r_[cut, len(at)]
    return [(int(at[a]), int(at[b - 1]) + 1) for a, b in zip(starts, ends, strict=True)]


def _cloud_call(
    tree: KdTree,
    ks: np.ndarray,
    gaussian: bool,
    workers: int,
    rows: np.ndarray | None = None,
    in_tree_order: tuple[str, ...] = (),
    **out: np.ndarray | int | None,
) -> None:
    """One pass of ``ms_cloud_pdis`` over the tree's points (only the points ``rows``,
    cleaned indices, and a few near them in the tree, when given) at the scales ``ks``;
    ``out`` names the arrays (fields of :class:`_CloudOut`) to fill, and the numbers
    ``noise_k`` and ``sheet_*``. Without the kNN table
    (``idx``) the pass writes its rows in tree order, moved to cleaned order after,
    except the arrays named in ``in_tree_order`` (``near`` and ``kth_idx`` among them:
    their values are tree positions too)."""
    lib = _LIB
    assert lib is not None
    t = tree
    arrays = {
        name: value
        for name, value in out.items()
        if value is not None and name not in _NUMBERS and name != "idx"
    }
    tree_order = out.get("idx") is None
    fields = {
        name: value if name in _NUMBERS else _ptr(value)  # type: ignore[arg-type]
        for name, value in out.items()
        if value is not None
    }
    # 2: near and kth_idx as tree positions too, for isolated_from_stats in tree order
    spec = _CloudOut(**fields, tree_order=tree_order * (2 if "near" in in_tree_order else 1))
    args = (_ptr(t.points), _ptr(t.orig), t.n, _ptr(t.boxes), t.depth, _ptr(ks), len(ks))
    _run_chunks(
        t.n,
        workers,
        lambda a, b: lib.ms_cloud_pdis(*args, int(gaussian), a, b, ctypes.byref(spec)),
        spans=None if rows is None else _tree_spans(t, rows),
    )
    if not tree_order:
        return
    to_cleaned_order(
        [
            r
            for name, a in arrays.items()
            if name not in in_tree_order
            for r in (a if name in _PER_SCALE else (a,))
        ],
        t.orig,
        workers,
    )


def cloud_knn(
    tree: KdTree, k: int, workers: int = -1, rows: np.ndarray | None = None
) -> np.ndarray:
    """The k nearest neighbours of every point (cleaned order), (n, k) int64, rows
    sorted by (squared distance, index); with ``rows`` (cleaned indices) only those
    points' (and a few others'), the rest undefined."""
    out = np.empty((tree.n, k), dtype=np.int64)
    _cloud_call(tree, np.array([k], dtype=np.int64), False, workers, rows, idx=out)
    return out


def cloud_knn_rows(tree: KdTree, rows: np.ndarray, k: int, workers: int = -1) -> np.ndarray:
    """The rows ``rows`` (r,) of :func:`cloud_knn`'s table, (r, k) int64 (for a few
    rows: the table of every point is not built), searched in tree order
    (:func:`_knn_at`)."""
    t = tree
    where = np.empty(t.n, dtype=np.int64)
    where[t.orig] = np.arange(t.n, dtype=np.int64)
    pos = where[np.asarray(rows, dtype=np.int64)]
    del where
    order = np.argsort(pos, kind="stable")
    found = _knn_at(tree, np.ascontiguousarray(pos[order]), k, workers)
    out = np.empty_like(found)
    out[order] = found
    return out


def cloud_knn_of_mask(
    tree: KdTree, mask: np.ndarray, k: int, workers: int = -1
) -> tuple[np.ndarray, np.ndarray]:
    """The points of ``mask`` (n,) bool (cleaned order) in tree order, their cleaned
    indices (r,) int64, and the k nearest of each, (r, k) int64 (:func:`cloud_knn`'s
    rows): :func:`cloud_knn_rows` without the inverse of the tree's order."""
    pos = np.flatnonzero(np.asarray(mask, dtype=bool)[tree.orig])
    return tree.orig[pos], _knn_at(tree, pos, k, workers)


def _knn_at(tree: KdTree, pos: np.ndarray, k: int, workers: int) -> np.ndarray:
    """The k nearest (cleaned indices, (r, k) int64) of the points at the tree positions
    ``pos`` (r,) int64, increasing: searched in tree order as the pass searches them (the
    rows of one leaf share its block of nearby points)."""
    lib = _LIB
    assert lib is not None
    t = tree
    pos = np.ascontiguousarray(pos, dtype=np.int64)
    found = np.empty((len(pos), k), dtype=np.int64)
    args = (_ptr(t.points), _ptr(t.orig), t.n, _ptr(t.boxes), t.depth, _ptr(pos), k)
    _run_chunks(len(pos), workers, lambda a, b: lib.ms_knn_rows(*args, a, b, _ptr(found)))
    return found


@dataclass
class CloudStats:
    """Per point (cleaned order) what robust mode's set-up reads from the kNN lists at
    the largest scale ``k``, without the (n, k) table. With ``tree``, per position of
    that kd-tree instead, and ``near`` and ``kth_idx`` tree positions: what reads them
    (:func:`isolated_from_stats`, a median of ``noise``) needs no cleaned order, and
    reads near each point's own row."""

    # int32: n < 2**31 (cloud_projected_distances checks), 8 bytes a point less
    near: np.ndarray  # (n,) int32 nearest other point (column 1 of the kNN table)
    kth_d2: np.ndarray  # (n,) float64 squared distance of the k-th neighbour
    kth_idx: np.ndarray  # (n,) int32 its index
    nth_d2: np.ndarray  # (n,) float64 squared distance of column min(ISOLATED_NTH, k - 1)
    ref_d2: np.ndarray  # (n,) float64 squared distance of column min(ISOLATED_REF, k - 1)
    noise: np.ndarray  # (n,) float64 noise ratio over the noise_k nearest
    tree: KdTree | None = None  # the kd-tree whose order the rows follow, or None


def isolated_from_stats(
    points: np.ndarray, stats: CloudStats, spread: float, workers: int = -1
) -> np.ndarray:
    """:func:`meshlab_sharp.reference.robust.isolated_points` from a pass's :class:`CloudStats` at
    ``k_max`` over ``points`` (n, 3) (no kNN table): ``i`` is isolated when ``(|p_i -
    p_j|^2, i)``, ``j = near[i]``, comes after ``j``'s k_max-th neighbour in the lists'
    order (squared distance, then index), or when ``nth_d2[i] > spread**2 *
    ref_d2[kth_idx[i]]``. (n,) bool, cleaned order; from statistics in
    tree order (``stats.tree``) found per tree position, moved only when some point is
    isolated."""
    lib = _LIB
    assert lib is not None
    tree = stats.tree
    out = np.empty(len(points), dtype=np.bool_)
    found = (_ptr(stats.near), _ptr(stats.kth_d2), _ptr(stats.kth_idx))
    found += (_ptr(stats.nth_d2), _ptr(stats.ref_d2), ctypes.c_double(spread))
    if tree is None:
        points = np.ascontiguousarray(points, dtype=np.float64)
        args = (_ptr(points), *found)
        isolated = lib.ms_isolated
    else:
        args = (_ptr(tree.points), _ptr(tree.orig), *found)
        isolated = lib.ms_isolated_tree

    def task(a: int, b: int) -> int:
        isolated(*args, a, b, _ptr(out))
        return 0

    _run_chunks(len(points), workers, task)
    if tree is None or not out.any():
        return out
    cleaned = np.empty_like(out)
    cleaned[tree.orig] = out
    return cleaned


def lower_median(values: np.ndarray, workers: int = -1) -> float | None:
    """The lower median of ``values`` (n,) float64, n > 0, the value ``np.partition``
    puts at ``(n - 1) // 2`` (NaN last), without reordering ``values``: a histogram of
    the values (+0.0 apart, the others by the top 16 bits of their bit patterns, bins in
    the values' order) on ``workers`` threads (``ms_bit_histogram``), then a selection
    among the values of the one bin that holds it (none when it is +0.0's, as on a
    cloud without noise). None when some value is negative or -0.0 (their bits do not
    sort)."""
    lib = _LIB
    assert lib is not None
    values = np.ascontiguousarray(values, dtype=np.float64)
    n = len(values)
    chunk = max(CHUNK, -(-n // _workers(workers)))
    counts = np.zeros((-(-n // chunk), (1 << 15) + 1), dtype=np.int64)
    negative = np.zeros(len(counts), dtype=np.int64)

    def task(a: int, b: int) -> int:
        negative[a // chunk] = lib.ms_bit_histogram(_ptr(values), a, b, _ptr(counts[a // chunk]))
        return 0

    _run_chunks(n, workers, task, chunk=chunk)
    if negative.any():
        return None
    total = np.cumsum(counts.sum(axis=0))
    at = (n - 1) // 2
    top = int(np.searchsorted(total, at, side="right"))  # the bin of rank `at`
    if top == 0:
        return 0.0
    bits = values.view(np.uint64)
    members = values[((bits >> np.uint64(48)) == top - 1) & (bits != 0)]
    rank = at - int(total[top - 1])
    members.partition(rank)
    return float(members[rank])


@dataclass
class ScalePass:
    """What one pass over the points computed at every scale (cleaned order).

    Robust mode (``relative``) gets, instead of the projected distances, what
    :class:`meshlab_sharp.reference.detect.RelativeRule` computes from them, bit for bit: the
    relative distances and the thinning's score. With ``order``, the per-scale arrays
    (``pdis``, ``normals``, ``relative``) are in the kd-tree's order instead, row ``t``
    being the cleaned point ``order[t]`` (what needs no order, as a histogram, reads them
    as they are: :func:`to_cleaned_order` moves what is kept)."""

    pdis: np.ndarray | None  # (s, n) projected distances (paper mode)
    normals: np.ndarray | None  # (s, n, 3) their normals, when kept
    relative: np.ndarray | None = None  # (s, n) relative distances r (robust mode)
    score: np.ndarray | None = None  # (n,) RelativeRule's score after every scale
    stats: CloudStats | None = None
    order: np.ndarray | None = None  # (n,) int64 the kd-tree's ``orig``, or None


#: Robust mode's sheet filter parameters (:func:`meshlab_sharp.robust.sheet_parameters`):
#: gap, minimum, own, column, column gap, far span.
SheetParameters = tuple[float, int, float, float, float, float, float, float]


def cloud_projected_distances(
    tree: KdTree,
    scales: Sequence[int],
    weighting: str = "gaussian",
    *,
    keep_normals: bool = False,
    relative: bool = False,
    keep_pdis: bool | None = None,
    noise_k: int = 0,
    isolated: tuple[int, int] | None = None,
    sheet: SheetParameters | None = None,
    workers: int = -1,
    rows: np.ndarray | None = None,
    tree_order: bool = False,
) -> ScalePass:
    """Projected distances (s, n) at every kNN scale (cleaned order), the normals
    (s, n, 3) when ``keep_normals``; with ``relative`` robust mode's relative distances
    and score (:class:`ScalePass`), and then the projected distances only when
    ``keep_pdis`` (default: not ``relative``); with ``noise_k > 0`` the
    :class:`CloudStats` (noise ratio over the ``noise_k`` nearest; ``nth_d2`` and
    ``ref_d2`` at the columns ``isolated``, default the header's ``MS_ISOLATED_NTH`` and
    ``MS_ISOLATED_REF``). With ``sheet``
    (:func:`meshlab_sharp.robust.sheet_parameters`), robust mode's
    :func:`meshlab_sharp.reference.detect.sheet_mask` first: every
    neighbourhood (the scales', the noise's) is then the kept neighbours among its
    points. One neighbour search at the largest scale. With ``rows`` (cleaned indices),
    only those points' values are computed (and a few others'); the rest are undefined.
    With ``tree_order``, the per-scale arrays are left in the kd-tree's order
    (:attr:`ScalePass.order`), and so are the statistics (:attr:`CloudStats.tree`)."""
    ks = np.ascontiguousarray(scales, dtype=np.int64)
    n, s = tree.n, len(ks)
    if noise_k > 0 and n >= 2**31:  # before any (n,) array
        raise ValueError("the compiled pass's statistics handle fewer than 2**31 points")
    keep = not relative if keep_pdis is None else keep_pdis
    out = ScalePass(
        np.empty((s, n)) if keep else None, np.empty((s, n, 3)) if keep_normals else None
    )
    if relative:
        out.relative, out.score = np.empty((s, n)), np.empty(n)
    if noise_k > 0:
        i32 = np.int32
        out.stats = CloudStats(
            np.empty(n, i32), np.empty(n), np.empty(n, i32), np.empty(n), np.empty(n), np.empty(n)
        )
    fields: dict[str, np.ndarray | int | None] = {"pdis": out.pdis, "normals": out.normals}
    fields.update(relative=out.relative, score=out.score)
    if out.stats is not None:
        st = out.stats
        nth, ref = isolated or (_header.integer("ISOLATED_NTH"), _header.integer("ISOLATED_REF"))
        fields.update(
            near=st.near,
            kth_d2=st.kth_d2,
            kth_idx=st.kth_idx,
            nth_d2=st.nth_d2,
            ref_d2=st.ref_d2,
            isolated_nth=nth,
            isolated_ref=ref,
            noise=st.noise,
            noise_k=noise_k,
        )
    if sheet is not None:
        fields.update(_sheet_fields(sheet))
    kept = _PER_SCALE + _STATS if tree_order else ()
    _cloud_call(tree, ks, weighting == "gaussian", workers, rows, kept, **fields)
    if tree_order:
        out.order = tree.orig
        if out.stats is not None:
            out.stats.tree = tree
    return out


def _sheet_fields(sheet: SheetParameters) -> dict[str, float | int]:
    """The ``sheet_*`` fields of :class:`_CloudOut` from
    :func:`meshlab_sharp.robust.sheet_parameters`' tuple."""
    gap, minimum, own, column, column_gap, far_span, trim, trim_cos = sheet
    return {
        "sheet_gap": float(gap),
        "sheet_min": int(minimum),
        "sheet_own": float(own),
        "sheet_column": float(column),
        "sheet_column_gap": float(column_gap),
        "sheet_far_span": float(far_span),
        "sheet_trim": float(trim),
        "sheet_trim_cos": float(trim_cos),
    }


def sheet_mask(
    points: np.ndarray,
    indices: np.ndarray,
    normals: np.ndarray,
    parameters: SheetParameters,
    workers: int = -1,
) -> np.ndarray:
    """:func:`meshlab_sharp.reference.detect.sheet_mask`, bit for bit, by the filter of the compiled
    pass (``ms_sheet_mask``): ``points`` (n, 3), ``indices`` (n, k) the kNN lists (the
    point itself first), ``normals`` (n, 3), ``parameters`` as
    :func:`meshlab_sharp.robust.sheet_parameters` gives them (gap > 0). Returns the (n, k)
    bool mask of the kept neighbours."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    indices = np.ascontiguousarray(indices, dtype=np.int64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    n, k = indices.shape
    keep = np.empty((n, k), dtype=np.bool_)
    spec = _CloudOut(**_sheet_fields(parameters))
    args = (_ptr(points), _ptr(indices), k, _ptr(normals), ctypes.byref(spec))
    _run_chunks(n, workers, lambda a, b: lib.ms_sheet_mask(*args, a, b, _ptr(keep)))
    return keep


def local_scale_csr(
    points: np.ndarray, indptr: np.ndarray, indices: np.ndarray, workers: int = -1
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`meshlab_sharp.reference.detect.local_scale` over CSR lists, bit for bit."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    indptr = np.ascontiguousarray(indptr, dtype=np.int64)
    wide = np.asarray(indices).dtype.itemsize > 4
    indices = np.ascontiguousarray(indices, dtype=np.int64 if wide else np.int32)
    n = len(indptr) - 1
    ell, off = np.empty(n), np.empty(n)
    args = (_ptr(points), _ptr(indptr), _ptr(indices), int(wide))
    _run_chunks(n, workers, lambda a, b: lib.ms_local_scale_csr(*args, a, b, _ptr(ell), _ptr(off)))
    return ell, off


def cloud_knn_projected_distances(
    tree: KdTree,
    scales: Sequence[int],
    weighting: str = "gaussian",
    workers: int = -1,
    rows: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The k = max(scales) nearest neighbours (n, k) int64 and the projected distances
    (s, n) of every point (cleaned order) from one neighbour search; with ``rows``
    (cleaned indices) only those points' (and a few others'), the rest undefined."""
    ks = np.ascontiguousarray(scales, dtype=np.int64)
    idx = np.empty((tree.n, int(ks[-1])), dtype=np.int64)
    pdis = np.full((len(ks), tree.n), np.nan)
    _cloud_call(tree, ks, weighting == "gaussian", workers, rows, pdis=pdis, idx=idx)
    check = pdis[:, 0] if rows is None or len(rows) == 0 else pdis[:, int(rows[0])]
    if tree.n and np.isnan(check).any():  # a library built before this function
        raise RuntimeError("the compiled kernels are out of date: rebuild (pip install -e .)")
    return idx, pdis


# ---------------------------------------------------------------------------- meshes


def adjacency(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """1-ring adjacency in CSR form: indptr (n + 1,) int64, indices int32, each vertex's
    neighbours in the order of its faces, each once (about 6 per vertex)."""
    lib = _LIB
    assert lib is not None
    if n >= 2**31:
        raise ValueError("the compiled ring kernel handles fewer than 2**31 vertices")
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    ptr = np.empty(n + 1, dtype=np.int64)
    idx = np.empty(6 * len(faces), dtype=np.int32)
    rc = lib.ms_adjacency(_ptr(faces), len(faces), n, _ptr(ptr), _ptr(idx))
    if rc == -2:
        raise InputError(f"a face index lies outside the {n} vertices")
    if rc != 0:
        raise MemoryError("out of memory building the mesh adjacency")
    # trimmed in place (a shrinking realloc): no copy beside the untrimmed array
    idx.resize(int(ptr[-1]), refcheck=False)
    return ptr, idx


def scattered(indptr: np.ndarray, indices: np.ndarray) -> bool:
    """Whether a mesh's vertex order lacks locality, so that the ring pass renumbers it
    (``ms_scattered``'s rule: most of a sample of vertices lie more than
    ``SCATTERED_GAP`` positions from their first neighbour). ``indptr`` (n + 1,) int64,
    ``indices`` int32: :func:`adjacency`'s lists."""
    lib = _LIB
    assert lib is not None
    return bool(lib.ms_scattered(_ptr(indptr), _ptr(indices), len(indptr) - 1))


def scattered_faces(faces: np.ndarray, n: int, remap: np.ndarray | None = None) -> bool:
    """:func:`scattered` of the :func:`adjacency` of ``faces`` (m, 3) int64 mapped
    through ``remap`` (int64; None: as they are) into ``[0, n)``, from the faces alone,
    before the adjacency is built (``ms_scattered_faces``: one read of the faces, stopped
    once the vote is decided)."""
    lib = _LIB
    assert lib is not None
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    remap = None if remap is None else np.ascontiguousarray(remap, dtype=np.int64)
    return bool(lib.ms_scattered_faces(_ptr(faces), len(faces), _ptr(remap), n))


@dataclass
class Renumbering:
    """A mesh's vertices renumbered breadth-first (:func:`bfs_renumber`).

    Attributes
    ----------
    order : (n,) int32
        ``order[k]``: the old number of the vertex numbered ``k``.
    rank : (n,) int32
        The inverse: ``rank[order[k]] == k``.
    adjacency : (indptr (n + 1,) int64, indices int32)
        The lists in the new numbering: row ``k`` is old row ``order[k]`` mapped through
        ``rank``, in the same order.
    points : (n, 3) float64
        The points in the new order.
    normals : (n, 3) float64 or None
        The fixed normals in the new order, when given.
    """

    order: np.ndarray
    rank: np.ndarray
    adjacency: tuple[np.ndarray, np.ndarray]
    points: np.ndarray
    normals: np.ndarray | None


def bfs_renumber(
    adjacency: tuple[np.ndarray, np.ndarray], points: np.ndarray, normals: np.ndarray | None = None
) -> Renumbering:
    """The mesh's vertices renumbered breadth-first over :func:`adjacency`'s lists (each
    component from its lowest vertex not yet met, ``ms_bfs_renumber``), so that a search
    reads nearby memory: a search over the new lists meets the same vertices in the same
    order, so every ring and every sum over it is the same, bit for bit.

    Parameters
    ----------
    adjacency : (indptr (n + 1,) int64, indices int32)
    points : (n, 3) float64
    normals : (n, 3) float64, optional
        Gathered into the new order as well.
    """
    lib = _LIB
    assert lib is not None
    indptr, indices = adjacency
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    order, rank = np.empty(n, dtype=np.int32), np.empty(n, dtype=np.int32)
    ptr, idx = np.empty(n + 1, dtype=np.int64), np.empty(len(indices), dtype=np.int32)
    at, normals_at = np.empty_like(points), None if normals is None else np.empty_like(normals)
    lib.ms_bfs_renumber(
        _ptr(indptr), _ptr(indices), n, _ptr(points), _ptr(normals), _ptr(order), _ptr(rank),
        _ptr(ptr), _ptr(idx), _ptr(at), _ptr(normals_at),
    )  # fmt: skip
    return Renumbering(order, rank, (ptr, idx), at, normals_at)


def shifted_lists(indptr: np.ndarray, indices: np.ndarray, workers: int = -1) -> np.ndarray:
    """(n,) uint8: 1 where vertex ``w + 1``'s list is vertex ``w``'s with each neighbour
    plus one (``ms_shifted_lists``; a grid-numbered mesh's vertices), over
    :func:`adjacency`'s lists (``indptr`` (n + 1,) int64, ``indices`` int32)."""
    lib = _LIB
    assert lib is not None
    n = len(indptr) - 1
    out = np.empty(n, dtype=np.uint8)

    def task(a: int, b: int) -> int:
        lib.ms_shifted_lists(_ptr(indptr), _ptr(indices), n, a, b, _ptr(out))
        return 0

    _run_chunks(n, workers, task, chunk=8 * CHUNK)
    return out


def ring_projected_distances(
    points: np.ndarray,
    indptr: np.ndarray,
    indices: np.ndarray,
    rings: Sequence[int],
    normals: np.ndarray | None,
    weighting: str = "gaussian",
    *,
    keep_normals: bool = False,
    relative: bool = False,
    workers: int = -1,
    renumber: bool | None = None,
    follow: bool = True,
) -> ScalePass:
    """Projected distances (s, n) at every ring, by breadth-first search over the
    adjacency (``indptr``, ``indices``: :func:`adjacency`); ``normals`` (n, 3) fixed (zero
    rows: PCA of the ring) or None (PCA everywhere). Each ring is summed in the order
    ``RingNeighbourhoods.at`` lists it. With ``relative``, robust mode's
    :class:`meshlab_sharp.reference.detect.RelativeRule` in the same walk instead of the projected
    distances: the relative distances (s, n) and the score (n,), bit for bit (the local
    scales of each ring summed in numpy's order). ``renumber``: run the pass over the
    vertices renumbered breadth-first (``ms_bfs_renumber``: the same rings listed in the
    same order, so the same outputs bit for bit, read from nearby memory; each vertex's
    results written back to its own column); None: when the order is :func:`scattered`.
    ``follow``: take a vertex's search from the previous vertex's, every member plus one,
    where the lists it walked are shifted (:func:`shifted_lists`: a grid-numbered mesh);
    the same outputs as False (every vertex searched)."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    rs = np.ascontiguousarray(rings, dtype=np.int64)
    fixed = None if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
    dest = None
    if renumber is None:
        renumber = scattered(indptr, indices)
    if renumber:
        new = bfs_renumber((indptr, indices), points, fixed)
        dest, points, fixed, (indptr, indices) = new.order, new.points, new.normals, new.adjacency
    out = ScalePass(
        pdis=None if relative else np.empty((len(rs), n)),
        normals=np.empty((len(rs), n, 3)) if keep_normals else None,
        relative=np.empty((len(rs), n)) if relative else None,
        score=np.empty(n) if relative else None,
    )
    w = _workers(workers)
    stamp = _thread_scratch(n, np.int32)
    shifted = shifted_lists(indptr, indices, w) if follow else None

    def task(a: int, b: int) -> int:
        return lib.ms_ring_pdis(
            _ptr(points), n, _ptr(indptr), _ptr(indices), _ptr(fixed), _ptr(rs), len(rs),
            int(weighting == "gaussian"), a, b, _ptr(stamp()), _ptr(dest), _ptr(shifted),
            _ptr(out.pdis), _ptr(out.normals), _ptr(out.relative), _ptr(out.score),
        )  # fmt: skip

    _run_chunks(n, w, task)
    return out


def ring_members(
    adjacent: tuple[np.ndarray, np.ndarray],
    rows: np.ndarray,
    rings: Sequence[int],
    workers: int = -1,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The k-rings of the vertices ``rows`` (r,) for each k in ``rings`` (increasing), in
    breadth-first order over :func:`adjacency`'s lists (``adjacent``), as
    :func:`meshlab_sharp.neighbourhoods.grow_rings` lists them, each ring a prefix of the
    next: the last ring's members of row ``c`` at ``indices[start[c]:start[c + 1]]``
    (start (r + 1,) int64, indices int32), the ring ``rings[s]`` their first
    ``lengths[s, c]`` (lengths (s, r) int64). The rows in chunks of :data:`RING_CHUNK` on
    ``workers`` threads, each searched twice in a row: the lengths, then the members."""
    lib = _LIB
    assert lib is not None
    ptr, adj = adjacent
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    rs = np.ascontiguousarray(rings, dtype=np.int64)
    m = len(rows)
    stamp = _thread_scratch(len(ptr) - 1, np.int32)
    lengths = np.empty((len(rs), m), dtype=np.int64)
    members: dict[int, np.ndarray] = {}

    def search(a: int, b: int) -> int:
        count = np.empty((len(rs), b - a), dtype=np.int64)  # the chunk's lengths
        at = np.zeros(b - a + 1, dtype=np.int64)
        found = np.empty(0, dtype=np.int32)
        for fill in (False, True):  # the lengths, then the members (the rings still cached)
            if fill:
                np.cumsum(count[-1], out=at[1:])
                found = np.empty(int(at[-1]), dtype=np.int32)
            rc = lib.ms_ring_lists(
                _ptr(ptr), _ptr(adj), _ptr(rows[a:b]), b - a, _ptr(rs), len(rs), _ptr(stamp()),
                _ptr(count), _ptr(at) if fill else None, _ptr(found) if fill else None,
            )  # fmt: skip
            if rc != 0:
                return rc
        lengths[:, a:b] = count
        members[a] = found
        return 0

    _run_chunks(m, workers, search, chunk=RING_CHUNK)
    start = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(lengths[-1], out=start[1:])
    indices = np.concatenate([members[a] for a in sorted(members)] or [np.zeros(0, np.int32)])
    return start, lengths, indices


def two_face_edges(faces: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edges with exactly two faces, (e, 2) int64 ``a < b`` sorted lexicographically,
    and the dot products (e,) of their faces' unit normals (``faces`` (m, 3) of ``points``
    (n, 3)), as :func:`meshlab_sharp.creases.dihedral_angles` computes and pairs them."""
    lib = _LIB
    assert lib is not None
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    n, m = len(points), len(faces)
    if m and n > (2**63 - 1) // m:
        raise ValueError("too many vertices and faces for the compiled face pairing")
    # each such edge takes two of the 3 m face edges; the kernel sorts its 3 m keys in
    # the edges' array before writing the edges there
    room = (3 * m + 1) // 2
    edges = np.empty((room, 2), dtype=np.int64)
    dot = np.empty(room)
    e = lib.ms_two_face_edges(_ptr(points), _ptr(faces), m, n, _ptr(edges), _ptr(dot))
    if e < 0:
        raise MemoryError("out of memory pairing the faces of the mesh's edges")
    return edges[:e], dot[:e]


def crease_vertices(
    points: np.ndarray,
    faces: np.ndarray,
    angles_and_threshold: Callable[[np.ndarray, int], tuple[np.ndarray, float]],
) -> tuple[np.ndarray, float]:
    """The vertices of the edges with two faces that turn by more than a threshold, in
    less memory than :func:`two_face_edges` (no edge list): ``ms_crease_dots`` gives the
    dot products (t,) of the turned edges' unit face normals (those not >= 1) and the
    number of flat edges (their angle is exactly 0: most edges of a mesh, kept nowhere),
    ``angles_and_threshold(dots, flat) -> (angles (t,), threshold)`` turns them into
    angles (it may overwrite ``dots``) and the threshold of all the edges' angles, and
    ``ms_crease_mask`` marks the vertices of the edges whose angle exceeds it, walking
    again only the vertices that have such an edge.

    Returns
    -------
    mask : (n,) bool
    threshold : float
    """
    lib = _LIB
    assert lib is not None
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    n, m = len(points), len(faces)
    if m >= 2**31:
        raise ValueError("the compiled crease kernel handles fewer than 2**31 faces")
    ptr = np.empty(n + 1, dtype=np.int64)
    inc = np.empty(3 * m, dtype=np.int32)
    if lib.ms_vertex_faces(_ptr(faces), m, n, _ptr(ptr), _ptr(inc)) != 0:
        raise MemoryError("out of memory listing the faces of each vertex")
    # room for every edge; only the turned ones' pages are touched (a CAD mesh: a few)
    dots = np.empty((3 * m + 1) // 2)
    estart = np.empty(n + 1, dtype=np.int64)
    flat = np.zeros(1, dtype=np.int64)
    e = lib.ms_crease_dots(
        _ptr(points), _ptr(faces), n, _ptr(ptr), _ptr(inc), _ptr(dots), _ptr(estart), _ptr(flat)
    )
    angles, threshold = angles_and_threshold(dots[:e], int(flat[0]))
    angles = np.ascontiguousarray(angles, dtype=np.float64)
    mask = np.zeros(n, dtype=bool)
    lib.ms_crease_mask(
        _ptr(points), _ptr(faces), n, _ptr(ptr), _ptr(inc), _ptr(estart), _ptr(angles),
        float(threshold), _ptr(mask),
    )  # fmt: skip
    return mask, float(threshold)


def face_average_normals(
    points: np.ndarray, faces: np.ndarray, zero: float
) -> tuple[np.ndarray, int]:
    """Face-average vertex normals, bit for bit as the numpy reference computes them, and
    the number of faces :func:`face_windings` could not orient."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    acc = np.zeros_like(points)
    unoriented = lib.ms_face_average_normals(
        _ptr(points), len(points), _ptr(faces), len(faces), zero, _ptr(acc)
    )
    if unoriented < 0:
        raise MemoryError("out of memory orienting the faces of the mesh")
    return acc, int(unoriented)


def face_windings(faces: np.ndarray, n: int) -> tuple[np.ndarray, int]:
    """:func:`meshlab_sharp.creases.face_windings` (the faces to turn, and the number of
    faces it could not orient)."""
    lib = _LIB
    assert lib is not None
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    flip = np.zeros(len(faces), np.uint8)
    unoriented = lib.ms_face_windings(_ptr(faces), len(faces), n, _ptr(flip))
    if unoriented < 0:
        raise MemoryError("out of memory orienting the faces of the mesh")
    return flip.view(bool), int(unoriented)


#: Fewest faces that :func:`keep_faces` splits between two threads (65,536 faces are
#: about 1 ms of one thread; below, handing half to the pool is not worth it).
_PARALLEL_FACES = 1 << 16


def keep_faces(
    points: np.ndarray, faces: np.ndarray, from_input: np.ndarray | None, workers: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Cleaning's faces in one C pass (``ms_keep_faces``): ``faces`` (f, 3) mapped
    through ``from_input`` (n,) when not None, those whose double area on ``points``
    (m, 3) (``|(p1 - p0) x (p2 - p0)|``, as vcg's DoubleArea) is > 0, in order. With
    ``workers`` other than 1 and enough faces, the two halves of the faces on two
    threads, each marking the vertices it uses in an array of its own; the result does
    not depend on ``workers``.

    Returns
    -------
    kept : (k, 3) int64
    used : (m,) bool
        The vertices that a kept face uses.
    """
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    remap = None if from_input is None else np.ascontiguousarray(from_input, dtype=np.int64)
    parts = 2 if _workers(workers) > 1 and len(faces) >= _PARALLEL_FACES else 1
    bounds = [len(faces) * part // parts for part in range(parts + 1)]
    out = np.empty_like(faces)
    used = np.zeros((parts, len(points)), dtype=bool)
    kept = [0] * parts

    def task(a: int, b: int) -> int:
        for part in range(a, b):
            lo, hi = bounds[part], bounds[part + 1]
            kept[part] = lib.ms_keep_faces(_ptr(points), _ptr(faces[lo:]), hi - lo, _ptr(remap),
                                           _ptr(out[lo:]), _ptr(used[part]))  # fmt: skip
        return 0

    _run_chunks(parts, parts, task, chunk=1)
    k = kept[0]
    for part in range(1, parts):  # its faces moved to follow the parts' before it
        lo = bounds[part]
        if k != lo:
            out[k : k + kept[part]] = out[lo : lo + kept[part]]  # numpy copes with the overlap
        k += kept[part]
        used[0] |= used[part]
    out.resize((k, 3), refcheck=False)
    return out, used[0]


def extent(points: np.ndarray) -> np.ndarray:
    """``max - min`` of each coordinate of the finite ``points`` (n, 3): (3,) float64,
    numpy's ``ptp`` of each column (``ms_extent``, one pass)."""
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    out = np.empty(3)
    lib.ms_extent(_ptr(points), len(points), _ptr(out))
    return out


def noise_floor(counts: np.ndarray) -> float:
    """Robust mode's noise floor of a histogram's counts (``threshold.BINS``,) int
    (``ms_noise_floor``; :func:`meshlab_sharp.reference.robust.noise_floor` is the numpy
    reference)."""
    lib = _LIB
    assert lib is not None
    counts = np.ascontiguousarray(counts, dtype=np.int64)
    if counts.shape != (_header.integer("BINS"),):
        raise ValueError("counts must hold one count per histogram bin")
    return float(lib.ms_noise_floor(_ptr(counts)))


def scale_vote(
    values: np.ndarray,
    votes: np.ndarray,
    *,
    flat_span: float | None = None,
    otsu: bool = True,
    floor: float = 0.0,
    out: np.ndarray | None = None,
) -> tuple[float, int]:
    """One scale's threshold and votes in one C call (``ms_scale_vote``), bit for bit
    :func:`meshlab_sharp.threshold.normalise` (when ``flat_span`` is not None),
    :func:`~meshlab_sharp.threshold.otsu_threshold` and ``v >= T``.

    Parameters
    ----------
    values : (m,) float64
        Projected distances (normalised here when ``flat_span`` is given) or values
        already in [0, 1] (robust mode's relative distances).
    votes : (m,) int64
        Incremented in place where ``v >= T``.
    flat_span : float, optional
        Min-max normalise first, every value 0 when ``max - min <= flat_span``.
    otsu : bool, default True
        ``T = max(otsu_threshold(v), floor)``; False: ``T = floor``
        (:func:`meshlab_sharp.reference.detect.robust_threshold`).
    floor : float, default 0.0
    out : (m,) float64, optional
        Receives ``v``.

    Returns
    -------
    threshold : float
    count : int
        Points with ``v >= T``.
    """
    lib = _LIB
    assert lib is not None
    values = np.ascontiguousarray(values, dtype=np.float64)
    if votes.dtype != np.int64 or not votes.flags.c_contiguous or votes.shape != values.shape:
        raise ValueError("votes must be a contiguous int64 array shaped like values")
    if out is not None and (out.dtype != np.float64 or not out.flags.c_contiguous):
        raise ValueError("out must be a contiguous float64 array")
    count = ctypes.c_int64(0)
    normalise = flat_span is not None
    t = lib.ms_scale_vote(
        _ptr(values), len(values), int(normalise), float(flat_span or 0.0), int(otsu),
        float(floor), _ptr(out), _ptr(votes), ctypes.byref(count),
    )  # fmt: skip
    return float(t), int(count.value)


# ------------------------------------------- robust mode's rules, the cloud's stages


def _lib() -> ctypes.CDLL:
    """The loaded library; RuntimeError when it is not built."""
    if _LIB is None:
        raise RuntimeError(
            "the compiled kernels are not built: reinstall with 'pip install .' (needs gcc)"
        )
    return _LIB


def noise_factor(noise: float) -> float:
    """``ms_noise_factor``: the scales' growth for the cloud's noise ratio."""
    return float(_lib().ms_noise_factor(float(noise)))


def scale_growth(noise: float, n: int, top: int) -> float:
    """``ms_scale_growth``: the scales' growth on a cloud of ``n`` points (isolated ones
    left out) whose largest scale is ``top``: :func:`noise_factor`, at most ``n / top``."""
    return float(_lib().ms_scale_growth(float(noise), int(n), int(top)))


def grown_scale(k: int, factor: float) -> int:
    """``ms_grown_scale``: ``k * factor`` rounded half up."""
    return int(_lib().ms_grown_scale(int(k), float(factor)))


def thin_knn(growth: float) -> int:
    """``ms_thin_knn``: thinning's comparison list on a cloud whose scales grew by ``growth``."""
    return int(_lib().ms_thin_knn(float(growth)))


def quiet_cloud(mesh: bool, noise: float) -> bool:
    """``ms_quiet_cloud``: a cloud whose noise ratio is at most ``NOISE_QUIET``."""
    return bool(_lib().ms_quiet_cloud(int(mesh), float(noise)))


def otsu_splits(mesh: bool, noise: float) -> bool:
    """``ms_otsu_splits``: Otsu's split can raise the threshold above the floor."""
    return bool(_lib().ms_otsu_splits(int(mesh), float(noise)))


def scale_floor(counts: np.ndarray | None, last: bool, mesh: bool, noise: float) -> float:
    """``ms_scale_floor``: the floor of a scale's threshold, from its histogram ``counts``
    (B,) int (read only on the largest scale of a noisy cloud)."""
    if counts is None:
        counts = np.zeros(_header.integer("BINS"), np.int64)
    counts = np.ascontiguousarray(counts, np.int64)
    return float(_lib().ms_scale_floor(_ptr(counts), int(last), int(mesh), float(noise)))


def thin_cone(mesh: bool, noise: float) -> float:
    """``ms_thin_cone``: thinning's cone cosine."""
    return float(_lib().ms_thin_cone(int(mesh), float(noise)))


def thin_side(mesh: bool, noise: float) -> float:
    """``ms_thin_side``: thinning's side rule, a fraction of the list's reach."""
    return float(_lib().ms_thin_side(int(mesh), float(noise)))


def ranking_smoothed(mesh: bool, noise: float) -> bool:
    """``ms_ranking_smoothed``: thinning ranks by the smoothed score."""
    return bool(_lib().ms_ranking_smoothed(int(mesh), float(noise)))


def support_free_score(mesh: bool, noise: float) -> float | None:
    """``ms_support_free_score``: the score below which a candidate needs no support;
    None where there is none."""
    score = ctypes.c_double(0.0)
    found = _lib().ms_support_free_score(int(mesh), float(noise), ctypes.byref(score))
    return score.value if found else None


class _RobustPlan(ctypes.Structure):
    """``ms_robust_plan_t``."""

    _fields_ = [
        ("mesh", _int),
        ("noise", _f64),
        ("n_scales", _int),
        ("scales", _int * _header.integer("MAX_SCALES")),
        ("growth", _f64),
        ("grown", _int),
        ("otsu", _int),
        ("noise_floor", _int),
        ("acute_tests", _int),
        ("support_knn", _int),
        ("compare_knn", _int),
        ("ranking_smoothed", _int),
        ("support_exempt", _int),
        ("free_below", _f64),
        ("thin_cone", _f64),
        ("thin_side", _f64),
        ("thin_between", _int),
        ("curved_dropped", _int),
        ("thin_line", _int),
    ]


@dataclass(frozen=True)
class RobustPlan:
    """Robust mode's decisions once the first pass has measured the noise
    (``ms_robust_plan_t``, :func:`robust_plan`; the numpy reference's statement:
    :func:`meshlab_sharp.reference.robust.robust_plan`). ``scales``: those the detection
    runs at, grown by ``growth`` when ``grown`` (a pass at them follows); ``otsu``: Otsu's
    split raises the thresholds; ``noise_floor``: the largest scale's floor reads its
    histogram (:func:`plan_thresholds` applies both); ``acute_tests``: acute tips are
    looked for; ``support_knn``, ``compare_knn``: the support and comparison lists' sizes
    (a mesh's ``THIN_RING``-ring); ``ranking_smoothed``: thinning ranks by the smoothed
    score; ``free_below``: the score below which a candidate needs no support (None: every
    candidate needs it); ``thin_cone``: thinning's cone; ``thin_side``: its side rule;
    ``thin_between``: thinning is
    blocked by the points that are not candidates; ``curved_dropped``: the candidates on
    a curved surface are dropped (:func:`stage_curved`); ``thin_line``: thinning's line test
    follows (a cloud whose ranking is not smoothed)."""

    mesh: bool
    noise: float
    scales: tuple[int, ...]
    growth: float
    grown: bool
    otsu: bool
    noise_floor: bool
    acute_tests: bool
    support_knn: int
    compare_knn: int
    ranking_smoothed: bool
    free_below: float | None
    thin_cone: float
    thin_side: float
    thin_between: bool
    curved_dropped: bool
    thin_line: bool


def robust_plan(noise: float, n_kept: int, scales: Sequence[int], mesh: bool) -> RobustPlan:
    """``ms_robust_plan``: robust mode's decisions on an input (``mesh`` or a cloud) of
    noise ratio ``noise`` and ``n_kept`` points (isolated ones left out) at the given
    increasing ``scales``."""
    c = _RobustPlan()
    given = np.ascontiguousarray(scales, dtype=np.intc)  # not a ctypes array type per call
    args = (float(noise), int(n_kept), given.ctypes.data, len(given), int(mesh), ctypes.byref(c))
    if _lib().ms_robust_plan(*args):
        raise ValueError(f"robust_plan: 1 to {len(c.scales)} scales, got {len(scales)}")
    return RobustPlan(
        mesh=bool(c.mesh),
        noise=c.noise,
        scales=tuple(c.scales[: c.n_scales]),
        growth=c.growth,
        grown=bool(c.grown),
        otsu=bool(c.otsu),
        noise_floor=bool(c.noise_floor),
        acute_tests=bool(c.acute_tests),
        support_knn=c.support_knn,
        compare_knn=c.compare_knn,
        ranking_smoothed=bool(c.ranking_smoothed),
        free_below=c.free_below if c.support_exempt else None,
        thin_cone=c.thin_cone,
        thin_side=c.thin_side,
        thin_between=bool(c.thin_between),
        curved_dropped=bool(c.curved_dropped),
        thin_line=bool(c.thin_line),
    )


def plan_thresholds(plan: RobustPlan, counts: np.ndarray) -> np.ndarray:
    """``ms_plan_thresholds``: each scale's threshold (s,) from its summed histogram,
    ``counts`` (s, BINS) int64, by ``plan``'s rules (Otsu's split and the floors)."""
    c = _RobustPlan()
    for name, _ in _RobustPlan._fields_:
        if name not in ("scales", "free_below"):  # the others are plan's own fields
            setattr(c, name, getattr(plan, name, 0))
    c.n_scales, c.scales[: len(plan.scales)] = len(plan.scales), plan.scales
    c.support_exempt, c.free_below = plan.free_below is not None, plan.free_below or 0.0
    counts = np.ascontiguousarray(counts, dtype=np.int64)
    bins = _header.integer("BINS")
    if counts.shape != (len(plan.scales), bins):
        raise ValueError(f"counts must be (s, {bins}), one histogram per scale")
    out = np.zeros(len(plan.scales))
    _lib().ms_plan_thresholds(ctypes.byref(c), _ptr(counts), _ptr(out))
    return out


def flat_span(extent: np.ndarray) -> float:
    """``ms_flat_span``: ``FLAT_TOLERANCE`` times the diagonal of the bounding box whose
    sides are ``extent`` (3,) (:func:`extent`'s)."""
    extent = np.ascontiguousarray(extent, dtype=np.float64)
    if extent.shape != (3,):
        raise ValueError("extent must be (3,)")
    return float(_lib().ms_flat_span(_ptr(extent)))


#: Lower and upper ends of each scale's min-max normalisation, and the flat span: the
#: global ones of a cloud (None: the values as they are, in [0, 1]).
Normalisation = tuple[np.ndarray, np.ndarray, float] | None


def _stage_args(values: np.ndarray, norm: Normalisation) -> tuple[np.ndarray, tuple[Any, ...]]:
    """The values (m, s) made contiguous, and their scale count, point and scale strides
    and normalisation as the ``ms_stage_`` functions take them (the normalisation's
    arrays kept alive by the caller's ``norm``)."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    if values.ndim != 2:
        raise ValueError("values must be (m, s)")
    s = values.shape[1]
    if norm is None:
        return values, (s, s, 1, None, None, 0.0)
    lo, hi, flat = norm
    if len(lo) != s or len(hi) != s:
        raise ValueError("the normalisation needs one lo and one hi per scale")
    return values, (s, s, 1, _ptr(lo), _ptr(hi), float(flat))


def _norm(norm: Normalisation) -> Normalisation:
    """``norm`` with contiguous float64 arrays."""
    if norm is None:
        return None
    lo, hi, flat = norm
    as_f64 = (np.ascontiguousarray(x, dtype=np.float64) for x in (lo, hi))
    return (*as_f64, float(flat))


def stage_histograms(values: np.ndarray, norm: Normalisation = None) -> np.ndarray:
    """``ms_stage_histograms``: each scale's ``BINS``-bin histogram (s, BINS) int64 of
    ``values`` (m, s), min-max normalised with ``norm`` when given; histograms of parts
    of the points add up to the whole's."""
    norm = _norm(norm)
    values, (s, ps, ss, lo, hi, flat) = _stage_args(values, norm)
    counts = np.zeros((s, _header.integer("BINS")), dtype=np.int64)
    _lib().ms_stage_histograms(_ptr(values), ps, ss, s, 0, len(values), lo, hi, flat, _ptr(counts))
    return counts


def stage_threshold(counts: np.ndarray, otsu: bool, floor: float) -> float:
    """``ms_stage_threshold``: a scale's threshold from its (summed) histogram (BINS,):
    ``max(Otsu's split, floor)``, ``floor`` alone when not ``otsu``."""
    counts = np.ascontiguousarray(counts, dtype=np.int64)
    return float(_lib().ms_stage_threshold(_ptr(counts), int(otsu), float(floor)))


def stage_decide(
    values: np.ndarray,
    thresholds: np.ndarray,
    norm: Normalisation = None,
    out: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ms_stage_decide``: with the global ``thresholds`` (s,), the candidates at every
    scale (m,) bool, the strength (m,) (fraction of scales) and the candidates per scale
    (s,) int64 of ``values`` (m, s) (normalised with ``norm`` when given); ``out``
    (m, s) float64, when given, receives the values compared with the thresholds."""
    norm = _norm(norm)
    values, (s, ps, ss, lo, hi, flat) = _stage_args(values, norm)
    thresholds = np.ascontiguousarray(thresholds, dtype=np.float64)
    if len(thresholds) != s:
        raise ValueError("one threshold per scale")
    if out is not None and (
        out.dtype != np.float64 or not out.flags.c_contiguous or out.shape != values.shape
    ):
        raise ValueError("out must be a contiguous float64 array shaped like values")
    m = len(values)
    feature, strength = np.zeros(m, dtype=bool), np.zeros(m)
    counts = np.zeros(s, dtype=np.int64)
    _lib().ms_stage_decide(
        _ptr(values), ps, ss, s, 0, m, lo, hi, flat, _ptr(thresholds), _ptr(feature),
        _ptr(strength), _ptr(counts), _ptr(out),
    )  # fmt: skip
    return feature, strength, counts


def stage_acute_tests(score: np.ndarray, mask: np.ndarray, mesh: bool, noise: float) -> np.ndarray:
    """``ms_stage_acute_tests``: the points :func:`acute_tips` tests, (t,) int64
    increasing (none unless a quiet cloud)."""
    score = np.ascontiguousarray(score, dtype=np.float64)
    mask = np.ascontiguousarray(mask, dtype=bool)
    tested = np.zeros(len(score), dtype=bool)
    args = (int(mesh), float(noise), _ptr(tested))
    _lib().ms_stage_acute_tests(_ptr(score), _ptr(mask), 0, len(score), *args)
    return np.flatnonzero(tested)


def stage_curved(
    first: np.ndarray, last: np.ndarray, s_first: int, s_last: int, mask: np.ndarray
) -> np.ndarray:
    """``ms_stage_curved``: ``mask`` (m,) bool less the points whose relative distance
    grows from ``first`` (m,), at the ring ``s_first``, to ``last`` (m,), at the ring
    ``s_last``, at least as the square root of the ring. Returns (m,) bool, a copy."""
    first = np.ascontiguousarray(first, dtype=np.float64)
    last = np.ascontiguousarray(last, dtype=np.float64)
    out = np.array(mask, dtype=bool)
    ends = (int(s_first), int(s_last))
    _lib().ms_stage_curved(_ptr(first), _ptr(last), 0, len(out), *ends, _ptr(out))
    return out


def stage_isolated(
    a: np.ndarray,
    b: np.ndarray,
    kth_d2: np.ndarray,
    kth_idx: np.ndarray,
    idx: np.ndarray,
    nth_d2: np.ndarray,
    far_d2: np.ndarray,
    spread: float,
) -> np.ndarray:
    """``ms_stage_isolated``: which of the points ``a`` (r, 3) (indices ``idx`` (r,) in the
    lists' order) are isolated, their values gathered per row: the nearest ``b`` (r, 3),
    its k-th neighbour's squared distance ``kth_d2`` and index ``kth_idx``, the point's
    ``nth_d2`` and its k-th neighbour's ``far_d2`` (r,). Returns (r,) bool."""
    f64 = [np.ascontiguousarray(x, dtype=np.float64) for x in (a, b, kth_d2, nth_d2, far_d2)]
    i64 = [np.ascontiguousarray(x, dtype=np.int64) for x in (kth_idx, idx)]
    pa, pb, pk, pn, pf = (_ptr(x) for x in f64)
    out = np.zeros(len(f64[0]), dtype=bool)
    args = (pa, pb, pk, _ptr(i64[0]), _ptr(i64[1]), pn, pf, float(spread))
    _lib().ms_stage_isolated(*args, 0, len(out), _ptr(out))
    return out


def merge_duplicates(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exactly equal points merged into their first occurrence (``ms_dedup``, one thread:
    the library's merge in ``ms_detect``).

    Returns
    -------
    to_input : (m,) int64
        Input index of each distinct point, increasing.
    from_input : (n,) int64
        Distinct index of each input point.
    distinct : (m, 3) float64
        The distinct points, ``points[to_input]`` (copied in the numbering pass;
        ``points`` itself, contiguous float64, when none merges).
    """
    lib = _LIB
    assert lib is not None
    points = np.ascontiguousarray(points, dtype=np.float64)
    n = len(points)
    if n >= 2**31:
        raise ValueError("the compiled duplicate merge handles fewer than 2**31 points")
    size = 1 << int(np.ceil(np.log2(max(2 * n, 2))))
    table = np.empty(size, dtype=np.uint64)  # cleared by ms_dedup
    from_input = np.zeros(n, dtype=np.int64)
    to_input = np.empty(n, dtype=np.int64)
    distinct = np.empty_like(points)  # its pages: touched by the copy only when some merge
    m = lib.ms_dedup(
        _ptr(points), n, _ptr(table), size - 1, _ptr(from_input), _ptr(to_input), _ptr(distinct)
    )
    del table
    to_input.resize(m, refcheck=False)  # trimmed in place: no copy
    if m == n:
        return to_input, from_input, points
    distinct.resize((m, 3), refcheck=False)
    return to_input, from_input, distinct


def smallest_eigenvectors(cov: np.ndarray) -> np.ndarray:
    """Unit eigenvector of the smallest eigenvalue of each symmetric (c, 3, 3) matrix."""
    lib = _LIB
    assert lib is not None
    c = np.ascontiguousarray(cov[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]], dtype=np.float64)
    out = np.empty((len(c), 3))
    lib.ms_eigvecs(_ptr(c), len(c), _ptr(out))
    return out


# ------------------------------------------------------- robust mode's finishing steps


class _Lists(ctypes.Structure):
    """``ms_lists_t``: the lists of candidate slots (:class:`CandidateLists`)."""

    _fields_ = [
        ("idx", _c_void_p),
        ("wide", _i64),
        ("start", _c_void_p),
        ("stride", _i64),
        ("len", _c_void_p),
        ("k", _i64),
    ]


@dataclass
class CandidateLists:
    """One list per candidate slot ``c`` (the point ``rows[c]`` of the finishing steps):
    the first ``len[c]`` (or ``k``) members of ``idx`` from ``start[c]`` (or ``c *
    stride``) on. The lists of several steps share ``idx``: a kNN table's first ``k``
    columns (:meth:`knn`), or a mesh's rings, each a prefix of the next (:meth:`rings`).
    """

    idx: np.ndarray  # int64 or int32
    start: np.ndarray | None = None  # (c,) int64
    stride: int = 0
    len: np.ndarray | None = None  # (c,) int64
    k: int = 0

    @classmethod
    def knn(cls, table: np.ndarray, k: int, slots: np.ndarray | None = None) -> CandidateLists:
        """The first ``k`` columns of each row of ``table`` (r, K) int64, or of its rows
        ``slots`` (c,) only."""
        table = np.ascontiguousarray(table, dtype=np.int64)
        stride = table.shape[1]
        start = None if slots is None else np.asarray(slots, dtype=np.int64) * stride
        return cls(table, start=start, stride=stride, k=k)

    @classmethod
    def rings(cls, members: tuple[np.ndarray, np.ndarray, np.ndarray]) -> list[CandidateLists]:
        """Each ring of :func:`ring_members`' ``(start, lengths, indices)``."""
        start, lengths, indices = members
        return [cls(indices, start=start, len=np.ascontiguousarray(n)) for n in lengths]

    def spec(self) -> _Lists:
        """The ``ms_lists_t`` (it refers to these arrays: keep them while it is used)."""
        wide = self.idx.dtype == np.int64
        assert wide or self.idx.dtype == np.int32
        start, length = _ptr(self.start), _ptr(self.len)
        return _Lists(_ptr(self.idx), int(wide), start, self.stride, length, self.k)


def _slot_chunks(c: int, workers: int, task: Callable[[int, int], int]) -> None:
    """``task`` over the ``c`` candidate slots, about two chunks a thread: a few
    thousand candidates, a few milliseconds of work."""
    w = _workers(workers)
    _run_chunks(c, w, task, chunk=max(256, -(-c // (2 * w))))


def acute_tips(
    points: np.ndarray, mask: np.ndarray, rows: np.ndarray, lists: CandidateLists, workers: int = -1
) -> np.ndarray:
    """:func:`meshlab_sharp.reference.robust.acute_tips` of the points ``rows`` (t,) with their
    lists (the thinning's): (t,) bool, on ``workers`` threads."""
    lib = _LIB
    assert lib is not None
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    mask = np.ascontiguousarray(mask, dtype=bool)
    points = np.ascontiguousarray(points, dtype=np.float64)
    out = np.zeros(len(rows), dtype=bool)
    spec = ctypes.byref(lists.spec())
    args = (_ptr(points), _ptr(mask), _ptr(rows), spec)

    def task(a: int, b: int) -> int:
        lib.ms_acute_tips(*args, a, b, _ptr(out))
        return 0

    _slot_chunks(len(rows), workers, task)
    return out


@dataclass(frozen=True)
class LineRules:
    """Thinning's line test (``ms_line_rules_t``): the offset, spread and reach in local
    units, the fewest stronger features that make a line, and how many nearest set the
    unit (robust.py's ``LINE_`` constants)."""

    offset: float
    spread: float
    reach: float
    minimum: int
    unit: int


class _LineRules(ctypes.Structure):
    _fields_ = [
        ("offset", _f64),
        ("spread", _f64),
        ("reach", _f64),
        ("minimum", _i64),
        ("unit", _i64),
    ]


@dataclass
class FinishRules:
    """How robust mode's support and thinning decide (robust.py's rules for the input):
    support's cone and minimum and the scores it exempts (below ``free_below``; None:
    none), thinning's cone and side rule, its ranking smoothed over the first ``window``
    of its lists (0: the score itself), its blockers ``between`` (n,) bool (None:
    none), and the rules of the line test that follows (``line``: a cloud's,
    ``ms_line_test``; None: none)."""

    support_cone: float
    minimum: int
    free_below: float | None
    thin_cone: float
    thin_side: float
    window: int
    between: np.ndarray | None
    line: LineRules | None = None


def line_support(
    points: np.ndarray,
    mask: np.ndarray,
    score: np.ndarray,
    rows: np.ndarray,
    lists: tuple[CandidateLists, CandidateLists],
    rules: FinishRules,
    workers: int = -1,
    compare: CandidateLists | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Support, the first of robust mode's finishing steps, over the candidates ``rows``
    (c,) (points of ``mask`` (n,) bool), in C: each one's line direction
    (``ms_line_directions``, over ``lists[0]``) and support (``ms_supported``, over
    ``lists[1]``, by ``rules``' cone and minimum, ``score`` (n,) below
    ``rules.free_below`` exempt) and, with ``rules.window`` and ``compare``, the score
    smoothed over the first ``window`` of compare (``ms_smoothed_ranking``). Returns the
    directions (c, 3), the supported mask (n,) bool (at the rows; False elsewhere) and the
    ranking (n,): the smoothed score at the rows, ``score`` elsewhere (``score`` itself
    when not smoothed)."""
    lib = _lib()
    points = np.ascontiguousarray(points, dtype=np.float64)
    mask = np.ascontiguousarray(mask, dtype=bool)
    score = np.ascontiguousarray(score, dtype=np.float64)
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    direction, around = (ctypes.byref(x.spec()) for x in lists)
    window = rules.window if compare is not None else 0
    near = None if compare is None else ctypes.byref(compare.spec())
    e = np.empty((len(rows), 3))
    supported = np.zeros(len(mask), dtype=bool)
    rank = score.copy() if window else score
    free = rules.free_below
    p, f0, r, f1, pe, pr = (
        _ptr(points),
        _ptr(mask),
        _ptr(rows),
        _ptr(supported),
        _ptr(e),
        _ptr(rank),
    )

    def along(a: int, b: int) -> int:
        if lib.ms_line_directions(p, f0, r, direction, a, b, pe) != 0:
            return -1
        lib.ms_supported(
            p, f0, r, pe, around, rules.support_cone, rules.minimum,
            None if free is None else _ptr(score), 0.0 if free is None else free, a, b, f1,
        )  # fmt: skip
        if window:
            lib.ms_smoothed_ranking(_ptr(score), r, near, window, a, b, pr)
        return 0

    _slot_chunks(len(rows), workers, along)
    return e, supported, rank


def smoothed_ranking(
    score: np.ndarray, rows: np.ndarray, compare: CandidateLists, window: int, workers: int = -1
) -> np.ndarray:
    """``ms_smoothed_ranking`` of the points ``rows`` (c,): the mean of ``score`` (n,) over
    the first ``window`` of each one's ``compare`` list at the rows, ``score`` elsewhere
    (n,)."""
    lib = _lib()
    score = np.ascontiguousarray(score, dtype=np.float64)
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    rank = score.copy()
    spec = ctypes.byref(compare.spec())

    def task(a: int, b: int) -> int:
        lib.ms_smoothed_ranking(_ptr(score), _ptr(rows), spec, window, a, b, _ptr(rank))
        return 0

    _slot_chunks(len(rows), workers, task)
    return rank


def thin_candidates(
    points: np.ndarray,
    supported: np.ndarray,
    rows: np.ndarray,
    e: np.ndarray,
    compare: CandidateLists,
    rank: np.ndarray,
    rules: FinishRules,
    workers: int = -1,
) -> np.ndarray:
    """Thinning, the last of robust mode's finishing steps (``ms_thin``), of the points
    ``rows`` (c,) with their line directions ``e`` (c, 3), once ``supported`` (n,) bool
    is known at every point of their ``compare`` lists: by ``rank`` (n,), in
    ``rules.thin_cone`` or beside the line (``rules.thin_side``), blocked by
    ``rules.between``. Returns the thinned mask (n,) bool (False off the rows)."""
    lib = _lib()
    points = np.ascontiguousarray(points, dtype=np.float64)
    supported = np.ascontiguousarray(supported, dtype=bool)
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    e = np.ascontiguousarray(e, dtype=np.float64)
    rank = np.ascontiguousarray(rank, dtype=np.float64)
    between = None if rules.between is None else np.ascontiguousarray(rules.between, bool)
    spec = ctypes.byref(compare.spec())
    out = np.zeros(len(supported), dtype=bool)
    args = (_ptr(points), _ptr(supported), _ptr(rows), _ptr(e), spec, _ptr(rank))

    def task(a: int, b: int) -> int:
        lib.ms_thin(*args, rules.thin_cone, rules.thin_side, _ptr(between), a, b, _ptr(out))
        return 0

    _slot_chunks(len(rows), workers, task)
    return out


def line_test(
    points: np.ndarray,
    thinned: np.ndarray,
    rows: np.ndarray,
    compare: CandidateLists,
    rank: np.ndarray,
    rules: LineRules,
    between: np.ndarray | None,
    workers: int = -1,
) -> np.ndarray:
    """Thinning's line test (``ms_line_test``, by ``rules``) of the points ``rows`` (c,),
    once ``thinned`` (n,) bool is known at every point of their ``compare`` lists: by
    ``rank`` (n,), blocked by ``between`` (n,) bool (None: none). Returns the tested mask
    (n,) bool (False off the rows) (:func:`meshlab_sharp.reference.robust.line_test`'s)."""
    lib = _lib()
    points = np.ascontiguousarray(points, dtype=np.float64)
    thinned = np.ascontiguousarray(thinned, dtype=bool)
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    rank = np.ascontiguousarray(rank, dtype=np.float64)
    between = None if between is None else np.ascontiguousarray(between, bool)
    spec = ctypes.byref(compare.spec())
    out = np.zeros(len(thinned), dtype=bool)
    c_rules = _LineRules(rules.offset, rules.spread, rules.reach, rules.minimum, rules.unit)
    args = (_ptr(points), _ptr(thinned), _ptr(rows), spec, _ptr(rank), ctypes.byref(c_rules))

    def task(a: int, b: int) -> int:
        return lib.ms_line_test(*args, _ptr(between), a, b, _ptr(out))

    _slot_chunks(len(rows), workers, task)
    return out


def support_and_thin(
    points: np.ndarray,
    mask: np.ndarray,
    score: np.ndarray,
    rows: np.ndarray,
    lists: tuple[CandidateLists, CandidateLists, CandidateLists],
    rules: FinishRules,
    workers: int = -1,
) -> np.ndarray:
    """Robust mode's finishing steps over the candidates ``rows`` (c,) = the points of
    ``mask`` (n,) bool, in C: :func:`line_support` (with ``rules.window``, the smoothed
    ranking too), then, once every candidate's support is known,
    :func:`thin_candidates` (:func:`meshlab_sharp.reference.robust.line_directions`, ``supported``,
    ``smoothed_ranking``, ``thin``, of which this gives the masks). ``lists``: each
    candidate's direction, support and comparison lists; ``score`` (n,): the ranking.
    Returns the thinned mask (n,) bool."""
    direction, around, compare = lists
    e, supported, rank = line_support(
        points, mask, score, rows, (direction, around), rules, workers, compare
    )
    thinned = thin_candidates(points, supported, rows, e, compare, rank, rules, workers)
    if rules.line is None:
        return thinned
    return line_test(points, thinned, rows, compare, rank, rules.line, rules.between, workers)
