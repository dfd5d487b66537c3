"""Running the steps over the tiles: a few at a time on threads, or as Dask tasks.

A tile task is :func:`tile_task` (a module-level function of picklable arguments), so
that it runs the same in this process or on a Dask worker; the partials it returns are
reduced with :func:`meshlab_sharp.tiles.steps.combine`, locally or as a Dask tree
reduction.
"""

from __future__ import annotations

import itertools
import resource
import sys
import time
from collections.abc import Callable, Mapping
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _kernels
from .cluster import cluster_failures, completed
from .layout import Layout
from .neighbours import neighbours
from .steps import Partial, Span, Step, combine, finish
from .store import Store


def peak_rss() -> int:
    """Peak resident memory of this process so far, bytes.

    On Linux the high-water mark of the process's address space (``VmHWM``), not
    ``ru_maxrss``: a process started by ``vfork`` + ``exec`` (Python's ``subprocess``,
    Dask's worker processes) inherits its parent's peak in ``ru_maxrss``, so a small
    child of a large process (a test in a long pytest run) would report the
    parent's memory as its own.
    """
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) * (1 if sys.platform == "darwin" else 1024)


@dataclass(frozen=True)
class Outcome:
    """What a tile task returns: the partial, the halo that held, points searched, rows
    that took the streaming route, the process's peak memory, the task's own seconds,
    the threads of its searches."""

    partial: Partial
    halo: float
    gathered: int
    streamed: int
    peak: int
    seconds: float
    threads: int


def tile_task(
    step: Step,
    store: Store,
    layout: Layout,
    tile: int,
    halo: float,
    most_points: int,
    workers: int,
    sharing: Mapping[str, int] | None = None,
) -> Outcome:
    """Run ``step`` on one tile with ``workers`` threads; on a Dask worker (``sharing``
    given: threads of the workers per machine) ``workers <= 0`` is
    :func:`task_threads` of the worker's machine."""
    started = time.perf_counter()
    if sharing is not None and workers <= 0:
        from distributed import get_worker
        from distributed.comm import get_address_host

        worker = get_worker()
        share = sharing.get(get_address_host(worker.address), worker.state.nthreads)
        workers = task_threads(_kernels._workers(-1), share)
    if step.query is None:
        a, b = int(layout.offsets[tile]), int(layout.offsets[tile + 1])
        partial = step.fn(Span(store, a, b), **step.params)
        used, gathered, streamed = halo, b - a, 0
    else:
        contexts, used, gathered, streamed = neighbours(
            store, layout, tile, step.query, halo=halo, most_points=most_points, workers=workers
        )
        partial = combine([step.fn(ctx, **step.params) for ctx in contexts])
    seconds = time.perf_counter() - started
    return Outcome(partial, used, gathered, streamed, peak_rss(), seconds, workers)


def warm_up(client: Any) -> list[Any]:
    """Futures of a no-op task on each of the cluster's workers: loading it imports
    meshlab_sharp there (numpy, scipy, pymeshlab, the compiled kernels: about a
    second), all workers at once, instead of in each worker's first tile task."""
    return [
        client.submit(_ready, workers=[address], allow_other_workers=True, pure=False)
        for address in client.scheduler_info(n_workers=-1)["workers"]
    ]


def _ready() -> None:
    """Nothing: :func:`warm_up`'s task."""


