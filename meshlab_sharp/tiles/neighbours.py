"""Exact k nearest neighbours of a tile's points, from the tile and a halo around it.

A point's k nearest neighbours found among the points of a box are its k nearest in the
whole cloud when the ball of its k-th neighbour distance lies inside the box: every
point outside the box is then farther than the k-th. This is checked for every point
(with a relative margin of 1e-9 against rounding). Where it fails the halo is widened
to hold the failing points' balls (their distance inside the box bounds the true one
from above) and the search is run again. Points whose balls would need a box of more
than ``most_points`` points (far outliers) take a streaming route instead: every tile
near enough is searched in turn and the k best kept, then their neighbourhood is
computed on exactly those k points.

The points of a box are ordered by input index, which is the cleaned order, so that
ties in distance are broken as in the in-memory run; the neighbour lists, projected
distances and everything computed from them are then bit for bit the same.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .. import _kernels, robust
from ..errors import InputError
from ..neighbourhoods import Neighbourhood, squared_distances
from ..normals import DEFAULT_WEIGHTING
from .layout import Layout, bounds
from .store import Store

#: Relative margin of the ball-in-box test.
MARGIN = 1e-9
#: Widenings of a tile's halo before its failing points take the streaming route.
ROUNDS = 4
#: A search for rows fewer than this share of the points builds its tree over the
#: points near them only (:func:`_knn_near`).
NEAR_SHARE = 0.125


@dataclass(frozen=True)
class Query:
    """What neighbourhoods a step needs.

    Attributes
    ----------
    k : int
        Neighbours per point (the point itself first).
    kept : str or None
        Store array (bool) of the points searched; None: every distinct point.
    rows : str or None
        Store array (bool) of the points whose neighbours are needed; None: every
        searched point.
    scales : tuple of int or None
        Also the projected distances at these kNN scales (``k == max(scales)``).
    weighting : str
    robust : bool
        Robust mode's compiled pass at ``scales`` instead of the projected distances:
        the relative distances, the score, the noise ratio and the nearest and k-th
        neighbours (:func:`meshlab_sharp._kernels.cloud_projected_distances`), from the
        search itself (no kNN table).
    save : str or None
        Keep the rows' lists (store positions) under this name, per tile
        (:meth:`Store.put`), for a later query to reuse.
    reuse : str or None
        No search: the first ``k`` of the lists an earlier query saved under this name,
        of its rows that are this query's rows (a subset of them, ``k`` at most the
        earlier ``k``: the k nearest are a prefix of the earlier k nearest).
    hint : str or None
        Store array of estimates of the points' squared k-th neighbour distances: a
        search for a few rows then builds its tree over the points near them only
        (:func:`_knn_near`; the estimates set the first reach, never the answer).
    """

    k: int
    kept: str | None = None
    rows: str | None = None
    scales: tuple[int, ...] | None = None
    weighting: str = DEFAULT_WEIGHTING
    robust: bool = False
    save: str | None = None
    reuse: str | None = None
    hint: str | None = None


@dataclass
class Context:
    """Exact neighbourhoods of some points (the rows) inside a set of points.

    Attributes
    ----------
    store : Store
    points : (L, 3) float64
        The set, in increasing input index.
    pos : (L,) int64
        Store positions of the set's points.
    rows : (r,) int64
        Increasing local indices of the points whose neighbourhoods are exact.
    idx : (r, k) int64 or None
        Local indices of their k nearest, sorted by (squared distance, input index)
        (None after a robust pass).
    found : dict of str to array
        What the query's pass computed for the rows (first axis r): ``pdis`` (r, s)
        (paper); ``near``, ``kth_d2``, ``kth_idx``, ``nth_d2``, ``ref_d2``, ``noise``
        (r,), ``relative`` (r, s), ``score`` (r,) (robust pass; ``near`` and ``kth_idx``
        local indices).
    """

    store: Store
    points: np.ndarray
    pos: np.ndarray
    rows: np.ndarray
    idx: np.ndarray | None
    found: dict[str, np.ndarray] = field(default_factory=dict)

    def gather(self, name: str) -> np.ndarray:
        """Store array ``name`` at the set's points, (L, ...)."""
        return self.store.read_at(name, self.pos)

    def lists(self, k: int, part: slice = slice(None)) -> Neighbourhood:
        """CSR lists over the whole set: the k nearest of the rows (of ``rows[part]``),
        empty lists for the other points."""
        assert self.idx is not None
        sizes = np.zeros(len(self.points), np.int64)
        sizes[self.rows[part]] = k
        indptr = np.concatenate([[0], np.cumsum(sizes)])
        return Neighbourhood(indptr, np.ascontiguousarray(self.idx[part, :k]).reshape(-1))

    @property
    def own(self) -> np.ndarray:
        """Store positions of the rows, (r,)."""
        return self.pos[self.rows]


