"""Generated CAD-like parts whose sharp edges are known exactly: the built-in sample
(``meshlab_sharp.sample``) is built here, and the evaluation's other parts
(``evaluation/parts.py`` in the source tree, not installed) are built the same way.

Every part is built the same way:

1. A **reference surface**: a closed, consistently oriented triangle mesh of the exact
   solid, made from numpy primitives (boxes, prisms, frustums, convex hulls, swept
   surfaces) and pymeshlab's exact mesh booleans. Round surfaces are polygons with
   128 segments per turn, so facets meet at about 3 degrees and lie within
   ``r * (1 - cos(pi / 128))`` (0.03 % of the radius) of the round surface.
2. The **truth**: every edge of the reference surface whose two faces turn by more
   than ``CREASE_ANGLE`` (20) degrees, as straight segments. Facet edges of round
   surfaces (about 3 degrees) are never included; smooth controls have none.
3. A **point cloud**: Poisson-disk samples of the reference surface (a maximal
   Poisson-disk set drawn from random area-weighted candidates, then trimmed to exactly
   ``n_points``), every point exactly on a reference triangle, with that triangle's
   normal. Deterministic for a given seed.
4. A **mesh**: the reference surface remeshed isotropically by pymeshlab with the
   creases kept as mesh edges, about ``n_points`` vertices. Deterministic (no seed).

Coordinates are rounded to float32 (MeshLab stores float) and returned as float64.

>>> from meshlab_sharp.parts import make_part
>>> part = make_part("fandisk", n_points=20_000, seed=1)   # doctest: +SKIP
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import pymeshlab
from scipy.spatial import cKDTree

__all__ = [
    "CREASE_ANGLE",
    "SAMPLE_PARTS",
    "SamplePart",
    "box",
    "check_kind_and_count",
    "crease_edges",
    "crease_segments",
    "cylinder",
    "face_normals",
    "float32_rounded",
    "frustum",
    "make_part",
    "mesh_spacing",
    "minus",
    "prism",
    "reference_surface",
    "sample_surface",
    "sampled",
    "union",
    "vertex_normals",
]


CREASE_ANGLE = 20.0
"""Degrees: a reference edge whose faces turn by more than this is a sharp edge."""

SEGMENTS = 128
"""Segments per full turn of every round surface (facets turn by 2.8 degrees)."""

DEFAULT_POINTS = 50_000
DEFAULT_MESH_VERTICES = 25_000

Mesh = tuple[np.ndarray, np.ndarray]
"""(vertices (n, 3) float64, faces (m, 3) int64), closed and outward oriented."""

Builder = Callable[[int], Mesh]
"""A part's reference surface, given the segments per turn of its round surfaces."""


