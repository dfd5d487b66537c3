"""Out-of-core and distributed detection of point clouds: spatial tiles with halos.

``detect(cloud, max_memory="1GB")`` (CLI ``--max-memory 1GB``) and ``detect(cloud,
dask="local:2")`` (CLI ``--dask``) come here. The cloud is sorted into tiles
(:mod:`.layout`) on disk (:mod:`.store`); each mode is a sequence of steps
(:mod:`.steps`, each the native library's stage that the in-memory run composes too)
run tile by tile (:mod:`.run`): local steps on each tile's exact
neighbourhoods (:mod:`.neighbours`, the halo proven wide enough per point) and
pointwise steps, with the global quantities (min-max ranges, the 256-bin histograms
that give Otsu's thresholds, counts) reduced exactly over the tiles. The result is the
in-memory result, bit for bit: same features, strengths and thresholds.

Point clouds only: a mesh's k-rings follow its faces, not space, and meshes are not
tiled (an input with faces is an error unless ``as_points``).
"""

from __future__ import annotations

import logging
import os
import re
import shutil
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import _kernels, robust
from ..defaults import DEFAULT_MODE
from ..errors import InputError
from ..extras import require
from ..io import Geometry
from ..io.source import PointSource
from ..io.stream import open_points
from ..multiscale import DEFAULT_KNN_SCALES
from ..normals import DEFAULT_WEIGHTING
from ..options import as_input, check_mode_and_weighting, check_scales
from ..preprocessing import as_preprocessing
from ..progress import Progress
from .cluster import cluster_failures, completed, connect
from .curves import curves_out_of_core
from .layout import build_layout
from .neighbours import Query
from .run import Runner, peak_rss, warm_up
from .select import order_statistic
from .steps import (
    Step,
    paper_decide,
    paper_distances,
    paper_histograms,
    robust_acute_join,
    robust_acute_tests,
    robust_acute_tips,
    robust_affected,
    robust_decide,
    robust_histograms,
    robust_isolated,
    robust_line,
    robust_pass,
    robust_rank,
    robust_support,
    robust_thin,
)
from .store import Store, make_scratch

if TYPE_CHECKING:
    from ..result import DetectionResult

__all__ = ["PointSource", "detect_out_of_core", "detect_tiled", "parse_memory", "tile_size"]

#: Bytes a point of a tile (with its halo) takes while its neighbourhoods are searched,
#: beyond ``8 * k_max`` for the neighbour lists (measured, with a margin).
BYTES_PER_POINT = 700
#: Halo points per tile point assumed when sizing the tiles.
HALO_FACTOR = 2.5
#: Tiles run at the same time in one process (without Dask): one's Python work and
#: reads overlap the other's compiled pass.
TILES_AT_ONCE = 2
#: Default memory of a tile task on a Dask worker without ``max_memory``.
DASK_TILE_MEMORY = 1 << 30

#: Memory of a Dask worker before its first tile (interpreter, numpy, scipy, dask).
WORKER_BASELINE = 200 << 20
#: Dask settings while a ``local:N`` cluster starts: its workers keep glibc's own
#: memory handling. Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``,
#: which also fixes glibc's mmap threshold at 128 kB: every array over it is mapped,
#: faulted in page by page and unmapped again, tile after tile (measured: 8x the page
#: faults, 1.46x the workers' CPU time on 500k points).
LOCAL_WORKER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
#: Tile steps of each mode (progress bar).
STEPS = {"paper": 3, "robust": 8}

