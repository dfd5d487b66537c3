"""The evaluation's parts: CAD-like solids whose sharp edges are known exactly, built
as :mod:`meshlab_sharp.parts` builds the sample's (which is one of them, ``fandisk``).

>>> from evaluation.parts import make_part
>>> part = make_part("drilled_plate", n_points=20_000, seed=1)   # doctest: +SKIP
"""

from __future__ import annotations

import math

import numpy as np
import pymeshlab
from scipy.spatial import ConvexHull

from meshlab_sharp import parts as sample_parts
from meshlab_sharp.parts import (
    SAMPLE_PARTS,
    SEGMENTS,
    Builder,
    Mesh,
    SamplePart,
    box,
    cylinder,
    frustum,
    minus,
    prism,
    union,
)

__all__ = [
    "ACUTE_PARTS",
    "COARSE_SEGMENTS",
    "PARTS",
    "ROUND_PARTS",
    "SHARP_PARTS",
    "SMOOTH_PARTS",
    "make_part",
    "part_names",
    "reference_surface",
]


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


def _rounded_box(
    half: tuple[float, float, float], r: float, n_flat: int = 24, segments: int = SEGMENTS
) -> Mesh:
    """Box of half-sizes ``half`` with every edge and corner rounded by radius r.

    A cube's surface grid is mapped onto the offset surface of the inner box: a grid
    point v goes to ``clip(v) + r * (v - clip(v)) / |v - clip(v)|``; grid lines past the
    inner box sit at ``tan(theta)`` so the 90-degree roundings get uniform angle steps.
    """
    steps = segments // 8  # 45 degrees on each of the two cube faces a rounding spans
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


def _part_box(segments: int = SEGMENTS) -> Mesh:
    """Box 60 x 40 x 30: twelve 90-degree edges (no round surface: ``segments`` unused)."""
    return box((0, 0, 0), (60, 40, 30))


def _part_chamfered_box(segments: int = SEGMENTS) -> Mesh:
    """Box 60 x 40 x 30 whose four top edges carry a 6-wide 45-degree chamfer (no round
    surface: ``segments`` unused)."""
    a, b, h, c = 30.0, 20.0, 30.0, 6.0
    pts = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            pts += [(sx * a, sy * b, 0), (sx * a, sy * b, h - c), (sx * (a - c), sy * (b - c), h)]
    return _convex_hull(np.array(pts))


def _part_cylinder(segments: int = SEGMENTS) -> Mesh:
    """Cylinder r = 20, height 40: two circular 90-degree edges."""
    return cylinder((0, 0), 20, 0, 40, segments)


def _part_cone(segments: int = SEGMENTS) -> Mesh:
    """Truncated cone r = 25 at the base to r = 10 at height 35 (23-degree half-angle):
    a 67-degree edge at the base circle, a 113-degree one at the top."""
    return frustum((0, 0), 25, 10, 0, 35, segments)


def _part_drilled_plate(segments: int = SEGMENTS) -> Mesh:
    """Plate 80 x 50 x 12 with three through holes (r = 5, 7, 9): rims at 90 degrees."""
    plate = box((0, 0, 0), (80, 50, 12))
    holes = [
        cylinder(c, r, -1, 13, segments) for c, r in (((16, 25), 5), ((38, 25), 7), ((62, 25), 9))
    ]
    return minus(plate, *holes)


def _part_concave_steps(segments: int = SEGMENTS) -> Mesh:
    """Three-step staircase 60 x 40 (steps 20 deep, 10 high): two concave 90-degree edges
    between the treads and the risers, and the convex nosings (``segments`` unused)."""
    return union(
        box((0, 0, 0), (60, 40, 10)),
        box((0, 0, 0), (40, 40, 20)),
        box((0, 0, 0), (20, 40, 30)),
    )


def _part_star_prism(segments: int = SEGMENTS) -> Mesh:
    """Five-pointed star prism (R = 30, height 20) with 45-degree tips: the vertical
    tip edges are acute (the faces turn by 135 degrees), the five inner ones concave
    (``segments`` unused)."""
    n, big = 5, 30.0
    t22 = math.tan(math.radians(22.5))
    small = big * t22 / (math.sin(math.pi / n) + t22 * math.cos(math.pi / n))
    ang = np.pi / 2 + np.pi * np.arange(2 * n) / n
    rad = np.where(np.arange(2 * n) % 2 == 0, big, small)
    return prism(np.c_[rad * np.cos(ang), rad * np.sin(ang)], 0, 20)