@dataclass(frozen=True, eq=False)
class SamplePart:
    """A generated part: points or a mesh, and its exact sharp edges.

    Attributes
    ----------
    name : str
        Part name (a key of the ``parts`` it was made from).
    vertices : (n, 3) float64
        Points or mesh vertices, float32-representable.
    faces : (m, 3) int64 or None
        Triangles of a mesh; None for a point cloud.
    edges : (e, 2, 3) float64
        Sharp-edge segments of the exact solid (start and end point of each).
        Empty ``(0, 2, 3)`` for smooth parts.
    spacing : float
        Mean point spacing: mean nearest-neighbour distance (points) or mean edge
        length (mesh).
    normals : (n, 3) float64
        Unit normal of the true surface at each vertex (points: the normal of the
        reference triangle the point lies on; mesh: area-weighted vertex normal).
    outliers : (n,) bool
        True for points added by ``add_outliers`` (all False otherwise).
    kind : str
        ``"points"`` or ``"mesh"``.
    seed : int
        Seed the points were drawn with (meshes do not depend on it).
    extra : dict
        ``"reference"``: (vertices, faces) of the reference surface; optional
        ``"local_spacing"`` (n,) per-point spacing to score with (density gradient,
        scan), ``"visible_edges"`` (p, 2, 3) the edges a scan saw (coverage is measured
        on them), ``"view"`` (n,) the scanner of each scan point, ``"scoring"``
        ("vertices" for CAD tessellations), ``"wall"`` (thin parts' wall thickness).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray | None
    edges: np.ndarray
    spacing: float
    normals: np.ndarray
    outliers: np.ndarray
    kind: str
    seed: int = 0
    extra: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def n(self) -> int:
        """Number of points (vertices)."""
        return int(self.vertices.shape[0])

    @property
    def edge_length(self) -> float:
        """Total length of the sharp edges."""
        return float(np.linalg.norm(self.edges[:, 1] - self.edges[:, 0], axis=1).sum())


# ----------------------------------------------------------------------------------
# Primitives: closed, outward-oriented triangle meshes in numpy
# ----------------------------------------------------------------------------------


def _circle(center: tuple[float, float], r: float, n: int = SEGMENTS) -> np.ndarray:
    """(n, 2) counter-clockwise regular polygon."""
    t = 2.0 * np.pi * np.arange(n) / n
    return np.c_[center[0] + r * np.cos(t), center[1] + r * np.sin(t)]


def _loft(bottom: np.ndarray, top: np.ndarray) -> Mesh:
    """Closed solid between two loops of the same length, caps fanned from centroids.

    ``bottom`` and ``top`` are (k, 3); both loops run counter-clockwise seen from the
    top side (outside the top cap), and each cap must be star-shaped about its centroid.
    """
    k = len(bottom)
    verts = np.vstack([bottom, top, bottom.mean(0), top.mean(0)])
    i = np.arange(k)
    j = (i + 1) % k
    faces = np.vstack(
        [
            np.c_[i, j, k + j],
            np.c_[i, k + j, k + i],
            np.c_[np.full(k, 2 * k), j, i],
            np.c_[np.full(k, 2 * k + 1), k + i, k + j],
        ]
    )
    return verts.astype(np.float64), faces.astype(np.int64)


def prism(polygon: np.ndarray, z0: float, z1: float) -> Mesh:
    """Extrude a counter-clockwise, star-shaped (k, 2) polygon from z0 to z1."""
    k = len(polygon)
    return _loft(np.c_[polygon, np.full(k, z0)], np.c_[polygon, np.full(k, z1)])


def box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> Mesh:
    """Axis-aligned box."""
    rect = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]], float)
    return prism(rect, lo[2], hi[2])


def cylinder(
    center: tuple[float, float], r: float, z0: float, z1: float, n: int = SEGMENTS
) -> Mesh:
    """Vertical cylinder (n-gon prism)."""
    return prism(_circle(center, r, n), z0, z1)


def frustum(
    center: tuple[float, float], r0: float, r1: float, z0: float, z1: float, n: int = SEGMENTS
) -> Mesh:
    """Vertical truncated cone (n segments), radius r0 at z0 and r1 at z1."""
    b = _circle(center, r0, n)
    t = _circle(center, r1, n)
    return _loft(np.c_[b, np.full(len(b), z0)], np.c_[t, np.full(len(t), z1)])


def _halfspace_cutter(point: np.ndarray, normal: np.ndarray, size: float = 1000.0) -> Mesh:
    """A large box filling the side of the plane (point, normal) that normal points to."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    p = np.asarray(point, float)
    sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * size
    loop = p + sq[:, :1] * a + sq[:, 1:] * b
    # counter-clockwise seen from +n: (a, b, n) is right-handed
    return _loft(loop, loop + 2 * size * n)


