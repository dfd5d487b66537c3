"""Test inputs with known answers, built with numpy and pymeshlab (no files needed)."""

from __future__ import annotations

import math

import numpy as np
import pymeshlab


def cube_grid_points(m: int = 21) -> np.ndarray:
    """Regular m x m grid on each face of the cube [-1, 1]^3, shared edges once. (n, 3)."""
    g = np.linspace(-1.0, 1.0, m)
    faces = []
    for axis in range(3):
        others = [i for i in range(3) if i != axis]
        a, b = np.meshgrid(g, g, indexing="ij")
        for side in (-1.0, 1.0):
            p = np.empty((m * m, 3))
            p[:, axis] = side
            p[:, others[0]] = a.ravel()
            p[:, others[1]] = b.ravel()
            faces.append(p)
    return np.unique(np.concatenate(faces), axis=0)


def cube_grid_mesh(subdivisions: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Cube [-1, 1]^3 triangulated regularly (midpoint subdivision). (n, 3), (m, 3)."""
    ms = pymeshlab.MeshSet()
    ms.create_cube(size=2.0)
    ms.meshing_surface_subdivision_midpoint(iterations=subdivisions)
    ms.meshing_remove_duplicate_vertices()
    mesh = ms.current_mesh()
    return mesh.vertex_matrix(), mesh.face_matrix().astype(np.int64)


def on_cube_edges(points: np.ndarray, half: float = 1.0, tol: float = 1e-9) -> np.ndarray:
    """True for points on the 12 edges of the cube [-half, half]^3. (n,) bool."""
    return np.sum(np.abs(np.abs(points) - half) < tol, axis=1) >= 2


def flat_square(m: int = 30) -> np.ndarray:
    """Regular m x m grid on the unit square in the plane z = 0. (m*m, 3)."""
    g = np.linspace(0.0, 1.0, m)
    a, b = np.meshgrid(g, g)
    return np.column_stack([a.ravel(), b.ravel(), np.zeros(m * m)])


def random_box_points(n: int = 3000, seed: int = 0, size=(2.0, 1.4, 1.0)) -> np.ndarray:
    """Uniform random samples on the surface of an axis-aligned box (no exact ties). (n, 3)."""
    rng = np.random.default_rng(seed)
    sx, sy, sz = size
    areas = np.array([sy * sz, sy * sz, sx * sz, sx * sz, sx * sy, sx * sy])
    face = rng.choice(6, size=n, p=areas / areas.sum())
    u, v = rng.random(n), rng.random(n)
    p = np.empty((n, 3))
    axis = face // 2
    side = face % 2
    dims = np.array(size)
    for i in range(n):
        a = axis[i]
        o = [j for j in range(3) if j != a]
        p[i, a] = side[i] * dims[a]
        p[i, o[0]] = u[i] * dims[o[0]]
        p[i, o[1]] = v[i] * dims[o[1]]
    return p - dims / 2


def box_cylinder_points(n: int = 4000, seed: int = 1) -> np.ndarray:
    """Random samples on a box with a cylinder standing on its top: planes, a cylinder,
    convex and concave circular edges. (n, 3)."""
    rng = np.random.default_rng(seed)
    ms = pymeshlab.MeshSet()
    ms.create_cube(size=2.0)
    ms.create_cone(r0=0.5, r1=0.5, h=1.5, subdiv=96)
    ms.compute_matrix_from_translation(traslmethod="XYZ translation", axisx=0, axisy=1.5, axisz=0)
    ms.generate_boolean_union(first_mesh=0, second_mesh=1)
    mesh = ms.current_mesh()
    v, f = mesh.vertex_matrix(), mesh.face_matrix()
    tri = v[f]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    pick = rng.choice(len(f), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.column_stack([1 - s, s * (1 - r2), s * r2])
    return np.einsum("ij,ijk->ik", w, tri[pick])


def random_rotation(seed: int = 0) -> np.ndarray:
    """A random proper rotation matrix. (3, 3)."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def pipe_mesh(
    n: int = 40, r0: float = 10.0, r1: float = 7.0, h: float = 30.0
) -> tuple[np.ndarray, np.ndarray]:
    """A CAD-style pipe: n-gon rings only (4n vertices, all on a sharp rim), long thin
    triangles between them. (4n, 3), (8n, 3)."""
    a = 2 * np.pi * np.arange(n) / n
    ring = [
        np.c_[r * np.cos(a), r * np.sin(a), np.full(n, z)]
        for r, z in ((r0, 0.0), (r0, h), (r1, 0.0), (r1, h))
    ]
    ob, ot, ib, it = 0, n, 2 * n, 3 * n
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [(ob + i, ob + j, ot + j), (ob + i, ot + j, ot + i)]
        faces += [(ib + i, it + j, ib + j), (ib + i, it + i, it + j)]
        faces += [(ot + i, ot + j, it + j), (ot + i, it + j, it + i)]
        faces += [(ob + i, ib + j, ob + j), (ob + i, ib + i, ib + j)]
    return np.vstack(ring), np.array(faces)