def _part_sphere(segments: int = SEGMENTS) -> Mesh:
    """Smooth control: sphere r = 25 (icosphere, 10242 vertices; ``segments`` unused)."""
    ms = pymeshlab.MeshSet()
    ms.create_sphere(radius=25.0, subdiv=5)
    m = ms.current_mesh()
    return m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64)


def _part_torus(segments: int = SEGMENTS) -> Mesh:
    """Smooth control: torus R = 25, r = 10."""
    return _torus(25.0, 10.0, segments, segments // 2)


def _part_rounded_box(segments: int = SEGMENTS) -> Mesh:
    """Smooth control: box 60 x 40 x 30 with every edge rounded (r = 8)."""
    return _rounded_box((30.0, 20.0, 15.0), 8.0, segments=segments)


def _wedge(angle: float) -> Mesh:
    """Triangular prism (height 30) whose apex edge has an interior dihedral angle of
    ``angle`` degrees: isosceles cross-section, legs 50 long; the two base edges have
    ``(180 - angle) / 2`` degrees, the end caps 90."""
    half = math.radians(angle) / 2
    tri = np.array([[0.0, 0.0], [50 * math.cos(half), -50 * math.sin(half)]])
    tri = np.vstack([tri, [50 * math.cos(half), 50 * math.sin(half)]])
    return prism(tri, 0.0, 30.0)


def _part_wedge30(segments: int = SEGMENTS) -> Mesh:
    """Acute wedge: a 30-degree apex edge (``segments`` unused)."""
    return _wedge(30.0)


def _part_wedge45(segments: int = SEGMENTS) -> Mesh:
    """Acute wedge: a 45-degree apex edge (``segments`` unused)."""
    return _wedge(45.0)


def _part_wedge60(segments: int = SEGMENTS) -> Mesh:
    """Acute wedge: a 60-degree apex edge (``segments`` unused)."""
    return _wedge(60.0)


PARTS: dict[str, Builder] = {
    **SAMPLE_PARTS,
    "box": _part_box,
    "chamfered_box": _part_chamfered_box,
    "cylinder": _part_cylinder,
    "cone": _part_cone,
    "drilled_plate": _part_drilled_plate,
    "concave_steps": _part_concave_steps,
    "star_prism": _part_star_prism,
    "wedge30": _part_wedge30,
    "wedge45": _part_wedge45,
    "wedge60": _part_wedge60,
    "sphere": _part_sphere,
    "torus": _part_torus,
    "rounded_box": _part_rounded_box,
}
"""Part name -> builder of its reference surface, given the segments per turn of its
round surfaces."""

SMOOTH_PARTS = ("sphere", "torus", "rounded_box")
"""Smooth controls: no sharp edges."""

SHARP_PARTS = (
    "fandisk",
    "box",
    "chamfered_box",
    "cylinder",
    "cone",
    "drilled_plate",
    "concave_steps",
    "star_prism",
)
"""The parts of the standard conditions (clean, noise, outliers, density, mesh, CAD)."""

ACUTE_PARTS = ("wedge30", "wedge45", "wedge60", "star_prism")
"""Parts with acute edges (30, 45, 60 degrees; the star's tips are 45 degrees)."""

ROUND_PARTS = ("fandisk", "cylinder", "cone", "drilled_plate")
"""Sharp parts with round surfaces: they have a coarse CAD tessellation."""

COARSE_SEGMENTS = 24
"""Segments per turn of a coarse CAD tessellation: facets turn by 15 degrees, below
``CREASE_ANGLE``, so the coarse part's exact edges are still its round rims."""


def part_names(*, smooth: bool | None = None) -> list[str]:
    """Names of the parts; ``smooth=True`` only the smooth controls, False only the others."""
    return [n for n in PARTS if smooth is None or (n in SMOOTH_PARTS) == smooth]


def reference_surface(
    name: str, segments: int = SEGMENTS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`meshlab_sharp.parts.reference_surface` of the part ``name`` of ``PARTS``;
    ``COARSE_SEGMENTS`` gives the coarse CAD tessellation."""
    return sample_parts.reference_surface(name, segments, parts=PARTS)


def make_part(
    name: str, kind: str = "points", *, n_points: int | None = None, seed: int = 0
) -> SamplePart:
    """:func:`meshlab_sharp.parts.make_part` of the part ``name`` (one of
    :func:`part_names`)."""
    return sample_parts.make_part(name, kind, n_points=n_points, seed=seed, parts=PARTS)