def _boolean(op: str, a: Mesh, b: Mesh) -> Mesh:
    """Exact mesh boolean of two closed meshes with pymeshlab ("union", "difference",
    "intersection")."""
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=a[0], face_matrix=a[1]))
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=b[0], face_matrix=b[1]))
    getattr(ms, f"generate_boolean_{op}")(first_mesh=0, second_mesh=1)
    # the boolean keeps coincident intersection vertices apart (zero-length edges):
    # weld them, then drop the faces that collapse
    ms.meshing_merge_close_vertices(threshold=pymeshlab.PureValue(1e-6))
    ms.meshing_remove_null_faces()
    ms.meshing_remove_unreferenced_vertices()
    m = ms.current_mesh()
    return _canonical(m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64))


def _canonical(verts: np.ndarray, faces: np.ndarray) -> Mesh:
    """The same triangles in one order, whatever order a filter wrote them in.

    pymeshlab's booleans list their output in an order that depends on thread timing
    (measured: four concurrent runs, three vertex orders, one set of triangles), and the
    sampling draws faces by index. Vertices sorted by (x, y, z); each face starting at its
    smallest vertex, orientation kept; faces sorted.

    Parameters
    ----------
    verts : (n, 3) float64
    faces : (m, 3) int64

    Returns
    -------
    verts : (n, 3) float64
    faces : (m, 3) int64
    """
    order = np.lexsort(verts.T[::-1])
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    f = rank[faces]
    first = np.argmin(f, axis=1)
    rows = np.arange(len(f))
    f = np.stack([f[rows, (first + j) % 3] for j in range(3)], axis=1)
    return verts[order], f[np.lexsort(f.T[::-1])]


def union(*meshes: Mesh) -> Mesh:
    """The exact union of closed meshes (at least one), taken left to right."""
    out = meshes[0]
    for m in meshes[1:]:
        out = _boolean("union", out, m)
    return out


def minus(a: Mesh, *cutters: Mesh) -> Mesh:
    """``a`` less each of the closed meshes ``cutters`` in turn (exact differences)."""
    out = a
    for c in cutters:
        out = _boolean("difference", out, c)
    return out


# ----------------------------------------------------------------------------------
# The parts
# ----------------------------------------------------------------------------------


def _part_fandisk(segments: int = SEGMENTS) -> Mesh:
    """The built-in sample: a 100 x 60 x 40 machined block, fandisk-like.

    - lower deck 100 x 60 x 20 and a raised block 50 x 60 x 40 on its left half: the
      step gives a concave 90-degree edge at x = 50, z = 20;
    - a 45-degree chamfer (8 wide) along the raised block's top-left edge (x = 0);
    - a 25-degree slope on the deck's right end (from x = 85 down to the end face):
      a weak 25-degree convex edge and a 65-degree edge at the end face; the same
      plane bevels the raised block's right top edge (from x = 42.1 to 50, a second
      25-degree edge at x = 42.1, z = 40);
    - a cylindrical boss (r = 9, up to z = 30) on the deck: convex rim on top,
      concave circle at its foot;
    - a hole (r = 6) drilled through the raised block with a 45-degree countersink
      (r = 10 at the top face): two weak 45-degree circles and a 90-degree rim below.
    """
    deck = box((0, 0, 0), (100, 60, 20))
    block = box((0, 0, 0), (50, 60, 40))
    boss = cylinder((68, 30), 9, 10, 30, segments)
    solid = union(deck, block, boss)
    s = 1 / math.sqrt(2)
    chamfer = _halfspace_cutter(np.array([0.0, 0.0, 32.0]), np.array([-s, 0.0, s]))
    a = math.radians(25)
    slope = _halfspace_cutter(np.array([85.0, 0.0, 20.0]), np.array([math.sin(a), 0, math.cos(a)]))
    hole = cylinder((27, 30), 6, -1, 41, segments)
    countersink = frustum((27, 30), 5, 12, 35, 42, segments)
    return minus(solid, chamfer, slope, hole, countersink)


SAMPLE_PARTS: dict[str, Builder] = {"fandisk": _part_fandisk}
"""Part name -> builder of its reference surface, given the segments per turn of its
round surfaces: the sample's part (``evaluation/parts.py`` holds the others)."""


