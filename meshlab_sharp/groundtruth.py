"""Generated CAD-like parts whose sharp edges are known exactly, and corruptions of them.

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

>>> from meshlab_sharp.groundtruth import make_part, add_noise
>>> part = make_part("drilled_plate", n_points=20_000, seed=1)   # doctest: +SKIP
>>> noisy = add_noise(part, 0.25, seed=2)                          # doctest: +SKIP
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import pymeshlab
from scipy.spatial import ConvexHull, cKDTree

__all__ = [
    "CORRUPTIONS",
    "CREASE_ANGLE",
    "PARTS",
    "SMOOTH_PARTS",
    "SamplePart",
    "add_noise",
    "add_outliers",
    "crease_segments",
    "density_gradient",
    "make_part",
    "part_names",
    "reference_surface",
]

CREASE_ANGLE = 20.0
"""Degrees: a reference edge whose faces turn by more than this is a sharp edge."""

SEGMENTS = 128
"""Segments per full turn of every round surface (facets turn by 2.8 degrees)."""

DEFAULT_POINTS = 50_000
DEFAULT_MESH_VERTICES = 25_000

Mesh = tuple[np.ndarray, np.ndarray]
"""(vertices (n, 3) float64, faces (m, 3) int64), closed and outward oriented."""


@dataclass(frozen=True, eq=False)
class SamplePart:
    """A generated part: points or a mesh, and its exact sharp edges.

    Attributes
    ----------
    name : str
        Part name (a key of ``PARTS``).
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


def _prism(polygon: np.ndarray, z0: float, z1: float) -> Mesh:
    """Extrude a counter-clockwise, star-shaped (k, 2) polygon from z0 to z1."""
    k = len(polygon)
    return _loft(np.c_[polygon, np.full(k, z0)], np.c_[polygon, np.full(k, z1)])


def _box(lo: tuple[float, float, float], hi: tuple[float, float, float]) -> Mesh:
    """Axis-aligned box."""
    rect = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]], float)
    return _prism(rect, lo[2], hi[2])


def _cylinder(center: tuple[float, float], r: float, z0: float, z1: float) -> Mesh:
    """Vertical cylinder (SEGMENTS-gon prism)."""
    return _prism(_circle(center, r), z0, z1)


def _frustum(center: tuple[float, float], r0: float, r1: float, z0: float, z1: float) -> Mesh:
    """Vertical truncated cone, radius r0 at z0 and r1 at z1."""
    b = _circle(center, r0)
    t = _circle(center, r1)
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


def _convex_hull(points: np.ndarray) -> Mesh:
    """Outward-oriented triangulated convex hull of (k, 3) points."""
    pts = np.asarray(points, float)
    hull = ConvexHull(pts)
    faces = hull.simplices.astype(np.int64).copy()
    v = pts[faces]
    nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    outward = np.einsum("ij,ij->i", nrm, v[:, 0] - pts.mean(0)) > 0
    faces[~outward] = faces[~outward][:, ::-1]
    used, faces = np.unique(faces, return_inverse=True)
    return pts[used], faces.reshape(-1, 3).astype(np.int64)


