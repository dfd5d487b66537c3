"""The feature graph: which detected points are linked, and its skeleton.

Clouds: every feature point is linked to the feature points among its
:data:`LINK_NEIGHBOURS` nearest features that lie within :data:`LINK_RADIUS` spacings.
Meshes: the mesh's own edges whose two vertices are features, weighted so that the
skeleton prefers the edges where the surface turns most. The skeleton is the minimum
spanning forest of the graph (on a cloud, with its free ends bridged to the trees they
point at, :func:`bridge_leaves`), pruned of spurs shorter than
:data:`SPUR_LENGTH` spacings.
"""

from __future__ import annotations

import heapq
import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial import cKDTree

from ..._header import CURVES
from ..neighbourhoods import squared_distances

__all__ = [
    "BRIDGE_ANGLE",
    "BRIDGE_BACK",
    "BRIDGE_REACH",
    "IRREGULAR_BRIDGE_ANGLE",
    "IRREGULAR_BRIDGE_REACH",
    "LINK_NEIGHBOURS",
    "LINK_RADIUS",
    "SPUR_LENGTH",
    "MeshPaths",
    "adjacency",
    "bridge_leaves",
    "close_loops",
    "cloud_graph",
    "mesh_graph",
    "nearest",
    "prune_spurs",
    "spanning_forest",
]

# The numbers are defined once, in native/include/meshlab_sharp.h.
#: Feature neighbours a cloud feature point is linked to, at most: enough for a band
#: three points wide (the paper mode's lines) to stay connected along its length.
LINK_NEIGHBOURS = CURVES.integer("LINK_NEIGHBOURS")
#: Longest link, in spacings: one missing point on a line (a gap of 2 spacings) is
#: bridged; two parallel lines 3 spacings apart are not linked.
LINK_RADIUS = CURVES.real("LINK_RADIUS")
#: Spurs (a branch from a free end to a junction) shorter than this, in spacings, are
#: removed: a band of feature points up to 4 spacings wide leaves side branches up to
#: about half its width plus one link.
SPUR_LENGTH = CURVES.real("SPUR_LENGTH")
#: Mesh edge weight: length / (sin(turn / 2) + MESH_FLAT_WEIGHT); a flat edge (turn 0)
#: costs 20 times its length, a 90-degree crease 1.3 times: the skeleton follows the
#: crease, not the band of feature vertices beside it.
MESH_FLAT_WEIGHT = CURVES.real("MESH_FLAT_WEIGHT")
#: Rounds of spur pruning (a spur on a spur is removed in the next round).
PRUNE_ROUNDS = CURVES.integer("PRUNE_ROUNDS")
#: Clouds: a free end of the skeleton is linked to the nearest feature of another tree
#: that lies ahead of it, in the direction from the skeleton vertex BRIDGE_BACK links
#: back (or the junction or end before it) to the end (:func:`bridge_leaves`): noise
#: and sampling gaps cut an edge's skeleton into pieces too short to join by their
#: direction.
BRIDGE_BACK = CURVES.integer("BRIDGE_BACK")
#: On a regular cloud, within this many spacings (half a spacing beyond LINK_RADIUS) ...
BRIDGE_REACH = CURVES.real("BRIDGE_REACH")
#: ... and this many degrees of the end's direction (the features of a second edge
#: converging at a sharp angle, or of a noisy band beside the edge, stay apart).
BRIDGE_ANGLE = CURVES.real("BRIDGE_ANGLE")
#: On an irregular cloud (points drawn independently leave gaps of several spacings
#: along an edge), within this many spacings ...
IRREGULAR_BRIDGE_REACH = CURVES.real("IRREGULAR_BRIDGE_REACH")
#: ... and this many degrees.
IRREGULAR_BRIDGE_ANGLE = CURVES.real("IRREGULAR_BRIDGE_ANGLE")