def gather(
    store: Store,
    layout: Layout,
    tiles: np.ndarray,
    blo: np.ndarray,
    bhi: np.ndarray,
    kept: str | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distinct (and kept) points of ``tiles`` inside ``[blo, bhi]``.

    Returns
    -------
    pos : (L,) int64, points : (L, 3) float64, ids : (L,) int64
        In increasing input index.
    """
    parts = []
    for t in tiles:
        a, b = int(layout.offsets[t]), int(layout.offsets[t + 1])
        pts = store.read("coords", a, b)
        # the points inside, an axis at a time where the tile's box sticks out (the
        # farthest first: a halo's slab of a neighbour tile leaves few for the others)
        tlo, thi = layout.boxes[t]
        out = np.maximum(blo - tlo, 0.0) + np.maximum(thi - bhi, 0.0)
        where = None
        for axis in np.argsort(-out, kind="stable")[: np.count_nonzero(out)]:
            col = pts[:, axis] if where is None else pts[where, axis]
            hit = (col >= blo[axis]) & (col <= bhi[axis])
            where = np.flatnonzero(hit) if where is None else where[hit]
        rep = store.read("rep", a, b)
        if where is None:
            where = np.flatnonzero(rep == np.arange(a, b))
        else:
            where = where[rep[where] == a + where]
        if kept is not None:
            where = where[store.read(kept, a, b)[where]]
        parts.append((a + where, pts[where], store.read("ids", a, b)[where]))
    if not parts:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int64)
    pos = np.concatenate([p[0] for p in parts])
    points = np.concatenate([p[1] for p in parts])
    ids = np.concatenate([p[2] for p in parts])
    order = np.argsort(ids, kind="stable")
    return pos[order], points[order], ids[order]


def _search(
    points: np.ndarray,
    rows: np.ndarray,
    query: Query,
    all_rows: bool,
    workers: int,
    hint: np.ndarray | None = None,
) -> tuple[np.ndarray | None, dict[str, np.ndarray], np.ndarray]:
    """k nearest (or the query's pass) of ``rows`` within ``points``: the kNN lists
    (None after a robust pass), what the pass found (:class:`Context`), and the rows'
    squared k-th neighbour distances (r,). The compiled passes compute the rows only
    (and a few points near them), not the halo. ``hint`` (r,): estimates of the rows'
    squared k-th neighbour distances (:attr:`Query.hint`)."""
    k = query.k
    if query.robust:
        assert query.scales is not None
        got = _kernels.cloud_projected_distances(
            _kernels.build_tree(points, workers),
            query.scales,
            query.weighting,
            relative=True,
            noise_k=min(robust.NOISE_KNN, k),
            isolated=(robust.ISOLATED_NTH, robust.ISOLATED_REF),
            sheet=robust.sheet_parameters(),
            workers=workers,
            rows=rows,
        )
        assert got.stats is not None and got.relative is not None and got.score is not None
        st = got.stats
        found = {
            "near": st.near[rows],
            "kth_d2": st.kth_d2[rows],
            "kth_idx": st.kth_idx[rows],
            "nth_d2": st.nth_d2[rows],
            "ref_d2": st.ref_d2[rows],
            "noise": st.noise[rows],
            "relative": np.ascontiguousarray(got.relative[:, rows].T),
            "score": got.score[rows],
        }
        return None, found, found["kth_d2"]
    found = {}
    if query.scales is not None:
        idx, pdis = _kernels.cloud_knn_projected_distances(
            _kernels.build_tree(points, workers), query.scales, query.weighting, workers, rows
        )
        found["pdis"] = np.ascontiguousarray(pdis[:, rows].T)
        idx = idx[rows]
    elif all_rows:
        idx = _kernels.cloud_knn(_kernels.build_tree(points, workers), k, workers, rows)[rows]
    else:  # a few rows: no table of the set
        idx = _knn_near(points, rows, k, workers, hint)
    return idx, found, squared_distances(points[idx[:, -1]], points[rows])


def _knn_near(
    points: np.ndarray, rows: np.ndarray, k: int, workers: int, hint: np.ndarray | None
) -> np.ndarray:
    """:func:`meshlab_sharp._kernels.cloud_knn_rows` of ``rows`` (r,) within ``points``
    (L, 3), (r, k) local indices, searching only the points near the rows when they are
    few and ``hint`` (r,) (squared distance estimates) is given.

    The points near are those of the cells, ``g`` wide, at or next to a row's cell: every
    point closer to a row than ``g``. A row whose k-th neighbour among them is closer
    than ``g`` (with a margin) has its exact k nearest, with the same ties (the subset
    keeps the order of the points); the others are searched again with ``g`` doubled,
    and after ``ROUNDS`` tries among all the points."""
    idx = np.empty((len(rows), k), np.int64)
    todo = np.arange(len(rows))
    if hint is not None and len(rows) < NEAR_SHARE * len(points) and len(hint):
        g = 2.0 * float(np.sqrt(np.max(hint)))
        for _ in range(ROUNDS):
            if not (np.isfinite(g) and g > 0.0):
                break
            near = _points_near(points, points[rows[todo]], g)
            if near is None or len(near) > 0.5 * len(points):
                break
            if len(near) >= k:
                sub = np.searchsorted(near, rows[todo])
                tree = _kernels.build_tree(points[near], workers)
                got = near[_kernels.cloud_knn_rows(tree, sub, k, workers)]
                d2 = squared_distances(points[got[:, -1]], points[rows[todo]])
                ok = np.sqrt(d2) < g * (1.0 - 1e-6)
                idx[todo[ok]] = got[ok]
                todo = todo[~ok]
                if len(todo) == 0:
                    return idx
            g *= 2.0
    tree = _kernels.build_tree(points, workers)
    idx[todo] = _kernels.cloud_knn_rows(tree, rows[todo], k, workers)
    return idx


def _points_near(points: np.ndarray, centres: np.ndarray, g: float) -> np.ndarray | None:
    """Increasing indices of ``points`` (L, 3) in the cells ``g`` wide at or next to
    the cells of ``centres`` (c, 3): a superset of the points closer than ``g`` to a
    centre. None when the grid over the centres has too many cells."""
    base = centres.min(axis=0)
    dims = np.floor((centres.max(axis=0) - base) / g).astype(np.int64) + 5
    if dims.max() >= 1 << 24 or float(np.prod(dims.astype(np.float64))) >= 2.0**62:
        return None
    # cells 2..dims-3 hold centres, their neighbours 1..dims-2; farther points are
    # clipped to the border cells 0 and dims-1, never near
    cell = np.floor((points - base) / g)
    np.clip(cell + 2.0, 0.0, (dims - 1).astype(np.float64), out=cell)
    cell = cell.astype(np.int64)
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    mine = np.floor((centres - base) / g).astype(np.int64) + 2
    step = np.array([-1, 0, 1])
    around = np.stack(np.meshgrid(step, step, step, indexing="ij"), -1).reshape(-1, 3)
    cells = (mine[:, None, :] + around).reshape(-1, 3)
    keys = np.unique((cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2])
    return np.flatnonzero(np.isin(key, keys))


def neighbours(
    store: Store,
    layout: Layout,
    tile: int,
    query: Query,
    *,
    halo: float,
    most_points: int,
    workers: int = -1,
) -> tuple[list[Context], float, int, int]:
    """Exact neighbourhoods of the tile's rows.

    Parameters
    ----------
    store, layout
    tile : int
    query : Query
    halo : float
        The first halo width to try.
    most_points : int
        Largest box (points, duplicates included) a widening may reach.
    workers : int

    Returns
    -------
    contexts : list of Context
        One for the tile (rows whose balls fit), one per point of the streaming route.
    halo : float
        The halo that held the tile's points.
    gathered : int
        Most points searched at once.
    streamed : int
        Rows that took the streaming route.
    """
    if query.reuse is not None:
        ctx = _reused(store, tile, query)
        return ([ctx] if len(ctx.rows) else []), float(halo), 0, 0
    contexts, h, biggest, far = _searched(store, layout, tile, query, halo, most_points, workers)
    if query.save is not None:
        kept = [np.column_stack([c.own, c.pos[c.idx]]) for c in contexts if c.idx is not None]
        lists = np.concatenate(kept) if kept else np.zeros((0, query.k + 1), np.int64)
        store.put(query.save, tile, lists)
    return contexts, h, biggest, far


def _reused(store: Store, tile: int, query: Query) -> Context:
    """The context of :attr:`Query.reuse`: the tile's rows among those whose lists were
    saved, their first ``k`` neighbours, on the set of the points met, in increasing
    input index."""
    saved = store.get(str(query.reuse), tile)
    assert saved.shape[1] > query.k
    if query.rows is not None and len(saved):
        saved = saved[store.read_at(query.rows, saved[:, 0]).astype(bool)]
    own, near = saved[:, 0], saved[:, 1 : query.k + 1]
    met = np.unique(np.concatenate([own, near.reshape(-1)]))
    order = np.argsort(store.read_at("ids", met), kind="stable")
    pos = met[order]
    local = np.empty(len(met), np.int64)
    local[order] = np.arange(len(met))
    rows = local[np.searchsorted(met, own)]
    idx = local[np.searchsorted(met, near)]
    first = np.argsort(rows, kind="stable")
    return Context(store, store.read_at("coords", pos), pos, rows[first], idx[first])


def _searched(
    store: Store,
    layout: Layout,
    tile: int,
    query: Query,
    halo: float,
    most_points: int,
    workers: int,
) -> tuple[list[Context], float, int, int]:
    """:func:`neighbours` by a search of the tile's box (and the streaming route). The
    rows whose balls fit are done; a wider box searches (and computes) only the others.
    With :attr:`Query.rows`, the box is that of the tile's points marked (none: no
    search), a halo's width around them (the few features of a support step, not the
    whole tile and its neighbours)."""
    a, b = int(layout.offsets[tile]), int(layout.offsets[tile + 1])
    lo0, hi0 = layout.boxes[tile]
    if query.rows is not None:
        marked = store.read(query.rows, a, b).astype(bool)
        if not marked.any():
            return [], float(halo), 0, 0
        lo0, hi0 = bounds(store.read("coords", a, b)[marked])
    diag = float(np.linalg.norm(layout.hi - layout.lo)) or 1.0
    h = float(halo)
    biggest = 0
    last = None
    done: list[Context] = []
    pending: np.ndarray | None = None  # store positions of the rows not done yet
    grown = False  # the halo grew because too few points were near (far outliers)
    for _ in range(ROUNDS):
        blo, bhi = lo0 - h, hi0 + h
        full = bool(np.all(blo <= layout.lo) and np.all(bhi >= layout.hi))
        pos, points, _ = gather(store, layout, layout.tiles_meeting(blo, bhi), blo, bhi, query.kept)
        if (last is not None or grown) and len(points) > most_points:
            break
        rows = _rows(store, pos, a, b, query, pending)
        if len(rows) == 0:
            return done, h, biggest, 0
        if len(points) < query.k:
            if full:
                raise InputError(
                    f"{len(points)} points left, fewer than the largest scale k = {query.k}"
                )
            h = max(2.0 * h, float(np.linalg.norm(hi0 - lo0)), 1e-3 * diag)
            grown = True
            continue
        biggest = max(biggest, len(points))
        hint = None if query.hint is None else store.read_at(query.hint, pos[rows])
        idx, found, kth_d2 = _search(points, rows, query, query.rows is None, workers, hint)
        r = np.sqrt(kth_d2)
        need = r * (1.0 + MARGIN) + 1e-300
        if full:
            ok = np.ones(len(rows), bool)
        else:
            p = points[rows]
            room = np.minimum(p - blo, bhi - p)  # per axis; their minimum, column-wise
            ok = need < np.minimum(np.minimum(room[:, 0], room[:, 1]), room[:, 2])
        last = (pos, points, rows, ok, r, h)
        if ok.any():
            sub = {key: value[ok] for key, value in found.items()}
            kidx = None if idx is None else idx[ok]
            done.append(Context(store, points, pos, rows[ok], kidx, sub))
        if ok.all():
            return done, h, biggest, 0
        pending = pos[rows[~ok]]
        p, nd = points[rows[~ok]], need[~ok][:, None]
        want = float(np.max(np.maximum(lo0 - (p - nd), (p + nd) - hi0)))
        h = max(want * (1.0 + 1e-6), h * 1.01 + 1e-12 * diag)
    if last is None:  # too few points near the tile: all its rows take the streaming route
        h = float(halo)  # the next step starts from it again, not from the whole cloud
        pos, points, _ = gather(store, layout, np.array([tile]), lo0, hi0, query.kept)
        rows = _rows(store, pos, a, b, query, pending)
        upper = np.full(len(rows), np.inf)
    else:
        pos, points, rows, ok, r, h = last
        rows, upper = rows[~ok], r[~ok]
    done.extend(streamed(store, layout, pos[rows], points[rows], upper, query, workers))
    return done, h, biggest, len(rows)


def _rows(
    store: Store, pos: np.ndarray, a: int, b: int, query: Query, pending: np.ndarray | None
) -> np.ndarray:
    """Local indices of the points at ``pos`` that are the tile's (positions a..b) rows
    (among the store positions ``pending``, when given)."""
    own = (pos >= a) & (pos < b)
    if pending is not None:
        own &= np.isin(pos, pending)
    if query.rows is not None:
        own &= store.read_at(query.rows, pos).astype(bool)
    return np.flatnonzero(own)


def streamed(
    store: Store,
    layout: Layout,
    pos: np.ndarray,
    points: np.ndarray,
    upper: np.ndarray,
    query: Query,
    workers: int = -1,
) -> list[Context]:
    """Exact neighbourhoods of a few points, tile by tile (the streaming route).

    Parameters
    ----------
    pos : (f,) int64
        Store positions of the points.
    points : (f, 3) float64
    upper : (f,) float64
        Upper bounds of their k-th neighbour distances (inf: unknown).
    query : Query

    Returns
    -------
    list of Context
        One per point, on exactly its k nearest (itself included).
    """
    f, k = len(pos), query.k
    if f == 0:
        return []
    best_d2 = np.full((f, k), np.inf)
    best_id = np.full((f, k), np.iinfo(np.int64).max)
    best_pos = np.full((f, k), -1, np.int64)
    bound = upper.astype(np.float64).copy()
    centre = points.mean(axis=0)
    near = np.maximum(0.0, np.maximum(layout.boxes[:, 0] - centre, centre - layout.boxes[:, 1]))
    for t in np.argsort((near * near).sum(axis=1), kind="stable"):
        lo, hi = layout.boxes[t]
        gap = np.maximum(0.0, np.maximum(lo - points, points - hi))
        reach = np.sqrt((gap * gap).sum(axis=1)) <= bound * (1.0 + MARGIN)
        if not reach.any():
            continue
        tpos, tpts, tids = gather(store, layout, np.array([t]), lo, hi, query.kept)
        if len(tpos) == 0:
            continue
        tree = cKDTree(tpts)
        which = np.flatnonzero(reach)
        kq = min(k + 1, len(tpts))
        _, cand = tree.query(points[which], kq)
        cand = cand.reshape(len(which), kq)
        d2 = squared_distances(tpts[cand], points[which][:, None, :])
        ids = tids[cand]
        order = np.lexsort((ids, d2), axis=-1)
        d2, cand = np.take_along_axis(d2, order, -1), np.take_along_axis(cand, order, -1)
        tied = np.zeros(len(which), bool) if kq <= k else d2[:, k - 1] == d2[:, k]
        for j in np.flatnonzero(tied):  # a tie across the k-th place: all of it, exactly
            i = which[j]
            ball = np.asarray(tree.query_ball_point(points[i], np.sqrt(d2[j, k - 1]) * 1.000001))
            _merge(best_d2, best_id, best_pos, i, squared_distances(tpts[ball], points[i]),
                   tids[ball], tpos[ball])  # fmt: skip
        plain = ~tied
        rows = which[plain]
        cand = cand[plain, : min(k, kq)]
        _merge(best_d2, best_id, best_pos, rows, d2[plain, : min(k, kq)], tids[cand], tpos[cand])
        done = np.isfinite(best_d2[which, -1])
        bound[which[done]] = np.minimum(bound[which[done]], np.sqrt(best_d2[which[done], -1]))
    out = []
    for i in range(f):
        if best_pos[i, -1] < 0:
            raise InputError(f"fewer than the largest scale k = {k} points left")
        order = np.argsort(best_id[i], kind="stable")
        mpos = best_pos[i][order]
        mpts = store.read_at("coords", mpos)
        row = np.flatnonzero(mpos == pos[i])
        idx, found, _ = _search(mpts, row, query, True, workers)
        out.append(Context(store, mpts, mpos, row, idx, found))
    return out


def _merge(
    best_d2: np.ndarray,
    best_id: np.ndarray,
    best_pos: np.ndarray,
    rows: np.ndarray | int,
    d2: np.ndarray,
    ids: np.ndarray,
    pos: np.ndarray,
) -> None:
    """Keep the k best by (squared distance, input index) of the current best of
    ``rows`` and new candidates (same leading shape as ``best_*[rows]``)."""
    k = best_d2.shape[1]
    all_d2 = np.concatenate([best_d2[rows], d2], axis=-1)
    all_id = np.concatenate([best_id[rows], ids], axis=-1)
    all_pos = np.concatenate([best_pos[rows], pos], axis=-1)
    order = np.lexsort((all_id, all_d2), axis=-1)[..., :k]
    best_d2[rows] = np.take_along_axis(all_d2, order, -1)
    best_id[rows] = np.take_along_axis(all_id, order, -1)
    best_pos[rows] = np.take_along_axis(all_pos, order, -1)
