"""Spatial tiles: the cloud sorted into boxes of about ``tile_points`` points each.

Built in three streaming passes over the input, ``chunk`` points at a time:

1. take the bounding box, checking that the coordinates are finite;
2. count the points in the cells of a ``GRID**3`` grid over the box, keeping every
   point's cell in a scratch array of the store;
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


@dataclass
class Layout:
    """Where every tile's points are.

    Attributes
    ----------
    n : int
        Input points.
    lo, hi : (3,) float64
        Bounding box of all points.
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
        called three times.
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
    for block in chunks():
        # a NaN or an infinity shows in the block's minimum or maximum
        blo, bhi = bounds(block)
        if not (np.isfinite(blo).all() and np.isfinite(bhi).all()):
            bad = seen + int(np.flatnonzero(~np.isfinite(block).all(axis=1))[0])
            raise InputError(f"{source}: point {bad} has a non-finite coordinate")
        lo = np.minimum(lo, blo)
        hi = np.maximum(hi, bhi)
        samples.append(block[(-seen) % step :: step])
        seen += len(block)
    if seen != n:
        raise InputError(f"{source}: {seen} points read, the header says {n}")
    # far points (neighbourhoods.far_points) are left out of every tile, as the
    # in-memory run drops them: no tile holds them, the outputs leave them out
    bulk = far_reach(np.concatenate(samples))
    del samples
    if bulk is not None and max(float((hi - bulk[0]).max()), float((bulk[0] - lo).max())) > bulk[1]:
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for block in chunks():
            near = block[~is_far(block, *bulk)]
            if len(near):
                blo, bhi = bounds(near)
                lo, hi = np.minimum(lo, blo), np.maximum(hi, bhi)
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

    cells = np.zeros(GRID**3, np.int64)
    store.create("cell", (n,), np.uint32)
    start = 0
    for block in chunks():
        near = near_of(block)
        cell = np.zeros(len(block), np.int64)
        cell[near] = _cells(unit(block[near]), lo, hi)
        cells += np.bincount(cell[near], minlength=GRID**3)
        store.write("cell", start, cell.astype(np.uint32))
        start += len(block)
    leaves = _split(cells.reshape(GRID, GRID, GRID), tile_points)
    # uint16 tiles sort by radix (numpy's stable sort of 16-bit integers); empty cells
    # (in no tile) keep the dtype's largest value
    kind = np.dtype(np.uint16 if len(leaves) < (1 << 16) - 1 else np.int64)
    table = np.full((GRID, GRID, GRID), np.iinfo(kind).max, kind)
    grid_counts = cells.reshape(GRID, GRID, GRID)
    sizes = []
    for t, (clo, chi) in enumerate(leaves):
        box = (slice(clo[0], chi[0]), slice(clo[1], chi[1]), slice(clo[2], chi[2]))
        table[box] = t
        sizes.append(int(grid_counts[box].sum()))
    table = table.reshape(-1)
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


def _cells(block: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Grid cell (flat index) of each point of ``block`` (c, 3)."""
    extent = np.where(hi > lo, hi - lo, 1.0)
    c = np.floor((block - lo) / extent * GRID).astype(np.int64)
    np.clip(c, 0, GRID - 1, out=c)
    return (c[:, 0] * GRID + c[:, 1]) * GRID + c[:, 2]


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