# ----------------------------------------------------------------------------------
# Truth, sampling, remeshing
# ----------------------------------------------------------------------------------


def face_normals(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (m, 3) and areas (m,) of triangles."""
    v = verts[faces]
    cr = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    norm = np.linalg.norm(cr, axis=1)
    return cr / np.where(norm > 0, norm, 1.0)[:, None], 0.5 * norm


def crease_edges(
    verts: np.ndarray, faces: np.ndarray, min_angle: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Edges whose two faces turn by more than ``min_angle`` degrees.

    Returns (e, 2) vertex indices, (e,) and (e,) the two faces of each, and the (m, 3)
    face normals. Edges with other than two faces, and faces of zero area, are ignored.
    """
    normals, areas = face_normals(verts, faces)
    scale = np.ptp(verts, axis=0).max() if len(verts) else 1.0
    good = areas > 1e-12 * scale * scale
    f_idx = np.flatnonzero(good)
    fg = faces[good]
    e = np.vstack([fg[:, [0, 1]], fg[:, [1, 2]], fg[:, [2, 0]]])
    owner = np.tile(f_idx, 3)
    key = np.sort(e, axis=1)
    _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    order = np.argsort(inv, kind="stable")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    two = counts == 2
    fa = owner[order[starts[two]]]
    fb = owner[order[starts[two] + 1]]
    cosang = np.einsum("ij,ij->i", normals[fa], normals[fb])
    sharp = cosang < math.cos(math.radians(min_angle))
    return key[order[starts[two]]][sharp], fa[sharp], fb[sharp], normals


def crease_segments(
    verts: np.ndarray, faces: np.ndarray, min_angle: float = CREASE_ANGLE
) -> np.ndarray:
    """Edges of a closed mesh whose two faces turn by more than ``min_angle`` degrees.

    Parameters
    ----------
    verts : (n, 3) float
    faces : (m, 3) int
    min_angle : float
        Degrees between the two face normals.

    Returns
    -------
    (e, 2, 3) float64
        Segment end points. Edges with other than two faces, and faces of zero area,
        are ignored.
    """
    verts = np.asarray(verts, np.float64)
    ends = crease_edges(verts, np.asarray(faces, np.int64), min_angle)[0]
    return verts[ends].reshape(-1, 2, 3)


def reference_surface(
    name: str, segments: int = SEGMENTS, *, parts: Mapping[str, Builder] = SAMPLE_PARTS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The exact part ``name`` of ``parts``: reference mesh and its sharp edges (kept in
    memory after the first call; the arrays are read-only).

    ``segments`` (per turn of the round surfaces) must keep facets below the crease
    angle (at least 18).

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    edges : (e, 2, 3) float64
    """
    if name not in parts:
        raise KeyError(f"unknown part {name!r}; known: {', '.join(parts)}")
    if segments * CREASE_ANGLE <= 360.0:
        raise ValueError(f"{segments} segments per turn make facets turn by crease angles")
    return _reference_cached(parts[name], int(segments))


@functools.cache
def _reference_cached(builder: Builder, segments: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    verts, faces = builder(segments)
    out = (verts, faces, crease_segments(verts, faces))
    for a in out:
        a.setflags(write=False)
    return out


def _maximal_poisson(cand: np.ndarray, radius: np.ndarray, prio: np.ndarray) -> np.ndarray:
    """Greedy maximal Poisson-disk subset of candidates, in priority order.

    Equivalent to: visit candidates by increasing ``prio``, keep one unless a kept one is
    closer than the mean of their two radii. Computed in parallel rounds (a candidate
    is decided once it has the lowest priority among its undecided neighbours).

    Parameters
    ----------
    cand : (c, 3) float
    radius : (c,) float
    prio : (c,) float, distinct

    Returns
    -------
    (c,) bool: kept.
    """
    k = min(len(cand), 20)
    dist, nb = cKDTree(cand).query(cand, k=k, distance_upper_bound=float(radius.max()))
    dist, nb = dist[:, 1:], nb[:, 1:]  # drop self
    c = len(cand)
    valid = nb < c
    nb = np.where(valid, nb, 0)
    valid &= dist < 0.5 * (radius[:, None] + radius[nb])
    state = np.zeros(c, np.int8)  # 0 undecided, 1 kept, 2 dropped
    while True:
        und = state == 0
        if not und.any():
            break
        live = valid & und[nb]
        minnb = np.where(live, prio[nb], np.inf).min(axis=1)
        keep = und & (prio < minnb)
        state[keep] = 1
        state[und & ~keep & (valid & keep[nb]).any(axis=1)] = 2
    return state == 1


def _trim(points: np.ndarray, radius: np.ndarray, n: int) -> np.ndarray:
    """Indices of n of the points, dropping the most crowded ones (relative to radius)."""
    keep = np.ones(len(points), bool)
    while keep.sum() > n:
        idx = np.flatnonzero(keep)
        d, j = cKDTree(points[idx]).query(points[idx], k=2)
        rel = d[:, 1] / radius[idx]
        excess = int(keep.sum() - n)
        gone = np.zeros(len(idx), bool)
        for a in np.argsort(rel, kind="stable"):
            if excess == 0:
                break
            if not gone[j[a, 1]]:
                gone[a] = True
                excess -= 1
        keep[idx[gone]] = False
    return np.flatnonzero(keep)


def sample_surface(
    verts: np.ndarray,
    faces: np.ndarray,
    n: int,
    seed: int,
    density: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Exactly n Poisson-disk points on a triangle mesh, with their face normals.

    ``density`` maps (c, 3) positions to relative point densities (default uniform).
    """
    rng = np.random.default_rng(seed)
    normals, areas = face_normals(verts, faces)
    weight = areas if density is None else areas * density(verts[faces].mean(axis=1))
    # area in units of the reference density (density 1)
    total = float(weight.sum())
    n_cand = 4 * n
    f = rng.choice(len(faces), size=n_cand, p=weight / total)
    r1 = np.sqrt(rng.random(n_cand))
    r2 = rng.random(n_cand)
    v = verts[faces[f]]
    cand = (
        (1 - r1)[:, None] * v[:, 0]
        + (r1 * (1 - r2))[:, None] * v[:, 1]
        + (r1 * r2)[:, None] * v[:, 2]
    )
    prio = rng.permutation(n_cand).astype(np.float64)
    # relative disk radius: density ~ 1 / radius^2
    rel = np.ones(n_cand) if density is None else 1.0 / np.sqrt(density(cand))
    # measured: from 4 candidates per point, a maximal Poisson-disk set of radius r
    # holds about 0.455 * area / r^2 points; aim 2 % high, then trim
    r = math.sqrt(0.445 * total / n)
    for _ in range(6):
        kept = _maximal_poisson(cand, r * rel, prio)
        got = int(kept.sum())
        if n <= got <= 1.06 * n:
            break
        r *= math.sqrt(got / (1.03 * n))
    idx = np.flatnonzero(kept)
    if got > n:
        idx = idx[_trim(cand[idx], rel[idx], n)]
    return cand[idx], normals[f[idx]]


def _remesh(verts: np.ndarray, faces: np.ndarray, n_vertices: int) -> Mesh:
    """Isotropic remesh with about n_vertices, creases over CREASE_ANGLE kept as edges."""
    _, areas = face_normals(verts, faces)
    # an equilateral mesh of edge L has area sqrt(3)/2 * L^2 per vertex
    target = math.sqrt(2.0 * areas.sum() / (math.sqrt(3.0) * n_vertices))
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=verts, face_matrix=faces))
    ms.meshing_surface_subdivision_midpoint(
        iterations=20, threshold=pymeshlab.PureValue(2.0 * target)
    )
    # Coarser passes first would be faster but flag the chords across small holes as
    # creases (they turn by more than CREASE_ANGLE), which the remesher then keeps.
    ms.meshing_isotropic_explicit_remeshing(
        iterations=3,
        targetlen=pymeshlab.PureValue(target),
        featuredeg=CREASE_ANGLE,
        checksurfdist=False,
        reprojectflag=True,
    )
    m = ms.current_mesh()
    return m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64)