_UNITS = {"": 1, "B": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_memory(text: str | int) -> int:
    """``"1GB"``, ``"512M"``, ``"2.5 GiB"`` or a number of bytes -> bytes."""
    if isinstance(text, int | np.integer) and not isinstance(text, bool):
        value = int(text)
    else:
        m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([kKmMgGtT]?)(?:i?[bB])?\s*", str(text))
        if m is None:
            raise InputError(f"cannot read the memory size {text!r}; write e.g. 1GB or 512MB")
        value = int(float(m.group(1)) * _UNITS[m.group(2).upper()])
    if value <= 0:
        raise InputError(f"the memory size must be positive, got {text!r}")
    return value


def tile_size(budget: float, scales: tuple[int, ...], mode: str, at_once: int) -> int:
    """Points per tile for ``budget`` bytes of tile memory: ``at_once`` tiles at the
    given scales fit in it, or one tile at the largest scales robust mode may grow them
    to (``NOISE_MAX_FACTOR``-fold; once grown, the tiles run one at a time), each tile
    searching up to ``HALO_FACTOR`` times its points at ``BYTES_PER_POINT`` plus its
    neighbour lists and per-scale values."""
    k_max = max(scales)
    # robust mode may grow the scales with the noise, up to NOISE_MAX_FACTOR-fold
    k_most = k_max * (robust.NOISE_MAX_FACTOR if mode == "robust" else 1.0)

    def per_point(k: float) -> float:
        return (BYTES_PER_POINT + 8 * k + 16 * len(scales)) * HALO_FACTOR

    return int(budget / max(at_once * per_point(k_max), per_point(k_most)))


def detect_tiled(
    source: PointSource | np.ndarray | Geometry,
    *,
    scales: tuple[int, ...],
    weighting: str = DEFAULT_WEIGHTING,
    mode: str = DEFAULT_MODE,
    max_memory: str | int | None = None,
    tile_points: int | None = None,
    dask: str | Any = None,
    scratch: str | os.PathLike[str] | None = None,
    on_tile: Callable[[str, int, int], None] | None = None,
    workers: int = -1,
) -> dict[str, Any]:
    """Detect the sharp features of a cloud tile by tile.

    Parameters
    ----------
    source : PointSource, (n, 3) array or Geometry (its vertices)
    scales : tuple of int
        Increasing kNN scales (checked by the caller).
    weighting, mode
        As :func:`meshlab_sharp.detect`.
    max_memory : str or int, optional
        Peak memory to stay under ("1GB"); sizes the tiles.
    tile_points : int, optional
        Points per tile, instead of deriving it from ``max_memory`` (tests).
    dask : str or dask.distributed.Client, optional
        ``"local:N"`` (a LocalCluster of N single-thread worker processes),
        ``"tcp://host:port"`` (a running scheduler) or a Client.
    scratch : path, optional
        Folder for the tiles' arrays (deleted afterwards); with a cluster on several
        machines, a path that every worker reaches. Default: the system's temp folder.
    on_tile : callable, optional
        ``on_tile(label, done, n_tiles)`` after each tile task.
    workers : int
        Threads of the kNN search in each tile task; <= 0 (default): on Dask, the
        cores of the worker's machine shared by its workers' threads
        (:func:`meshlab_sharp.tiles.run.task_threads`), else all the cores.

    Returns
    -------
    dict
        ``mask`` (n,) bool, ``strength`` (n,) float64, ``kept`` (n,) bool in input
        order; ``thresholds`` (s,), ``candidate_counts`` (s,), ``n_clean``, ``timings``
        (seconds: ``tiles``, ``cluster`` (Dask start-up), ``detect`` and within it
        ``step_<label>`` per step (wall) and ``tasks_<label>`` (its tile tasks' own
        seconds, summed), ``finish``, ``total``),
        and ``tiling`` (tiles, steps, tasks, halo, points that took the streaming route,
        most threads of a tile task's searches (``task_threads``),
        robust mode's points whose pass ran again (``redone``), peak memory of this
        process and of the workers).
    """
    if isinstance(source, Geometry):
        source = PointSource.from_array(source.vertices, source.source)
    elif isinstance(source, np.ndarray):
        source = PointSource.from_array(source)
    t0 = time.perf_counter()
    k_max = max(scales)
    limit = None if max_memory is None else parse_memory(max_memory)
    if tile_points is None:
        budget = limit if limit is not None else DASK_TILE_MEMORY
        if dask is None:
            budget -= _resident() + 10 * source.n
        else:  # a worker's interpreter and imports
            budget -= WORKER_BASELINE
        tile_points = tile_size(budget, scales, mode, 1 if dask is not None else TILES_AT_ONCE)
        if tile_points < 4 * k_max:
            raise InputError(
                f"--max-memory {max_memory}: too little memory for tiles of "
                f"{source.n} points (this process already uses {_resident() >> 20} MB)"
            )
    chunk = int(min(max(tile_points, 65536), 1 << 20))
    with ExitStack() as stack:
        root = make_scratch(scratch)
        stack.callback(shutil.rmtree, root, True)
        store = Store(root)
        timings: dict[str, float] = {}
        t = time.perf_counter()
        client = _client(dask, stack)
        if client is not None:
            timings["cluster"] = time.perf_counter() - t
        ready = [] if client is None else warm_up(client)  # imports while the tiles are cut
        t = time.perf_counter()
        layout = build_layout(
            source.n,
            lambda: source.blocks(chunk),
            store,
            tile_points=tile_points,
            source=source.name,
        )
        timings["tiles"] = time.perf_counter() - t
        if ready:
            with cluster_failures("start"):
                client.gather(list(completed(client, ready)))
        if layout.n_clean < k_max:
            raise InputError(
                f"{source.name}: {layout.n_clean} distinct points, fewer than the largest "
                f"scale k = {k_max}; use smaller --scales"
            )
        runner = Runner(
            store,
            layout,
            most_points=int(HALO_FACTOR * tile_points),
            workers=workers,
            at_once=TILES_AT_ONCE,
            on_tile=on_tile,
            client=client,
        )
        t = time.perf_counter()
        run = _paper if mode == "paper" else _robust
        thresholds, counts, mask, kept, used = run(runner, store, layout, scales, weighting)
        timings["detect"] = time.perf_counter() - t
        timings.update({f"step_{label}": v for label, v in runner.seconds.items()})
        timings.update({f"tasks_{label}": v for label, v in runner.task_seconds.items()})
        t = time.perf_counter()
        out = runner.finish(source.n, mask, kept)
        timings["finish"] = time.perf_counter() - t
        worker_peak = runner.peak if client is not None else 0
    timings["total"] = time.perf_counter() - t0
    out.update(
        scales=used,
        thresholds=thresholds,
        candidate_counts=counts,
        n_clean=layout.n_clean,
        timings=timings,
        tiling={
            "tiles": layout.n_tiles,
            "tile_points": tile_points,
            "tasks": runner.tasks,
            "largest_search": runner.gathered,
            "streamed": runner.streamed,
            "task_threads": runner.threads,
            "redone": runner.notes.get("redone", 0),
            "halo_max": float(runner.halos.max(initial=0.0)),
            "peak_bytes": peak_rss(),
            "worker_peak_bytes": worker_peak,
            "max_memory": limit,
            "dask": None if dask is None else str(dask),
        },
    )
    return out


def detect_out_of_core(
    source: Any,
    faces: np.ndarray | None,
    *,
    scales: Sequence[int] | int | None,
    weighting: str,
    as_points: bool,
    mode: str,
    return_details: bool,
    progress: bool | Progress,
    workers: int,
    preprocessing: Any,
    backend: str | None,
    max_memory: str | int | None,
    dask: Any,
    scratch: str | os.PathLike[str] | None,
    curves: bool = False,
) -> DetectionResult:
    """:func:`meshlab_sharp.detect` with ``max_memory`` or ``dask``: checks what the
    tiled run supports and returns its :class:`~meshlab_sharp.DetectionResult` (with
    ``curves``, the feature curves: :func:`meshlab_sharp.tiles.curves.curves_out_of_core`)."""
    from ..result import DetectionResult

    check_mode_and_weighting(mode, weighting)
    if return_details:
        raise InputError(
            "return_details keeps per-scale arrays in memory: not with max_memory/dask"
        )
    steps = as_preprocessing(preprocessing)
    if steps is not None and steps.active:
        raise InputError(
            "preprocessing runs pymeshlab on the whole input: not with max_memory/dask"
        )
    if _kernels.resolve(backend) != "compiled":
        raise InputError("out-of-core detection needs the compiled kernels (backend 'compiled')")
    t0 = time.perf_counter()
    if isinstance(source, PointSource):
        points = source
    elif isinstance(source, str | os.PathLike):
        if faces is not None:
            raise InputError("faces are taken from the file; do not pass faces with a path")
        points = open_points(source, as_points=as_points)
    else:
        geometry = as_input(source, faces, as_points)
        if geometry.is_mesh and not as_points:
            raise InputError(
                f"{geometry.source}: a mesh; out-of-core detection (max_memory, dask) "
                "handles point clouds only: pass as_points=True, or no max_memory"
            )
        points = PointSource.from_array(geometry.vertices, geometry.source)
    scales_t = check_scales(scales, DEFAULT_KNN_SCALES, "points")
    bar = progress if isinstance(progress, Progress) else Progress(1, enabled=bool(progress))

    sized: list[bool] = []

    def on_tile(label: str, done: int, total: int) -> None:
        if not sized:  # one bar step per tile task
            bar.total, bar.done = total * STEPS[mode] + 1, 0
            sized.append(True)
        bar.step(f"{label} {done}/{total}")

    out = detect_tiled(
        points,
        scales=scales_t,
        weighting=weighting,
        mode=mode,
        max_memory=max_memory,
        dask=dask,
        scratch=scratch,
        on_tile=on_tile,
        workers=workers,
    )
    if not isinstance(progress, Progress):
        bar.close()
    timings = {"load": 0.0, **out["timings"]}
    found = None
    if curves:
        t = time.perf_counter()
        found = curves_out_of_core(points, out["mask"], out["kept"], "compiled")
        timings["curves"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    return DetectionResult(
        mask=out["mask"],
        strength=out["strength"],
        kind="points",
        scales=out["scales"],
        thresholds=out["thresholds"],
        candidate_counts=out["candidate_counts"],
        kept=out["kept"],
        weighting=weighting,
        n_clean=out["n_clean"],
        timings=timings,
        mode=mode,
        tiling=out["tiling"],
        curves=None if found is None else found[0],
        corners=None if found is None else found[1],
        backend="compiled",
    )


def _paper(
    runner: Runner, store: Store, layout: Any, scales: tuple[int, ...], weighting: str
) -> tuple[np.ndarray, np.ndarray, str, str | None, tuple[int, ...]]:
    """The paper's method: distances, global min-max, histograms, decision."""
    n, s = layout.n, len(scales)
    store.create("pdis", (n, s), np.float64)
    store.create("mask", (n,), bool)
    store.create("strength", (n,), np.float64)
    query = Query(max(scales), scales=scales, weighting=weighting)
    ranges = runner.step(Step("distances", paper_distances, query, {"s": s}))
    flat = _kernels.flat_span(layout.hi - layout.lo)
    norm = {"lo": ranges["pdis_min"], "hi": ranges["pdis_max"], "flat": flat}
    hist = runner.step(Step("histograms", paper_histograms, None, norm))["hist"]
    thresholds = np.array([_kernels.stage_threshold(h, True, 0.0) for h in hist])
    decided = runner.step(Step("decide", paper_decide, None, {**norm, "thresholds": thresholds}))
    return thresholds, decided["counts"], "mask", None, scales


def _robust(
    runner: Runner, store: Store, layout: Any, scales: tuple[int, ...], weighting: str
) -> tuple[np.ndarray, np.ndarray, str, str | None, tuple[int, ...]]:
    """Robust mode (:mod:`meshlab_sharp.robust`) on a cloud, step by step, with the
    in-memory run's compiled passes and decisions (``ms_robust_plan``, once the noise is
    measured: the scales, thresholds, acute tips, lists and ranking): a pass over every
    point, which finds the isolated points and, when there are none and the noise does
    not grow the scales, everything else too; then, if there are isolated points, again
    over the kept points whose k nearest held one (the others' lists are unchanged); and
    if the noise grows the scales, over the kept points at the grown scales."""
    n = layout.n
    for name, shape, dtype in (
        ("nn1", (n,), np.int64),
        ("kd2", (n,), np.float64),
        ("kid", (n,), np.int64),
        ("kpos", (n,), np.int64),
        ("nd2", (n,), np.float64),
        ("rd2", (n,), np.float64),
        ("kept", (n,), bool),
        ("ratio", (n,), np.float64),
        ("r", (n, len(scales)), np.float64),
        ("score", (n,), np.float64),
        ("mask", (n,), bool),
        ("strength", (n,), np.float64),
        ("e", (n, 3), np.float64),
        ("mask1", (n,), bool),
        ("final", (n,), bool),
        ("lined", (n,), bool),
    ):
        store.create(name, shape, dtype)
    top = max(scales)
    passes = {"weighting": weighting, "robust": True}
    query = Query(top, scales=scales, **passes)
    hist = runner.step(Step("pass", robust_pass, query, {"first": True}))["hist"]
    found = runner.step(Step("isolated", robust_isolated))
    isolated = int(found["isolated"])
    n_kept = layout.n_clean - isolated
    if n_kept < top:
        raise InputError(
            f"{n_kept} points are not isolated, fewer than the largest scale k = {top}"
        )
    if isolated:
        store.create("redo", (n,), bool)
        lone = {"lone": found["lone_cat"]}
        redone = int(runner.step(Step("affected", robust_affected, None, lone))["redo"])
        runner.notes["redone"] = redone
        if redone:
            again = Query(top, "kept", "redo", scales, **passes)
            runner.step(Step("pass kept", robust_pass, again, {"first": False}))
        hist = runner.step(Step("histograms", robust_histograms))["hist"]
    nu = order_statistic(runner, "ratio", "kept", (n_kept - 1) // 2)
    plan = _kernels.robust_plan(nu, n_kept, scales, False)  # every decision below
    if plan.grown:  # the tiles are sized for one at a time at the grown scales
        runner.at_once = 1
        store.create("r", (n, len(plan.scales)), np.float64)
        grown = Query(max(plan.scales), "kept", None, plan.scales, **passes)
        hist = runner.step(Step("pass grown", robust_pass, grown, {"first": False}))["hist"]
    thresholds = _kernels.plan_thresholds(plan, hist)
    decided = runner.step(Step("decide", robust_decide, None, {"thresholds": thresholds}))
    top, compare = max(plan.scales), plan.compare_knn
    if plan.acute_tests:  # tips of acute edges
        for name in ("tested", "tip"):
            store.create(name, (n,), bool)
        tested = runner.step(Step("acute tests", robust_acute_tests, None, {"plan": plan}))
        if int(tested["tested"]):
            tips = Query(compare, "kept", "tested", hint="kd2")
            runner.step(Step("acute tips", robust_acute_tips, tips, {"compare": compare}))
            runner.step(Step("acute join", robust_acute_join))
    near = Query(top, "kept", "mask", save="lists", hint="kd2")
    runner.step(Step("support", robust_support, near, {"plan": plan}))
    reuse = Query(compare, "kept", "mask1", reuse="lists")  # mask1: a subset of mask
    ranking = "score"
    if plan.ranking_smoothed:  # thinning compares the rows of mask1 only
        ranking = "rank"
        store.create(ranking, (n,), np.float64)
        runner.step(Step("rank", robust_rank, reuse, {"plan": plan}))
    runner.step(Step("thin", robust_thin, reuse, {"plan": plan, "ranking": ranking}))
    if not plan.thin_line:
        return thresholds, decided["counts"], "final", "kept", plan.scales
    kept = Query(compare, "kept", "final", reuse="lists")  # final: a subset of mask1
    runner.step(Step("line", robust_line, kept, {"plan": plan, "ranking": ranking}))
    return thresholds, decided["counts"], "lined", "kept", plan.scales


def _resident() -> int:
    """Resident memory of this process now, bytes."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return peak_rss()


def _client(dask: str | Any, stack: ExitStack) -> Any:
    """A Dask client for ``dask`` (None: none); closed with ``stack``."""
    if dask is None:
        return None
    distributed = require("dask.distributed", "--dask", "dask")
    if not isinstance(dask, str):
        if not isinstance(dask, distributed.Client):
            raise TypeError(
                "dask= must be 'local:N', 'tcp://HOST:PORT' or a dask.distributed.Client, "
                f"not {type(dask).__name__}"
            )
        return dask
    if dask.startswith("local:"):
        try:
            n = int(dask.split(":", 1)[1])
        except ValueError:
            n = 0
        if n < 1:
            raise InputError(f"--dask {dask}: write local:N with N >= 1 workers")
        with require("dask", "--dask", "dask").config.set(LOCAL_WORKER_CONFIG):
            cluster = stack.enter_context(
                distributed.LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address="127.0.0.1:0",
                    host="127.0.0.1",
                    silence_logs=logging.getLogger("distributed").getEffectiveLevel(),
                )
            )
        return stack.enter_context(distributed.Client(cluster))
    return stack.enter_context(connect(dask))