def task_threads(cores: int, sharing: int) -> int:
    """Threads of a tile task's searches on a Dask worker: the cores of its machine
    shared by the threads of the workers on it (each runs a task at a time), at least
    one. ``dask worker --nworkers 8 --nthreads 1`` on 8 cores: one each, not 8 x 8."""
    return max(1, cores // max(1, sharing))


def machine_threads(client: Any) -> dict[str, int]:
    """Threads of the cluster's workers per machine (host), as the scheduler knows
    them now."""
    out: dict[str, int] = {}
    for info in client.scheduler_info(n_workers=-1)["workers"].values():
        out[info["host"]] = out.get(info["host"], 0) + int(info["nthreads"])
    return out


class Runner:
    """Runs steps on every tile and reduces their partials.

    Parameters
    ----------
    store, layout
    most_points : int
        Largest box a halo may widen to.
    workers : int
        Threads of a Dask tile task's kNN search (<= 0: :func:`task_threads` of its
        machine); in this process, of the searches of the tiles run at once together.
    at_once : int
        Tiles run at the same time in this process (no client), at most ``workers``.
    on_tile : callable, optional
        ``on_tile(label, tile, n_tiles)`` after each tile (progress).
    client : dask.distributed.Client, optional
        Run the tiles as Dask tasks on this client.
    """

    def __init__(
        self,
        store: Store,
        layout: Layout,
        *,
        most_points: int,
        workers: int,
        at_once: int = 1,
        on_tile: Callable[[str, int, int], None] | None = None,
        client: Any = None,
    ) -> None:
        self.store = store
        self.layout = layout
        self.most_points = most_points
        self.workers = workers
        #: Tiles at a time in this process (no more than the threads); a mode may
        #: lower it between steps.
        self.at_once = max(1, min(int(at_once), _kernels._workers(workers)))
        self.on_tile = on_tile
        self.client = client
        self.halos = np.zeros(layout.n_tiles)
        self.peak = 0
        self.tasks = 0
        self.gathered = 0
        self.streamed = 0
        #: Most threads a tile task's searches used.
        self.threads = 0
        self.seconds: dict[str, float] = {}
        self.task_seconds: dict[str, float] = {}
        #: Counts a mode reports in the summary (robust mode: ``redone``).
        self.notes: dict[str, int] = {}
        #: Threads of the workers per machine (Dask), for :func:`task_threads`.
        self.sharing = None if client is None else machine_threads(client)

    def step(self, step: Step) -> Partial:
        """Run ``step`` on every tile; the reduced partial."""
        n = self.layout.n_tiles
        started = time.perf_counter()
        if self.client is None:
            outcomes = self._local(step, n)
            reduced = combine([o.partial for o in outcomes])
        else:
            with cluster_failures(step.label):
                outcomes, reduced = self._dask(step, n)
        for t, o in enumerate(outcomes):
            self.halos[t] = max(self.halos[t], o.halo)
            self.peak = max(self.peak, o.peak)
            self.gathered = max(self.gathered, o.gathered)
            self.streamed += o.streamed
            self.threads = max(self.threads, o.threads)
        self.tasks += n
        label = step.label
        self.seconds[label] = self.seconds.get(label, 0.0) + time.perf_counter() - started
        busy = sum(o.seconds for o in outcomes)
        self.task_seconds[label] = self.task_seconds.get(label, 0.0) + busy
        return reduced

    def _halo(self, t: int, guess: float) -> float:
        """Tile ``t``'s first halo: its own from an earlier step, else ``guess``."""
        return float(self.halos[t]) if self.halos[t] > 0 else guess

    def _dask(self, step: Step, n: int) -> tuple[list[Outcome], Partial]:
        """The outcomes of ``step`` on the tiles ``0..n-1`` as Dask tasks, and their
        partials reduced by a Dask task. First halos as in :meth:`_local`: without any
        (a first search step), the first tile runs alone and its halo is every other
        tile's guess (a tile started with no halo searches twice)."""
        assert self.client is not None
        args = (self.most_points, self.workers, self.sharing)
        guess = float(self.halos.max(initial=0.0))

        def submit(t: int) -> Any:
            halo = self._halo(t, guess)
            task = (tile_task, step, self.store, self.layout, t, halo, *args)
            return self.client.submit(*task, pure=False)

        futures = []
        if step.query is not None and guess == 0.0 and n > 0:
            futures.append(submit(0))
            guess = next(completed(self.client, futures)).result().halo
        futures += [submit(t) for t in range(len(futures), n)]
        partials = [self.client.submit(_partial, f) for f in futures]
        total = self.client.submit(_combine_all, partials)
        for done, f in enumerate(completed(self.client, futures), start=1):
            f.result()
            if self.on_tile is not None:
                self.on_tile(step.label, done, n)
        return self.client.gather(futures), next(completed(self.client, [total])).result()

    def _local(self, step: Step, n: int) -> list[Outcome]:
        """The outcomes of ``step`` on the tiles ``0..n-1`` in this process, ``at_once``
        tiles at a time on threads (ctypes and numpy release the GIL: one tile's Python
        work and reads overlap another's compiled pass), the searches sharing the
        ``workers`` threads. A tile's first halo is the widest that held in the tiles
        done so far (or its own from an earlier step): a guess, proven per point either
        way; without any, the first tile runs alone and gives one."""
        threads = max(1, _kernels._workers(self.workers) // self.at_once)
        args = (self.most_points, threads)
        outcomes: dict[int, Outcome] = {}
        guess = float(self.halos.max(initial=0.0))

        def submit(pool: ThreadPoolExecutor, t: int) -> Future[Outcome]:
            halo = self._halo(t, guess)
            return pool.submit(tile_task, step, self.store, self.layout, t, halo, *args)

        first = 1 if step.query is not None and guess == 0.0 else self.at_once
        with ThreadPoolExecutor(max_workers=self.at_once) as pool:
            running = {submit(pool, t): t for t in range(min(first, n))}
            queued = iter(range(len(running), n))
            while running:
                finished, _ = wait(running, return_when=FIRST_COMPLETED)
                for f in finished:
                    o = outcomes[running.pop(f)] = f.result()
                    if step.query is not None:
                        guess = max(guess, o.halo)
                    if self.on_tile is not None:
                        self.on_tile(step.label, len(outcomes), n)
                for t in itertools.islice(queued, self.at_once - len(running)):
                    running[submit(pool, t)] = t
        return [outcomes[t] for t in range(n)]

    def finish(self, n: int, mask: str, kept: str | None) -> dict[str, np.ndarray]:
        """Per input point (input order): mask, strength, kept; read here from the
        store, with Dask too (the driver wrote the tiles there: no per-point array
        goes through the workers and the scheduler)."""
        out = {
            "mask": np.zeros(n, bool),
            "strength": np.zeros(n),
            "kept": np.zeros(n, bool),
        }
        offsets = self.layout.offsets
        for t in range(self.layout.n_tiles):
            span = Span(self.store, int(offsets[t]), int(offsets[t + 1]))
            part = finish(span, mask=mask, kept=kept)
            for key in ("mask", "strength", "kept"):
                out[key][part["ids"]] = part[key]
        return out


def _partial(outcome: Outcome) -> Partial:
    return outcome.partial


def _combine_all(parts: list[Partial]) -> Partial:
    return combine(parts)