def vertex_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals (n, 3) of a triangle mesh: its face normals weighted by area."""
    fn, areas = face_normals(verts, faces)
    vn = np.zeros_like(verts)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn * areas[:, None])
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)


def float32_rounded(a: np.ndarray) -> np.ndarray:
    """``a`` rounded to float32 and back to float64: coordinates as a float32 file holds
    them, so that a part written and read again is the same part."""
    return np.asarray(a, np.float64).astype(np.float32).astype(np.float64)


def _mean_nn(points: np.ndarray) -> float:
    d, _ = cKDTree(points).query(points, k=2)
    return float(d[:, 1].mean())


def mesh_spacing(verts: np.ndarray, faces: np.ndarray) -> float:
    """Mean edge length of a triangle mesh (each edge counted once)."""
    e = np.vstack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    return float(np.linalg.norm(verts[e[:, 0]] - verts[e[:, 1]], axis=1).mean())


def sampled(
    name: str, reference: tuple[np.ndarray, np.ndarray, np.ndarray], kind: str, n: int, seed: int
) -> SamplePart:
    """Points (exactly n) or an isotropic mesh (about n vertices) of a reference surface."""
    verts, faces, edges = reference
    if kind == "points":
        pts, nrm = sample_surface(verts, faces, n, seed)
        pts = float32_rounded(pts)
        out_faces = None
        spacing = _mean_nn(pts)
    else:
        pts, out_faces = _remesh(verts, faces, n)
        pts = float32_rounded(pts)
        nrm = vertex_normals(pts, out_faces)
        spacing = mesh_spacing(pts, out_faces)
    return SamplePart(
        name=name,
        vertices=pts,
        faces=out_faces,
        edges=edges,
        spacing=spacing,
        normals=nrm,
        outliers=np.zeros(len(pts), bool),
        kind=kind,
        seed=seed,
        extra={"reference": (verts, faces)},
    )


def check_kind_and_count(kind: str, n_points: int | None) -> int:
    """The number of points for ``kind`` (default when None), validated."""
    if kind not in ("points", "mesh"):
        raise ValueError(f"kind must be 'points' or 'mesh', not {kind!r}")
    if kind == "points":
        n = DEFAULT_POINTS if n_points is None else int(n_points)
        if n < 10:
            raise ValueError("n_points must be at least 10")
    else:
        n = DEFAULT_MESH_VERTICES if n_points is None else int(n_points)
        if n < 100:
            raise ValueError("n_points must be at least 100 for a mesh")
    return n


def make_part(
    name: str,
    kind: str = "points",
    *,
    n_points: int | None = None,
    seed: int = 0,
    parts: Mapping[str, Builder] = SAMPLE_PARTS,
) -> SamplePart:
    """Generate part ``name`` as a point cloud or a mesh, with its exact sharp edges.

    Parameters
    ----------
    name : str
        A key of ``parts``.
    kind : {"points", "mesh"}
        Poisson-disk points on the surface, or an isotropic watertight mesh whose
        sharp edges are mesh edges.
    n_points : int, optional
        Number of points (exact) or of mesh vertices (about, within ~10 %). Default
        ``DEFAULT_POINTS`` (50,000) for points, ``DEFAULT_MESH_VERTICES`` (25,000)
        for meshes.
    seed : int
        Seed of the point sampling (a mesh does not depend on it).
    parts : mapping of str to builder, default ``SAMPLE_PARTS``
        The parts known (``evaluation/parts.py``: every part of the evaluation).

    Returns
    -------
    SamplePart
    """
    n = check_kind_and_count(kind, n_points)
    return sampled(name, reference_surface(name, parts=parts), kind, n, seed)