def _torus(R: float, r: float, nu: int = SEGMENTS, nv: int = SEGMENTS // 2) -> Mesh:
    """Torus around z, major radius R, minor radius r, (nu x nv) quad grid."""
    u = 2 * np.pi * np.arange(nu) / nu
    v = 2 * np.pi * np.arange(nv) / nv
    uu, vv = np.meshgrid(u, v, indexing="ij")
    rho = R + r * np.cos(vv)
    verts = np.stack([rho * np.cos(uu), rho * np.sin(uu), r * np.sin(vv)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = i * nv + j
    b = ((i + 1) % nu) * nv + j
    c = ((i + 1) % nu) * nv + (j + 1) % nv
    d = i * nv + (j + 1) % nv
    faces = np.vstack(
        [np.c_[a.ravel(), b.ravel(), c.ravel()], np.c_[a.ravel(), c.ravel(), d.ravel()]]
    )
    return verts, faces.astype(np.int64)


def _rounded_box(half: tuple[float, float, float], r: float, n_flat: int = 24) -> Mesh:
    """Box of half-sizes ``half`` with every edge and corner rounded by radius r.

    A cube's surface grid is mapped onto the offset surface of the inner box: a grid
    point v goes to ``clip(v) + r * (v - clip(v)) / |v - clip(v)|``; grid lines past the
    inner box sit at ``tan(theta)`` so the 90-degree roundings get uniform angle steps.
    """
    steps = SEGMENTS // 8  # 45 degrees on each of the two cube faces a rounding spans
    theta = (np.arange(1, steps + 1) / steps) * (np.pi / 4)
    axes = []
    for h in half:
        inner = h - r
        flat = np.linspace(-inner, inner, max(2, round(n_flat * inner / max(half)) + 1))
        axes.append(np.concatenate([-inner - np.tan(theta[::-1]), flat, inner + np.tan(theta)]))
    verts_list, faces_list, offset = [], [], 0
    for ax in range(3):
        u_ax, v_ax = [a for a in range(3) if a != ax]
        for sign in (-1.0, 1.0):
            uu, vv = np.meshgrid(axes[u_ax], axes[v_ax], indexing="ij")
            g = np.zeros(uu.shape + (3,))
            g[..., ax] = sign * axes[ax][-1]
            g[..., u_ax] = uu
            g[..., v_ax] = vv
            nu, nv = uu.shape
            i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
            a = (i * nv + j).ravel()
            b = ((i + 1) * nv + j).ravel()
            c = ((i + 1) * nv + j + 1).ravel()
            d = (i * nv + j + 1).ravel()
            f = np.vstack([np.c_[a, b, c], np.c_[a, c, d]])
            # (u, v, ax) right-handed for ax=0 (y,z,x), ax=1 (x,z,y) is left-handed
            right_handed = ax != 1
            if (sign > 0) != right_handed:
                f = f[:, ::-1]
            verts_list.append(g.reshape(-1, 3))
            faces_list.append(f + offset)
            offset += nu * nv
    grid = np.vstack(verts_list)
    faces = np.vstack(faces_list)
    grid_r = np.round(grid, 9)
    uniq, inv = np.unique(grid_r, axis=0, return_inverse=True)
    faces = inv.reshape(-1)[faces]
    inner = np.array(half) - r
    clip = np.clip(uniq, -inner, inner)
    d = uniq - clip
    verts = clip + r * d / np.linalg.norm(d, axis=1, keepdims=True)
    return verts, faces.astype(np.int64)


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
    return m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64)


def _union(*meshes: Mesh) -> Mesh:
    out = meshes[0]
    for m in meshes[1:]:
        out = _boolean("union", out, m)
    return out


def _minus(a: Mesh, *cutters: Mesh) -> Mesh:
    out = a
    for c in cutters:
        out = _boolean("difference", out, c)
    return out


# ----------------------------------------------------------------------------------
# The parts
# ----------------------------------------------------------------------------------


def _part_fandisk() -> Mesh:
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
    deck = _box((0, 0, 0), (100, 60, 20))
    block = _box((0, 0, 0), (50, 60, 40))
    boss = _cylinder((68, 30), 9, 10, 30)
    solid = _union(deck, block, boss)
    s = 1 / math.sqrt(2)
    chamfer = _halfspace_cutter(np.array([0.0, 0.0, 32.0]), np.array([-s, 0.0, s]))
    a = math.radians(25)
    slope = _halfspace_cutter(np.array([85.0, 0.0, 20.0]), np.array([math.sin(a), 0, math.cos(a)]))
    hole = _cylinder((27, 30), 6, -1, 41)
    countersink = _frustum((27, 30), 5, 12, 35, 42)
    return _minus(solid, chamfer, slope, hole, countersink)


def _part_box() -> Mesh:
    """Box 60 x 40 x 30: twelve 90-degree edges."""
    return _box((0, 0, 0), (60, 40, 30))


def _part_chamfered_box() -> Mesh:
    """Box 60 x 40 x 30 whose four top edges carry a 6-wide 45-degree chamfer."""
    a, b, h, c = 30.0, 20.0, 30.0, 6.0
    pts = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            pts += [(sx * a, sy * b, 0), (sx * a, sy * b, h - c), (sx * (a - c), sy * (b - c), h)]
    return _convex_hull(np.array(pts))


def _part_cylinder() -> Mesh:
    """Cylinder r = 20, height 40: two circular 90-degree edges."""
    return _cylinder((0, 0), 20, 0, 40)


def _part_cone() -> Mesh:
    """Truncated cone r = 25 at the base to r = 10 at height 35 (23-degree half-angle):
    a 67-degree edge at the base circle, a 113-degree one at the top."""
    return _frustum((0, 0), 25, 10, 0, 35)


def _part_drilled_plate() -> Mesh:
    """Plate 80 x 50 x 12 with three through holes (r = 5, 7, 9): rims at 90 degrees."""
    plate = _box((0, 0, 0), (80, 50, 12))
    holes = [_cylinder(c, r, -1, 13) for c, r in (((16, 25), 5), ((38, 25), 7), ((62, 25), 9))]
    return _minus(plate, *holes)


def _part_concave_steps() -> Mesh:
    """Three-step staircase 60 x 40 (steps 20 deep, 10 high): two concave 90-degree edges
    between the treads and the risers, and the convex nosings."""
    return _union(
        _box((0, 0, 0), (60, 40, 10)),
        _box((0, 0, 0), (40, 40, 20)),
        _box((0, 0, 0), (20, 40, 30)),
    )


def _part_star_prism() -> Mesh:
    """Five-pointed star prism (R = 30, height 20) with 45-degree tips: the vertical
    tip edges are acute (the faces turn by 135 degrees), the five inner ones concave."""
    n, big = 5, 30.0
    t22 = math.tan(math.radians(22.5))
    small = big * t22 / (math.sin(math.pi / n) + t22 * math.cos(math.pi / n))
    ang = np.pi / 2 + np.pi * np.arange(2 * n) / n
    rad = np.where(np.arange(2 * n) % 2 == 0, big, small)
    return _prism(np.c_[rad * np.cos(ang), rad * np.sin(ang)], 0, 20)


def _part_sphere() -> Mesh:
    """Smooth control: sphere r = 25 (icosphere, 10242 vertices)."""
    ms = pymeshlab.MeshSet()
    ms.create_sphere(radius=25.0, subdiv=5)
    m = ms.current_mesh()
    return m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64)


def _part_torus() -> Mesh:
    """Smooth control: torus R = 25, r = 10."""
    return _torus(25.0, 10.0)


def _part_rounded_box() -> Mesh:
    """Smooth control: box 60 x 40 x 30 with every edge rounded (r = 8)."""
    return _rounded_box((30.0, 20.0, 15.0), 8.0)


PARTS: dict[str, Callable[[], Mesh]] = {
    "fandisk": _part_fandisk,
    "box": _part_box,
    "chamfered_box": _part_chamfered_box,
    "cylinder": _part_cylinder,
    "cone": _part_cone,
    "drilled_plate": _part_drilled_plate,
    "concave_steps": _part_concave_steps,
    "star_prism": _part_star_prism,
    "sphere": _part_sphere,
    "torus": _part_torus,
    "rounded_box": _part_rounded_box,
}
"""Part name -> builder of its reference surface."""

SMOOTH_PARTS = ("sphere", "torus", "rounded_box")
"""Smooth controls: no sharp edges."""


def part_names(*, smooth: bool | None = None) -> list[str]:
    """Names of the parts; ``smooth=True`` only the smooth controls, False only the others."""
    return [n for n in PARTS if smooth is None or (n in SMOOTH_PARTS) == smooth]


# ----------------------------------------------------------------------------------
# Truth, sampling, remeshing
# ----------------------------------------------------------------------------------


def _face_normals(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (m, 3) and areas (m,) of triangles."""
    v = verts[faces]
    cr = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    norm = np.linalg.norm(cr, axis=1)
    return cr / np.where(norm > 0, norm, 1.0)[:, None], 0.5 * norm


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
    faces = np.asarray(faces, np.int64)
    normals, areas = _face_normals(verts, faces)
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
    ends = key[order[starts[two]]][sharp]
    return verts[ends].reshape(-1, 2, 3)


def reference_surface(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The exact part ``name``: reference mesh and its sharp edges (kept in memory
    after the first call; the arrays are read-only).

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    edges : (e, 2, 3) float64
    """
    if name not in PARTS:
        raise KeyError(f"unknown part {name!r}; known: {', '.join(PARTS)}")
    return _reference_cached(name)


@functools.cache
def _reference_cached(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    verts, faces = PARTS[name]()
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


def _sample_surface(
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
    normals, areas = _face_normals(verts, faces)
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
    _, areas = _face_normals(verts, faces)
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


def _vertex_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    fn, areas = _face_normals(verts, faces)
    vn = np.zeros_like(verts)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn * areas[:, None])
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)


def _f32(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, np.float64).astype(np.float32).astype(np.float64)


def _mean_nn(points: np.ndarray) -> float:
    d, _ = cKDTree(points).query(points, k=2)
    return float(d[:, 1].mean())


def make_part(
    name: str,
    kind: str = "points",
    *,
    n_points: int | None = None,
    seed: int = 0,
) -> SamplePart:
    """Generate part ``name`` as a point cloud or a mesh, with its exact sharp edges.

    Parameters
    ----------
    name : str
        One of ``part_names()``.
    kind : {"points", "mesh"}
        Poisson-disk points on the surface, or an isotropic watertight mesh whose
        sharp edges are mesh edges.
    n_points : int, optional
        Number of points (exact) or of mesh vertices (about, within ~10 %). Default
        ``DEFAULT_POINTS`` (50,000) for points, ``DEFAULT_MESH_VERTICES`` (25,000)
        for meshes.
    seed : int
        Seed of the point sampling (a mesh does not depend on it).

    Returns
    -------
    SamplePart
    """
    if kind not in ("points", "mesh"):
        raise ValueError(f"kind must be 'points' or 'mesh', not {kind!r}")
    verts, faces, edges = reference_surface(name)
    if kind == "points":
        n = DEFAULT_POINTS if n_points is None else int(n_points)
        if n < 10:
            raise ValueError("n_points must be at least 10")
        pts, nrm = _sample_surface(verts, faces, n, seed)
        pts = _f32(pts)
        out_faces = None
        spacing = _mean_nn(pts)
    else:
        n = DEFAULT_MESH_VERTICES if n_points is None else int(n_points)
        if n < 100:
            raise ValueError("n_points must be at least 100 for a mesh")
        pts, out_faces = _remesh(verts, faces, n)
        pts = _f32(pts)
        nrm = _vertex_normals(pts, out_faces)
        e = np.vstack([out_faces[:, [0, 1]], out_faces[:, [1, 2]], out_faces[:, [2, 0]]])
        e = np.unique(np.sort(e, axis=1), axis=0)
        spacing = float(np.linalg.norm(pts[e[:, 0]] - pts[e[:, 1]], axis=1).mean())
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


# ----------------------------------------------------------------------------------
# Corruptions
# ----------------------------------------------------------------------------------


def add_noise(
    part: SamplePart,
    fraction: float,
    *,
    seed: int = 0,
    direction: str = "normal",
) -> SamplePart:
    """Gaussian noise of standard deviation ``fraction * part.spacing``.

    ``direction="normal"`` (default) moves each point along its true surface normal by
    N(0, sigma^2), the noise that a scanner's depth error makes and the one that blurs
    sharp edges; ``"isotropic"`` adds N(0, sigma^2) to each coordinate. Faces, truth
    edges and spacing are kept (spacing is that of the clean part). Outliers are not
    moved.
    """
    if direction not in ("normal", "isotropic"):
        raise ValueError("direction must be 'normal' or 'isotropic'")
    rng = np.random.default_rng(seed)
    sigma = float(fraction) * part.spacing
    n = part.n
    if direction == "normal":
        delta = part.normals * rng.normal(0.0, sigma, n)[:, None]
    else:
        delta = rng.normal(0.0, sigma, (n, 3))
    delta[part.outliers] = 0.0
    return replace(part, vertices=_f32(part.vertices + delta))


def add_outliers(part: SamplePart, fraction: float = 0.01, *, seed: int = 0) -> SamplePart:
    """Append ``round(fraction * n)`` far outliers, uniform in the bounding box enlarged
    by 20 % of its diagonal on every side, at least 2 spacings from every surface point.

    The result is a point cloud (faces dropped); ``outliers`` marks the new points
    (appended after the original ones, whose order is kept); their normals are zero.
    """
    rng = np.random.default_rng(seed)
    k = round(fraction * part.n)
    lo = part.vertices.min(0)
    hi = part.vertices.max(0)
    pad = 0.2 * float(np.linalg.norm(hi - lo))
    tree = cKDTree(part.vertices)
    out = np.empty((0, 3))
    while len(out) < k:
        c = rng.uniform(lo - pad, hi + pad, size=(2 * (k - len(out)) + 8, 3))
        d, _ = tree.query(c)
        out = np.vstack([out, c[d > 2 * part.spacing]])
    out = _f32(out[:k])
    return replace(
        part,
        vertices=np.vstack([part.vertices, out]),
        faces=None,
        normals=np.vstack([part.normals, np.zeros((k, 3))]),
        outliers=np.concatenate([part.outliers, np.ones(k, bool)]),
        kind="points",
    )


def density_gradient(
    part: SamplePart,
    factor: float = 4.0,
    *,
    axis: int = 0,
    seed: int | None = None,
) -> SamplePart:
    """Resample a point-cloud part so that one half is ``factor`` times denser.

    Points with coordinate ``axis`` below the middle of the bounding box get ``factor``
    times the density (spacing ``1/sqrt(factor)`` times) of the other half; the total
    count is that of ``part``. Both halves are Poisson-disk sets. ``spacing`` becomes the
    mean nearest-neighbour distance over all points; ``extra["local_spacing"]`` (n,)
    gives each point's nominal spacing (mean nearest-neighbour distance on its side).
    """
    verts, faces = part.extra["reference"]
    mid = 0.5 * (verts[:, axis].min() + verts[:, axis].max())

    def dens(p: np.ndarray) -> np.ndarray:
        return np.where(p[:, axis] < mid, float(factor), 1.0)

    pts, nrm = _sample_surface(verts, faces, part.n, part.seed if seed is None else seed, dens)
    pts = _f32(pts)
    d, _ = cKDTree(pts).query(pts, k=2)
    dense = pts[:, axis] < mid
    local = np.where(dense, d[dense, 1].mean(), d[~dense, 1].mean())
    return replace(
        part,
        vertices=pts,
        faces=None,
        normals=nrm,
        outliers=np.zeros(len(pts), bool),
        spacing=float(d[:, 1].mean()),
        kind="points",
        extra={**part.extra, "local_spacing": local},
    )


CORRUPTIONS: dict[str, Callable[..., SamplePart]] = {
    "noise": add_noise,
    "outliers": add_outliers,
    "density": density_gradient,
}