def cloud_graph(
    points: np.ndarray, spacing: float, local: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Links between feature points of a cloud.

    Parameters
    ----------
    points : (f, 3) float64
        Distinct feature points.
    spacing : float
        Point spacing.
    local : (f,) float64, optional
        Each point's own spacing (at least ``spacing``): two points are linked within
        LINK_RADIUS times the smaller of theirs (where a scan's density falls with
        range). Default: ``spacing`` everywhere.

    Returns
    -------
    edges : (e, 2) int64
        Node pairs ``a < b``, sorted.
    weights : (e,) float64
        Link lengths.
    """
    n = len(points)
    if n < 2:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    k = min(LINK_NEIGHBOURS + 1, n)
    reach = spacing if local is None else float(local.max())
    idx = nearest(cKDTree(points), points, k, LINK_RADIUS * reach)
    rows = np.repeat(np.arange(n), k).reshape(n, k)
    ok = (idx < n) & (idx != rows)
    a, b = rows[ok], idx[ok]
    pairs = np.unique(np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1), axis=0)
    lengths = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
    if local is not None:
        near = lengths < LINK_RADIUS * np.minimum(local[pairs[:, 0]], local[pairs[:, 1]])
        pairs, lengths = pairs[near], lengths[near]
    return pairs.astype(np.int64), lengths


def nearest(tree: cKDTree, queries: np.ndarray, k: int, bound: float = math.inf) -> np.ndarray:
    """The ``k`` nearest of the tree's points to each query, nearer than ``bound``, ordered
    by squared distance, ties by the lower index (whatever order the kd-tree returns tied
    points in: the native library's order, and the same on a regular grid).

    Parameters
    ----------
    tree : cKDTree
        Of ``n`` points.
    queries : (q, 3) float64
    k : int
        ``1 <= k <= n``.
    bound : float, default inf
        Only points at a distance below it.

    Returns
    -------
    (q, k) int64
        Indices into the tree's points; ``n`` where fewer than ``k`` are nearer than
        ``bound``.
    """
    n = tree.n
    kq = min(k + 1, n)
    idx, d2 = _sorted_query(tree, queries, kq, bound)
    if kq > k:
        # a tie across the k-th place may involve points the query left out: widen
        for r in np.flatnonzero((d2[:, k - 1] == d2[:, k]) & np.isfinite(d2[:, k])):
            wider = kq
            while True:
                wider = min(2 * wider, n)
                row, d2r = _sorted_query(tree, queries[r : r + 1], wider, bound)
                d2r = d2r[0]
                if wider == n or d2r[-1] != d2r[k - 1]:
                    idx[r, :k] = row[0, :k]
                    break
    return idx[:, :k]


def _sorted_query(
    tree: cKDTree, queries: np.ndarray, kq: int, bound: float
) -> tuple[np.ndarray, np.ndarray]:
    """kd-tree query on all cores, each row re-ordered by (squared distance, index):
    indices (q, kq) int64 and their squared distances (q, kq) float64 (:func:`_d2`)."""
    _, idx = tree.query(queries, k=kq, distance_upper_bound=bound, workers=-1)
    idx = np.asarray(idx, np.int64).reshape(len(queries), kq)
    d2 = _d2(tree, queries, idx)
    order = np.lexsort((idx, d2), axis=-1)
    return np.take_along_axis(idx, order, axis=-1), np.take_along_axis(d2, order, axis=-1)


def _d2(tree: cKDTree, queries: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Squared distances of the queries to their neighbours ``idx`` (q, kq); inf where
    ``idx == tree.n`` (none)."""
    found = idx < tree.n
    d2 = squared_distances(tree.data[np.where(found, idx, 0)], queries[:, None, :])
    return np.where(found, d2, np.inf)


def mesh_graph(
    vertices: np.ndarray, faces: np.ndarray, mask: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mesh edges between feature vertices.

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int
    mask : (n,) bool
        Feature vertices.

    Returns
    -------
    edges : (e, 2) int64
        Vertex pairs ``a < b`` (input vertex indices), sorted.
    weights : (e,) float64
        ``length / (sin(turn / 2) + MESH_FLAT_WEIGHT)``, ``turn`` the angle between the
        normals of the edge's faces (boundary and non-manifold edges: 90 degrees).
    all_lengths : (g,) float64
        Lengths of every edge of the faces touching two feature vertices (for the
        spacing).
    """
    f = np.asarray(faces, np.int64)
    near = f[mask[f].sum(axis=1) >= 2]
    if len(near) == 0:
        z = np.zeros(0)
        return np.zeros((0, 2), np.int64), z, z
    p = vertices[near]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    norm = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = normal / np.where(norm > 0, norm, 1.0)
    e = np.concatenate([near[:, [0, 1]], near[:, [1, 2]], near[:, [2, 0]]])
    face = np.tile(np.arange(len(near)), 3)
    e.sort(axis=1)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, face = e[order], face[order]
    first = np.ones(len(e), bool)
    first[1:] = (e[1:] != e[:-1]).any(axis=1)
    start = np.flatnonzero(first)
    count = np.diff(np.append(start, len(e)))
    all_lengths = np.linalg.norm(vertices[e[start, 0]] - vertices[e[start, 1]], axis=1)
    both = mask[e[start, 0]] & mask[e[start, 1]]
    s, c = start[both], count[both]
    edges = e[s]
    lengths = all_lengths[both]
    cos_turn = np.zeros(len(s))  # boundary / non-manifold: 90 degrees
    two = c == 2
    cos_turn[two] = np.einsum("ij,ij->i", normal[face[s[two]]], normal[face[s[two] + 1]])
    sin_half = np.sqrt(np.clip((1.0 - cos_turn) / 2.0, 0.0, 1.0))
    return edges, lengths / (sin_half + MESH_FLAT_WEIGHT), all_lengths


class DisjointSets:
    """Union-find over ``0..n-1`` with path halving; a join hangs the larger root under
    the smaller (the library's ``DisjointSets``)."""

    def __init__(self, n: int) -> None:
        self.parent = list(range(n))

    def root(self, i: int) -> int:
        """The root of ``i``'s set."""
        parent = self.parent
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def join(self, a: int, b: int) -> bool:
        """Join the sets of ``a`` and ``b``; whether they were apart."""
        ra, rb = self.root(a), self.root(b)
        if ra == rb:
            return False
        self.parent[max(ra, rb)] = min(ra, rb)
        return True

    def roots(self) -> np.ndarray:
        """(n,) int64: every element's root."""
        return np.array([self.root(i) for i in range(len(self.parent))], np.int64)


def spanning_forest(n: int, edges: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Minimum spanning forest.

    Parameters
    ----------
    n : int
        Number of nodes.
    edges : (e, 2) int
    weights : (e,) float64, > 0

    Returns
    -------
    (t, 2) int64
        The forest's edges, ``a < b``, sorted.
    """
    if len(edges) == 0:
        return np.zeros((0, 2), np.int64)
    graph = sp.coo_matrix((weights, (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    tree = minimum_spanning_tree(graph).tocoo()
    out = np.stack([np.minimum(tree.row, tree.col), np.maximum(tree.row, tree.col)], axis=1)
    return out[np.lexsort((out[:, 1], out[:, 0]))].astype(np.int64)


def close_loops(
    n: int, forest: np.ndarray, edges: np.ndarray, positions: np.ndarray, min_length: float
) -> np.ndarray:
    """Give back the links the spanning forest dropped to break long loops.

    A dropped link at a free end of the forest is added back when the forest's path
    between its two nodes is at least ``min_length`` long (a loop that long is a curve,
    a circle or the cycle of a polygon's edges; shorter ones are the criss-cross of a
    wide band). Links are tried shortest first, and each addition counts for the next.

    Parameters
    ----------
    n : int
    forest : (t, 2) int
        The spanning forest.
    edges : (e, 2) int
        The graph it spans.
    positions : (n, 3) float64
    min_length : float

    Returns
    -------
    (t + a, 2) int64
        The forest and the links added back.
    """
    degree = np.bincount(forest.ravel(), minlength=n)
    tree = set(map(tuple, forest.tolist()))
    free = (degree[edges[:, 0]] == 1) | (degree[edges[:, 1]] == 1)
    cand = [ab for ab in map(tuple, edges[free].tolist()) if ab not in tree]
    if not cand:
        return forest
    pairs = np.array(cand, np.int64)
    cand_length = np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)
    tree_length = np.linalg.norm(positions[forest[:, 0]] - positions[forest[:, 1]], axis=1)
    adj: dict[int, list[tuple[int, float]]] = {}
    for (a, b), d in zip(forest.tolist(), tree_length.tolist(), strict=True):
        adj.setdefault(a, []).append((b, d))
        adj.setdefault(b, []).append((a, d))
    added = []
    order = np.lexsort((pairs[:, 1], pairs[:, 0], cand_length))
    for (a, b), d in zip(pairs[order].tolist(), cand_length[order].tolist(), strict=True):
        if len(adj.get(a, [])) != 1 and len(adj.get(b, [])) != 1:
            continue
        if _path_shorter(adj, a, b, min_length):
            continue
        added.append((a, b))
        adj.setdefault(a, []).append((b, d))
        adj.setdefault(b, []).append((a, d))
    if not added:
        return forest
    return np.concatenate([forest, np.array(added, np.int64)])


def bridge_leaves(
    n: int, forest: np.ndarray, positions: np.ndarray, reach: float, angle: float
) -> np.ndarray:
    """Link the free ends of a forest to the trees they point at.

    For each free end (a node of degree 1), the direction from the node BRIDGE_BACK
    links back (stopping early at a junction or another free end) to it; a candidate
    link goes to every node of another tree within ``reach`` of the end whose direction
    from the end is within ``angle`` degrees of that one (and, for another free end,
    the other way round too: two edges' ends at a corner are not linked). Candidates are taken
    shortest first (ties by the end's, then the node's index), each joining two trees
    that are still apart.

    Parameters
    ----------
    n : int
        Number of nodes.
    forest : (t, 2) int
        The spanning forest, with its long loops closed (:func:`close_loops`).
    positions : (n, 3) float64
    reach : float
    angle : float
        In degrees.

    Returns
    -------
    (t + a, 2) int64
        The forest and the links added.
    """
    sets = DisjointSets(n)
    neighbours: list[list[int]] = [[] for _ in range(n)]
    for a, b in forest.tolist():
        neighbours[a].append(b)
        neighbours[b].append(a)
        sets.join(a, b)
    leaves = [a for a in range(n) if len(neighbours[a]) == 1]
    if not leaves:
        return forest
    direction = {}
    for a in leaves:
        prev, cur = a, neighbours[a][0]
        for _ in range(BRIDGE_BACK - 1):
            if len(neighbours[cur]) != 2:
                break
            two = neighbours[cur]
            prev, cur = cur, (two[1] if two[0] == prev else two[0])
        d = positions[a] - positions[cur]
        direction[a] = (d, float(np.linalg.norm(d[None], axis=1)[0]))
    tree = cKDTree(positions)
    min_cos = math.cos(math.radians(angle))
    cand: list[tuple[float, int, int]] = []
    for a in leaves:
        d, d_len = direction[a]
        own = sets.root(a)
        near = np.array(
            [b for b in tree.query_ball_point(positions[a], reach) if sets.root(b) != own], np.int64
        )
        if len(near) == 0:
            continue
        v = positions[near] - positions[a]
        length = np.linalg.norm(v, axis=1)
        ahead = np.einsum("ij,ij->i", v, np.broadcast_to(d, v.shape))
        for b, w, x, y in zip(near.tolist(), v, length.tolist(), ahead.tolist(), strict=True):
            if y < min_cos * x * d_len:
                continue
            if b in direction:  # two free ends: each ahead of the other
                e, e_len = direction[b]
                back = float(np.einsum("ij,ij->i", -w[None], e[None])[0])
                if back < min_cos * x * e_len:
                    continue
            cand.append((x, a, b))
    added = []
    for _, a, b in sorted(cand):
        if sets.join(a, b):
            added.append((min(a, b), max(a, b)))
    if not added:
        return forest
    return np.concatenate([forest, np.array(added, np.int64)])


def _path_shorter(adj: dict[int, list[tuple[int, float]]], a: int, b: int, limit: float) -> bool:
    """Whether a path from ``a`` to ``b`` shorter than ``limit`` exists (Dijkstra)."""
    best = {a: 0.0}
    heap = [(0.0, a)]
    while heap:
        d, node = heapq.heappop(heap)
        if node == b:
            return True
        if d > best.get(node, math.inf):
            continue
        for nxt, step in adj.get(node, []):
            nd = d + step
            if nd < limit and nd < best.get(nxt, math.inf):
                best[nxt] = nd
                heapq.heappush(heap, (nd, nxt))
    return False


def adjacency(n: int, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR adjacency of an undirected graph.

    Parameters
    ----------
    n : int
    edges : (e, 2) int

    Returns
    -------
    indptr : (n + 1,) int64
    neighbours : (2e,) int64
        Neighbours of node ``i``: ``neighbours[indptr[i]:indptr[i + 1]]``, ascending.
    edge_ids : (2e,) int64
        The edge (row of ``edges``) of each entry.
    """
    a = np.concatenate([edges[:, 0], edges[:, 1]]).astype(np.int64)
    b = np.concatenate([edges[:, 1], edges[:, 0]]).astype(np.int64)
    ids = np.tile(np.arange(len(edges), dtype=np.int64), 2)
    order = np.lexsort((b, a))
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(a, minlength=n), out=indptr[1:])
    return indptr, b[order], ids[order]


def prune_spurs(n: int, edges: np.ndarray, positions: np.ndarray, min_length: float) -> np.ndarray:
    """Remove branches from a free end to a junction shorter than ``min_length``.

    At each junction the shortest such spurs go first, and never so many that the
    junction is left with fewer than two branches: the ends of the main line are not
    eaten away round after round.

    Parameters
    ----------
    n : int
        Number of nodes.
    edges : (e, 2) int
        A forest, with the long loops closed (:func:`close_loops`).
    positions : (n, 3) float64
        Node positions.
    min_length : float
        Shortest branch kept.

    Returns
    -------
    (t, 2) int64
        The remaining edges, in their given order.
    """
    keep = np.ones(len(edges), bool)
    edge_length = np.linalg.norm(positions[edges[:, 0]] - positions[edges[:, 1]], axis=1)
    lengths = edge_length.tolist()
    for _ in range(PRUNE_ROUNDS):
        current = np.flatnonzero(keep)
        indptr_a, nbr_a, eid_a = adjacency(n, edges[current])
        degree_a = np.diff(indptr_a)
        # Python lists: the walks below index them one element at a time
        indptr, nbr, degree = indptr_a.tolist(), nbr_a.tolist(), degree_a.tolist()
        edge_of = current[eid_a].tolist()
        spurs: dict[int, list[tuple[float, int, list[int]]]] = {}
        for leaf in np.flatnonzero(degree_a == 1).tolist():
            prev, node, length, path = -1, leaf, 0.0, []
            while True:
                step = indptr[node]  # the first neighbour but the one we came from
                while nbr[step] == prev:
                    step += 1
                edge = edge_of[step]
                path.append(edge)
                nxt = nbr[step]
                length += lengths[edge]
                prev, node = node, nxt
                if degree[node] != 2 or length >= min_length:
                    break
            if degree[node] >= 3 and length < min_length:
                spurs.setdefault(node, []).append((length, int(leaf), path))
        removed = False
        for junction, found in spurs.items():
            found.sort()
            for _, _, path in found[: max(0, degree[junction] - 2)]:
                keep[path] = False
                removed = True
        if not removed:
            break
    return edges[keep]


class MeshPaths:
    """Shortest paths along the mesh edges of the faces that touch a feature vertex: the
    vertices joining curve ends across a gap, or a curve end to its corner, on a mesh.

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int
    mask : (n,) bool
        Feature vertices.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, mask: np.ndarray) -> None:
        f = np.asarray(faces, np.int64)
        f = f[mask[f].any(axis=1)]
        self.ids = np.unique(f)
        local = np.searchsorted(self.ids, f)
        e = np.concatenate([local[:, [0, 1]], local[:, [1, 2]], local[:, [2, 0]]])
        e = np.unique(np.sort(e, axis=1), axis=0)
        self.positions = vertices[self.ids]
        length = np.linalg.norm(self.positions[e[:, 0]] - self.positions[e[:, 1]], axis=1)
        n = len(self.ids)
        self.graph = sp.coo_matrix(
            (np.concatenate([length, length]), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
            shape=(n, n),
        ).tocsr()
        self.tree = cKDTree(self.positions) if n else None

    def nearest(self, point: np.ndarray) -> int:
        """The input index of the vertex nearest ``point`` (3,) among these faces' (the
        lowest of equally near ones)."""
        assert self.tree is not None
        return int(self.ids[nearest(self.tree, np.asarray(point)[None, :], 1)[0, 0]])

    def path(self, a: int, b: int, limit: float) -> np.ndarray | None:
        """Input indices of the vertices strictly between ``a`` and ``b`` on the shortest
        path (shape (k,)), or None when none is at most ``limit`` long.

        Dijkstra with a heap of (distance, vertex): of equally near vertices the lowest
        is settled first, and a vertex's predecessor is the first settled vertex that
        reaches it at its final distance; so among equally short paths (a regular grid)
        the one taken is fixed, and the same in the native library.
        """
        ia, ib = (int(i) for i in np.searchsorted(self.ids, [a, b]))
        if ia >= len(self.ids) or ib >= len(self.ids) or self.ids[ia] != a or self.ids[ib] != b:
            return None
        indptr, indices, weights = self.graph.indptr, self.graph.indices, self.graph.data
        dist, pred, settled = {ia: 0.0}, {ia: ia}, set()
        heap = [(0.0, ia)]
        while heap:
            d, node = heapq.heappop(heap)
            if node in settled:
                continue
            settled.add(node)
            if node == ib:
                break
            for j in range(indptr[node], indptr[node + 1]):
                nxt = int(indices[j])
                step = d + float(weights[j])
                if nxt not in settled and step <= limit and step < dist.get(nxt, math.inf):
                    dist[nxt], pred[nxt] = step, node
                    heapq.heappush(heap, (step, nxt))
        if ib not in settled:
            return None
        inner = []
        node = pred[ib]
        while node != ia:
            inner.append(node)
            node = pred[node]
        return self.ids[np.array(inner[::-1], np.int64)]