def fold_mesh(
    angle_deg: float, m: int = 12, steps: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A grid folded along the columns x = 0, ..., steps - 1, each turning by
    ``angle_deg / steps`` (one crease of angle_deg for ``steps = 1``, a rounded one
    otherwise). Returns vertices (v, 3), faces (f, 3) and the mask of the folding
    columns' vertices (v,)."""
    xs = np.arange(-m, m + 1, dtype=float)
    ys = np.arange(0, m + 1, dtype=float)
    # profile in the xz plane: unit segments, turning at the folding columns
    turn = math.radians(angle_deg) / steps * np.clip(xs[:-1] + 1, 0, steps)
    seg = np.c_[np.cos(turn), np.sin(turn)]
    seg[xs[:-1] < 0] = (1.0, 0.0)
    start = np.searchsorted(xs, 0.0)
    profile = np.zeros((len(xs), 2))
    profile[start + 1 :] = np.cumsum(seg[start:], axis=0)
    profile[:start] = np.c_[xs[:start], np.zeros(start)]
    x, y = np.meshgrid(np.arange(len(xs)), ys, indexing="ij")
    verts = np.c_[profile[x.ravel(), 0], y.ravel(), profile[x.ravel(), 1]]
    ny = len(ys)
    faces = []
    for i in range(len(xs) - 1):
        for j in range(ny - 1):
            a, b, c, d = i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1
            faces += [(a, b, c), (a, c, d)]
    column = xs[x.ravel()]
    return verts, np.array(faces), (column >= 0) & (column < steps)


def noisy_box_points(n: int, noise: float, seed: int = 0) -> np.ndarray:
    """:func:`random_box_points` moved by normal noise of ``noise`` times the mean
    spacing ``sqrt(area / n)`` along each axis. (n, 3)."""
    points = random_box_points(n, seed=seed)
    spacing = np.sqrt(2 * (2.0 * 1.4 + 2.0 * 1.0 + 1.4 * 1.0) / n)
    return points + np.random.default_rng(seed + 1).normal(0, noise * spacing, (n, 3))


def noisy_sphere_points(n: int, noise: float, seed: int = 0) -> np.ndarray:
    """n uniform points on the unit sphere moved along the radius by normal noise of
    ``noise`` times the spacing ``sqrt(4 pi / n)``. (n, 3)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return d * (1.0 + rng.normal(0.0, noise * np.sqrt(4 * np.pi / n), n))[:, None]


def with_outliers(points: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """``points`` followed by ``count`` uniform points in their bounding box grown by half
    its size on each side. (n + count, 3)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = 0.5 * (hi - lo)
    extra = np.random.default_rng(seed).uniform(lo - pad, hi + pad, (count, 3))
    return np.vstack([points, extra])


def noisy_mesh(
    vertices: np.ndarray, faces: np.ndarray, noise: float, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with each vertex moved by normal noise of ``noise`` times the mean edge
    length along each axis. (n, 3), (m, 3)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    length = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).mean()
    moved = vertices + np.random.default_rng(seed).normal(0, noise * length, vertices.shape)
    return moved, faces


def shuffled_mesh(
    vertices: np.ndarray, faces: np.ndarray, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with its vertices and its faces in random order (a vertex order without
    locality, as a scanned or remeshed input's). (n, 3), (m, 3)."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(vertices))
    rank = np.empty_like(perm)
    rank[perm] = np.arange(len(perm))
    return vertices[perm], rank[faces][rng.permutation(len(faces))]


def with_stray_clusters(
    points: np.ndarray, count: int, spacing: float, seed: int = 0
) -> np.ndarray:
    """``points`` followed by ``count`` clusters of 2 or 3 points (about half ``spacing``
    apart), each around a point 1 to 8 ``spacing`` from a random one of ``points`` in a
    random direction. (n + 2..3 count, 3)."""
    rng = np.random.default_rng(seed)
    clusters = []
    for i in rng.integers(len(points), size=count):
        d = rng.normal(size=3)
        centre = points[i] + rng.uniform(1.0, 8.0) * spacing * d / np.linalg.norm(d)
        clusters.append(centre + rng.normal(scale=0.3 * spacing, size=(rng.integers(2, 4), 3)))
    return np.vstack([points, *clusters])


def two_triangle_cube() -> tuple[np.ndarray, np.ndarray]:
    """Cube [-1, 1]^3 as a CAD exporter writes it: its 8 corners and 2 triangles per face
    (each sharp edge one mesh edge, a flat diagonal across each face), outward wound.
    (8, 3), (12, 3)."""
    v = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(faces, np.int64)


def prism_mesh(profile: np.ndarray, height: float) -> tuple[np.ndarray, np.ndarray]:
    """A convex polygon ``profile`` (k, 2), counter-clockwise, extruded from z = 0 to
    ``height`` as an STL export tessellates it: one quad (2 triangles) per side, each
    cap a fan of long thin triangles from its first vertex; no other vertex.
    (2 k, 3), (4 k - 4, 3)."""
    k = len(profile)
    v = np.vstack([np.c_[profile, np.zeros(k)], np.c_[profile, np.full(k, height)]])
    faces = []
    for i in range(k):
        j = (i + 1) % k
        faces += [(i, j, k + j), (i, k + j, k + i)]
    for i in range(1, k - 1):
        faces += [(0, i + 1, i), (k, k + i, k + i + 1)]
    return v, np.array(faces, np.int64)


def polygon(segments: int, radius: float = 1.0) -> np.ndarray:
    """A regular polygon of ``segments`` vertices on the circle of ``radius`` around the
    origin, counter-clockwise from the x axis. (segments, 2)."""
    a = 2 * np.pi * np.arange(segments) / segments
    return radius * np.c_[np.cos(a), np.sin(a)]


def rounded_rectangle(width: float, depth: float, radius: float, segments: int = 24) -> np.ndarray:
    """The outline of a ``width`` x ``depth`` rectangle centred on the origin with its
    corners rounded to ``radius``, ``segments`` per turn on the arcs, counter-clockwise.
    (segments + 4, 2)."""
    quarter = segments // 4
    cx, cy = width / 2 - radius, depth / 2 - radius
    out = []
    for q, (sx, sy) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
        a = np.pi / 2 * q + np.pi / 2 * np.arange(quarter + 1) / quarter
        out.append(np.c_[sx * cx + radius * np.cos(a), sy * cy + radius * np.sin(a)])
    return np.vstack(out)
