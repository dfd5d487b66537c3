"""Spatial tiles: the cloud sorted into boxes of about ``tile_points`` points each.

Built in three streaming passes over the input, ``chunk`` points at a time:

1. take the bounding box, checking that the coordinates are finite;
2. count the points in the cells of a ``GRID**3`` grid over the box, keeping every
   point's cell in a scratch array of the store; when one cell then holds more than a
   tile (far outliers stretch the box and squeeze the cloud into a few cells), count
   again on a grid over the box of the points' central quantiles (:data:`TAILS`,
   widened by :data:`MARGIN`); the points outside
   that box go to one of 26 outer cells (below, inside or above it on each axis), each
   its own tile, so the tiles of the cloud keep tight boxes;
3. split the grid's cells into boxes of at most ``tile_points`` points (k-d splits at
   the weighted median), then write every point's coordinates and input index to its
   tile's range of positions, in increasing input index within a tile (a stable
   counting sort of each chunk by tile, written as one run per tile).

Exact duplicates share their coordinates, hence their cell and tile: each tile merges
its own duplicates into their first occurrence, which is the first occurrence in the
whole input, exactly as the in-memory cleaning does.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from .. import _kernels
from ..errors import InputError
from ..neighbourhoods import far_reach, far_step, is_far, unit_exponent
from .store import Store

#: Cells per axis of the grid the tiles are made of.
GRID = 64
#: Points per axis of the sample whose quantiles give the grid's box when the bounding
#: box leaves a cell with more than a tile: at most this many, taken evenly.
SAMPLE = 100_000
#: Those quantiles, tried in turn until no cell holds more than a tile: the grid spans
#: the central 1 - 2 * tail of the sample on each axis, widened by MARGIN times that
#: span on each side (the cloud's own points near its edges stay on the grid).
TAILS = (0.01, 0.1)
MARGIN = 0.5


@dataclass
class Layout:
    """Where every tile's points are.

    Attributes
    ----------
    n : int
        Input points.
    lo, hi : (3,) float64
        Bounding box of the points that are not far, in the store's unit.
    offsets : (t + 1,) int64
        Tile ``i`` holds positions ``offsets[i]:offsets[i + 1]`` of the store's arrays.
    boxes : (t, 2, 3) float64
        Bounding box of each tile's points (min row, max row).
    n_clean : int
        Distinct points.
    """

    n: int
    lo: np.ndarray
    hi: np.ndarray
    offsets: np.ndarray
    boxes: np.ndarray
    n_clean: int

    @property
    def n_tiles(self) -> int:
        """Number of (non-empty) tiles."""
        return len(self.offsets) - 1

    def counts(self) -> np.ndarray:
        """Points (with duplicates) in each tile, shape (t,)."""
        return np.diff(self.offsets)

    def tiles_meeting(self, blo: np.ndarray, bhi: np.ndarray) -> np.ndarray:
        """Tiles whose box meets the box ``[blo, bhi]``, shape (r,) int."""
        meet = np.all((self.boxes[:, 0] <= bhi) & (self.boxes[:, 1] >= blo), axis=1)
        return np.flatnonzero(meet)


def build_layout(
    n: int,
    chunks: Callable[[], Iterator[np.ndarray]],
    store: Store,
    *,
    tile_points: int,
    source: str,
) -> Layout:
    """Sort the input into tiles; fills the store's ``coords`` (m, 3), ``ids`` (m,) and
    ``rep`` (m,) (position of each point's first occurrence) in tile order: the m points
    that are not far (:func:`meshlab_sharp.neighbourhoods.far_points`), coordinates in
    the unit of an in-memory run (:func:`meshlab_sharp.neighbourhoods.unit_scale`).

    Parameters
    ----------
    n : int
        Number of input points.
    chunks : callable
        ``chunks()`` yields the input's coordinates, (c, 3) float64 blocks in order;
        called once per pass (three to six times).
    store : Store
    tile_points : int
        Most points of a tile (a tile that is one grid cell may hold more).
    source : str
        Name of the input, for error messages.
    """
    if n == 0:
        raise InputError(f"{source}: no points")
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    seen = 0
    step = far_step(n)
    samples = []
    every = max(1, -(-n // SAMPLE))
    sample = []
    for block in chunks():
        # a NaN or an infinity shows in the block's minimum or maximum
        blo, bhi = bounds(block)
        if not (np.isfinite(blo).all() and np.isfinite(bhi).all()):
            bad = seen + int(np.flatnonzero(~np.isfinite(block).all(axis=1))[0])
            raise InputError(f"{source}: point {bad} has a non-finite coordinate")
        lo = np.minimum(lo, blo)
        hi = np.maximum(hi, bhi)
        samples.append(block[(-seen) % step :: step])
        sample.append(block[(-seen) % every :: every])
        seen += len(block)
    if seen != n:
        raise InputError(f"{source}: {seen} points read, the header says {n}")
    # far points (neighbourhoods.far_points) are left out of every tile, as the
    # in-memory run drops them: no tile holds them, the outputs leave them out
    bulk = far_reach(np.concatenate(samples))
    del samples
    picked = np.concatenate(sample)
    del sample
    if bulk is not None and max(float((hi - bulk[0]).max()), float((bulk[0] - lo).max())) > bulk[1]:
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for block in chunks():
            near = block[~is_far(block, *bulk)]
            if len(near):
                blo, bhi = bounds(near)
                lo, hi = np.minimum(lo, blo), np.maximum(hi, bhi)
        picked = picked[~is_far(picked, *bulk)]
    else:
        bulk = None

    def near_of(block: np.ndarray) -> np.ndarray | slice:
        """The points of ``block`` that are not far (all: a slice, no copy)."""
        return slice(None) if bulk is None else np.flatnonzero(~is_far(block, *bulk))

    # the store holds the coordinates in the unit of an in-memory run (unit_scale): the
    # same neighbourhoods and decisions whatever the input's unit (1e-300 to 1e300)
    e = unit_exponent(max(float(np.abs(lo).max()), float(np.abs(hi).max())))
    lo, hi = np.ldexp(lo, -e), np.ldexp(hi, -e)

    def unit(block: np.ndarray) -> np.ndarray:
        """``block`` in the store's unit."""
        return np.ldexp(block, -e) if e else block

    picked = unit(picked)
    store.create("cell", (n,), np.uint32)
    cells = _count_cells(chunks, store, lo, hi, near_of, unit)
    for tail in TAILS:
        if cells[: GRID**3].max() <= tile_points:
            break
        q_lo, q_hi = np.quantile(picked, [tail, 1.0 - tail], axis=0)
        margin = MARGIN * (q_hi - q_lo)
        g_lo, g_hi = np.maximum(q_lo - margin, lo), np.minimum(q_hi + margin, hi)
        if (g_lo > lo).any() or (g_hi < hi).any():
            cells = _count_cells(chunks, store, g_lo, g_hi, near_of, unit)
    grid_counts = cells[: GRID**3].reshape(GRID, GRID, GRID)
    leaves = _split(grid_counts, tile_points)
    outer = np.flatnonzero(cells[GRID**3 :])
    # uint16 tiles sort by radix (numpy's stable sort of 16-bit integers); empty cells
    # (in no tile) keep the dtype's largest value
    kind = np.dtype(np.uint16 if len(leaves) + len(outer) < (1 << 16) - 1 else np.int64)
    table = np.full(len(cells), np.iinfo(kind).max, kind)
    grid_table = table[: GRID**3].reshape(GRID, GRID, GRID)
    sizes = []
    for t, (clo, chi) in enumerate(leaves):
        box = (slice(clo[0], chi[0]), slice(clo[1], chi[1]), slice(clo[2], chi[2]))
        grid_table[box] = t
        sizes.append(int(grid_counts[box].sum()))
    for region in outer:
        table[GRID**3 + region] = len(sizes)
        sizes.append(int(cells[GRID**3 + region]))
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    kept = int(offsets[-1])
    store.create("coords", (kept, 3), np.float64)
    store.create("ids", (kept,), np.int64)
    store.create("rep", (kept,), np.int64)
    cursor = offsets[:-1].copy()
    start = 0
    for block in chunks():
        near = near_of(block)
        tile = table[store.read("cell", start, start + len(block))[near]]
        order = np.argsort(tile, kind="stable")
        if bulk is not None:
            order = near[order]
        per = np.bincount(tile, minlength=len(sizes))
        runs = np.concatenate([[0], np.cumsum(per)])
        xyz, ids = unit(block[order]), start + order
        for t in np.flatnonzero(per):
            a, b = runs[t], runs[t + 1]
            store.write("coords", int(cursor[t]), xyz[a:b])
            store.write("ids", int(cursor[t]), ids[a:b])
        cursor += per
        start += len(block)
    store.remove("cell")
    boxes = np.empty((len(sizes), 2, 3))
    n_clean = 0
    for t in range(len(sizes)):
        a, b = int(offsets[t]), int(offsets[t + 1])
        pts = store.read("coords", a, b)
        boxes[t] = bounds(pts)
        to_first, from_first, _ = _kernels.merge_duplicates(pts)
        store.write("rep", a, a + to_first[from_first])
        n_clean += len(to_first)
    return Layout(n, lo, hi, offsets, boxes, n_clean)


def bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Minimum and maximum (3,) of ``points`` (c, 3), column by column (a reduce over
    the first axis of a (c, 3) array is many times slower); NaN where a column has one."""
    return (
        np.array([points[:, i].min() for i in range(3)]),
        np.array([points[:, i].max() for i in range(3)]),
    )


def _count_cells(
    chunks: Callable[[], Iterator[np.ndarray]],
    store: Store,
    lo: np.ndarray,
    hi: np.ndarray,
    near_of: Callable[[np.ndarray], np.ndarray | slice],
    unit: Callable[[np.ndarray], np.ndarray],
) -> np.ndarray:
    """Points per cell of the grid over the box ``[lo, hi]`` and of its 27 outer cells
    (:func:`_cells`), (GRID**3 + 27,) int64; every point's cell in the store's ``cell``.
    Only the points ``near_of(block)`` count, at their coordinates ``unit(...)`` (the
    others are in no tile: their cell is read nowhere)."""
    cells = np.zeros(GRID**3 + 27, np.int64)
    start = 0
    for block in chunks():
        near = near_of(block)
        cell = np.zeros(len(block), np.int64)
        cell[near] = _cells(unit(block[near]), lo, hi)
        cells += np.bincount(cell[near], minlength=len(cells))
        store.write("cell", start, cell.astype(np.uint32))
        start += len(block)
    return cells


def _cells(block: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Grid cell (flat index) of each point of ``block`` (c, 3) in the box ``[lo, hi]``;
    a point outside the box: ``GRID**3 + 9 * ax + 3 * ay + az``, each digit 0 below the
    box, 1 within, 2 above it on that axis."""
    extent = np.where(hi > lo, hi - lo, 1.0)
    c = np.floor((block - lo) / extent * GRID).astype(np.int64)
    np.clip(c, 0, GRID - 1, out=c)
    flat = (c[:, 0] * GRID + c[:, 1]) * GRID + c[:, 2]
    side = (block > hi).astype(np.int64) - (block < lo)
    if not side.any():
        return flat
    region = 9 * side[:, 0] + 3 * side[:, 1] + side[:, 2] + 13
    return np.where(region == 13, flat, GRID**3 + region)


def _split(counts: np.ndarray, most: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Boxes of cells ``[lo, hi)`` holding at most ``most`` points each (single cells
    excepted), empty boxes left out; k-d splits of the longest side at the median."""
    prefix = np.zeros(tuple(s + 1 for s in counts.shape), np.int64)
    prefix[1:, 1:, 1:] = counts.cumsum(0).cumsum(1).cumsum(2)

    def total(lo: np.ndarray, hi: np.ndarray) -> int:
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        p = prefix
        return int(
            p[x1, y1, z1] - p[x0, y1, z1] - p[x1, y0, z1] - p[x1, y1, z0]
            + p[x0, y0, z1] + p[x0, y1, z0] + p[x1, y0, z0] - p[x0, y0, z0]
        )  # fmt: skip

    out: list[tuple[np.ndarray, np.ndarray]] = []
    stack = [(np.zeros(3, np.int64), np.array(counts.shape, np.int64))]
    while stack:
        lo, hi = stack.pop()
        count = total(lo, hi)
        if count == 0:
            continue
        side = hi - lo
        if count <= most or side.max() == 1:
            out.append((lo, hi))
            continue
        axis = int(np.argmax(side))
        below = []
        for c in range(lo[axis] + 1, hi[axis]):
            h = hi.copy()
            h[axis] = c
            below.append(total(lo, h))
        cut = lo[axis] + 1 + int(np.searchsorted(np.array(below), count / 2.0))
        cut = min(max(cut, lo[axis] + 1), hi[axis] - 1)
        left_hi, right_lo = hi.copy(), lo.copy()
        left_hi[axis] = right_lo[axis] = cut
        stack.append((right_lo, hi))
        stack.append((lo, left_hi))
    out.sort(key=lambda box: tuple(box[0]))
    return out
