"""The evaluation's ground truth: the parts of :mod:`evaluation.parts` (whose sharp
edges are known exactly), thin-walled parts, CAD tessellations, a simulated scan, and
corruptions of them.

Parts are built as :mod:`meshlab_sharp.parts` says: a reference surface, its exact
sharp edges, Poisson-disk points or an isotropic remesh.

The evaluation's **conditions** (``CONDITIONS``, ``suite``, ``make_condition``) add
corruptions (noise, outliers, a density gradient), CAD tessellations (``cad_part``: the
reference surface itself, also with ``COARSE_SEGMENTS``; ``openscad_part``: STL files
exported by OpenSCAD), thin-walled parts built for the sampling (``make_thin_part``),
acute wedges, and a simulated scan (``scan_part``, :mod:`evaluation.scan`).

>>> from evaluation.groundtruth import make_part, add_noise
>>> part = make_part("drilled_plate", n_points=20_000, seed=1)   # doctest: +SKIP
>>> noisy = add_noise(part, 0.25, seed=2)                          # doctest: +SKIP
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pymeshlab
from scipy.spatial import cKDTree

from meshlab_sharp.parts import (
    CREASE_ANGLE,
    DEFAULT_POINTS,
    SEGMENTS,
    Mesh,
    SamplePart,
    box,
    check_kind_and_count,
    crease_edges,
    crease_segments,
    cylinder,
    face_normals,
    float32_rounded,
    mesh_spacing,
    minus,
    sample_surface,
    sampled,
    union,
    vertex_normals,
)

from .parts import (
    ACUTE_PARTS,
    COARSE_SEGMENTS,
    PARTS,
    ROUND_PARTS,
    SHARP_PARTS,
    SMOOTH_PARTS,
    _convex_hull,
    make_part,
    part_names,
    reference_surface,
)
from .scan import scan, scanner_positions
from .scoring import POISSON_NN, density_spacing

__all__ = [
    "ACUTE_PARTS",
    "COARSE_SEGMENTS",
    "CONDITIONS",
    "CORRUPTIONS",
    "CREASE_ANGLE",
    "OPENSCAD_DIR",
    "OPENSCAD_PARTS",
    "PARTS",
    "ROUND_PARTS",
    "SCAN_NOISE",
    "SHARP_PARTS",
    "SMOOTH_PARTS",
    "THIN_PARTS",
    "Condition",
    "SamplePart",
    "add_noise",
    "add_outliers",
    "cad_part",
    "crease_segments",
    "density_gradient",
    "expected_spacing",
    "iid_part",
    "iid_points",
    "make_condition",
    "make_part",
    "make_thin_part",
    "openscad_part",
    "openscad_surface",
    "part_names",
    "reference_surface",
    "scan_part",
    "seen_creases",
    "suite",
    "thin_surface",
    "thin_wall",
    "weld",
]

# ----------------------------------------------------------------------------------
# Thin-walled parts: built for a wall thickness
# ----------------------------------------------------------------------------------


def _along_x(mesh: Mesh) -> Mesh:
    """Relabel axes (x, y, z) -> (z, x, y) (a rotation): a solid built along z then lies
    along x; its (x, y) centre becomes (y, z)."""
    return mesh[0][:, [2, 0, 1]].copy(), mesh[1]


def _thin_sheet_bracket(w: float, segments: int = SEGMENTS) -> Mesh:
    """Sheet-metal angle bracket: a 60 x 40 base and a 40-high upright of sheet ``w``
    thick, bent at a sharp 90 degrees (convex outside, concave inside), two r = 5
    holes in the base and an r = 6 hole in the upright."""
    base = box((0, 0, 0), (60, 40, w))
    upright = box((0, 0, 0), (w, 40, 40))
    holes = [cylinder((36, y), 5, -1, w + 1, segments) for y in (12, 28)]
    holes.append(_along_x(cylinder((20, 26), 6, -1, w + 1, segments)))
    return minus(union(base, upright), *holes)


def _thin_ribbed_housing(w: float, segments: int = SEGMENTS) -> Mesh:
    """Open box housing 80 x 50 x 30 with walls and floor ``w`` thick, two cross ribs
    (20 high) and a lengthwise rib (14 high), all ``w`` thick (``segments`` unused)."""
    shell = minus(box((0, 0, 0), (80, 50, 30)), box((w, w, w), (80 - w, 50 - w, 31)))
    ribs = [box((x - w / 2, w / 2, w / 2), (x + w / 2, 50 - w / 2, 20)) for x in (27.0, 53.0)]
    ribs.append(box((w / 2, 25 - w / 2, w / 2), (80 - w / 2, 25 + w / 2, 14)))
    return union(shell, *ribs)


def _thin_blade_rotor(w: float, segments: int = SEGMENTS) -> Mesh:
    """Rotor: a hub (r = 12, 20 high, r = 4 bore) with six flat blades ``w`` thick,
    reaching r = 40, 12 wide, pitched by 30 degrees."""
    pitch = math.radians(30.0)
    blades = []
    for k in range(6):
        phi = k * math.pi / 3
        corners = []
        for r in (8.0, 40.0):
            for t in (-w / 2, w / 2):
                for z in (-6.0, 6.0):
                    tp = t * math.cos(pitch) - z * math.sin(pitch)
                    zp = t * math.sin(pitch) + z * math.cos(pitch) + 10.0
                    corners.append(
                        (
                            r * math.cos(phi) - tp * math.sin(phi),
                            r * math.sin(phi) + tp * math.cos(phi),
                            zp,
                        )
                    )
        blades.append(_convex_hull(np.array(corners)))
    hub = cylinder((0, 0), 12, 0, 20, segments)
    return minus(union(hub, *blades), cylinder((0, 0), 4, -1, 21, segments))


def _thin_tube(w: float, segments: int = SEGMENTS) -> Mesh:
    """Tube: outer radius 15, wall ``w``, 40 long: four circular 90-degree edges."""
    return minus(cylinder((0, 0), 15, 0, 40, segments), cylinder((0, 0), 15 - w, -1, 41, segments))


THIN_PARTS: dict[str, Callable[[float], Mesh]] = {
    "sheet_bracket": _thin_sheet_bracket,
    "ribbed_housing": _thin_ribbed_housing,
    "blade_rotor": _thin_blade_rotor,
    "tube": _thin_tube,
}
"""Thin-walled part name -> builder of its reference surface for a wall thickness."""


def expected_spacing(area: float, n: int, kind: str) -> float:
    """Spacing that ``n`` points (or mesh vertices) on a surface of ``area`` will have.

    Clouds: ``evaluation.POISSON_NN * sqrt(area / n)`` (0.78); meshes: the remesher's
    target edge length ``sqrt(2 area / (sqrt(3) n))`` (the edge of an equilateral mesh
    with n vertices).
    """
    if kind == "points":
        return POISSON_NN * math.sqrt(area / n)
    return math.sqrt(2.0 * area / (math.sqrt(3.0) * n))


@functools.cache
def _thin_cached(name: str, wall: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    verts, faces = THIN_PARTS[name](wall)
    out = (verts, faces, crease_segments(verts, faces))
    for a in out:
        a.setflags(write=False)
    return out


def thin_wall(name: str, spacings: float, n: int, kind: str = "points") -> float:
    """Wall thickness that is ``spacings`` times the spacing of ``n`` samples of the part.

    The spacing depends on the part's area A, which depends on the wall w: A is linear
    in w for these parts (walls, rims and hole walls grow with w) up to the corners where
    walls meet; A(w) = a + b w is fitted through the parts built with w = 1 and w = 3,
    and ``w = spacings * expected_spacing(a + b w, n, kind)`` solved exactly.
    """
    if name not in THIN_PARTS:
        raise KeyError(f"unknown thin part {name!r}; known: {', '.join(THIN_PARTS)}")
    areas = []
    for w in (1.0, 3.0):
        verts, faces, _ = _thin_cached(name, w)
        areas.append(float(face_normals(verts, faces)[1].sum()))
    b = (areas[1] - areas[0]) / 2.0
    a = areas[0] - b
    # w = spacings * c * sqrt(A / n) with c from expected_spacing: w^2 = k (a + b w)
    k = (spacings * expected_spacing(1.0, n, kind)) ** 2
    return round(0.5 * (k * b + math.sqrt(k * k * b * b + 4.0 * k * a)), 6)


def thin_surface(name: str, wall: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The thin-walled part ``name`` with wall ``wall``: reference mesh and sharp edges.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    edges : (e, 2, 3) float64
    """
    if name not in THIN_PARTS:
        raise KeyError(f"unknown thin part {name!r}; known: {', '.join(THIN_PARTS)}")
    return _thin_cached(name, round(float(wall), 6))


def make_thin_part(
    name: str,
    spacings: float,
    kind: str = "points",
    *,
    n_points: int | None = None,
    seed: int = 0,
) -> SamplePart:
    """A thin-walled part whose walls are ``spacings`` point spacings thick.

    The part is built for the sampling: its wall is ``thin_wall(name, spacings, n,
    kind)``, ``spacings`` times the spacing that n samples of it will have (clouds:
    mean nearest-neighbour distance; meshes: mean edge length, within a few %).
    ``extra["wall"]`` holds the wall thickness.

    Parameters
    ----------
    name : str
        One of ``THIN_PARTS``.
    spacings : float
        Wall thickness in point spacings.
    kind, n_points, seed
        As for ``make_part``.

    Returns
    -------
    SamplePart
    """
    n = check_kind_and_count(kind, n_points)
    wall = thin_wall(name, spacings, n, kind)
    part = sampled(name, thin_surface(name, wall), kind, n, seed)
    return replace(part, extra={**part.extra, "wall": wall})


def cad_part(name: str, segments: int = SEGMENTS) -> SamplePart:
    """A part as a CAD exporter writes it: the CSG kernel's own triangulation.

    The reference surface itself (long thin triangles, vertices only where faces meet,
    plus the centre of each fanned cap), not remeshed; ``segments`` per turn of the
    round surfaces (``COARSE_SEGMENTS`` for a coarse export; its exact edges are
    those of the coarse solid). Scored per vertex (``extra["scoring"] = "vertices"``):
    a vertex is a true feature when it lies on an exact edge.

    Returns
    -------
    SamplePart
        ``kind`` "mesh", ``spacing`` the mean edge length.
    """
    verts, faces, edges = reference_surface(name, segments)
    return _tessellation(name, verts, faces, edges)


def _tessellation(name: str, verts: np.ndarray, faces: np.ndarray, edges: np.ndarray) -> SamplePart:
    """A CAD tessellation as a SamplePart scored per vertex."""
    pts = float32_rounded(verts)
    return SamplePart(
        name=name,
        vertices=pts,
        faces=np.asarray(faces, np.int64),
        edges=edges,
        spacing=mesh_spacing(pts, faces),
        normals=vertex_normals(pts, faces),
        outliers=np.zeros(len(pts), bool),
        kind="mesh",
        extra={"reference": (verts, faces), "scoring": "vertices"},
    )


OPENSCAD_DIR = Path(__file__).resolve().parent / "data" / "openscad"
"""OpenSCAD models (``.scad``) and the STL files OpenSCAD 2021.01 exported from them
(``openscad -o name.stl name.scad``; stored as binary STL, re-encoded by pymeshlab: the
same float32 coordinates)."""

OPENSCAD_PARTS = (
    "scad_bracket",
    "scad_pocket_plate",
    "scad_flanged_pipe",
    "scad_knob",
    "scad_handle",
)
"""Parts exported by OpenSCAD (file ``OPENSCAD_DIR / name[5:] + ".stl"``)."""


def weld(verts: np.ndarray, faces: np.ndarray) -> Mesh:
    """Merge identical vertices (an STL file repeats them per triangle), as MeshLab does
    on load, and drop the triangles that collapse.

    Parameters
    ----------
    verts : (n, 3) float
    faces : (m, 3) int

    Returns
    -------
    vertices : (k, 3) float64, faces : (m', 3) int64
    """
    uniq, inv = np.unique(np.asarray(verts, np.float64), axis=0, return_inverse=True)
    f = inv.reshape(-1)[np.asarray(faces, np.int64)]
    good = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])
    return uniq, f[good]


@functools.cache
def _openscad_cached(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(OPENSCAD_DIR / f"{name[len('scad_') :]}.stl"))
    m = ms.current_mesh()
    verts, faces = weld(m.vertex_matrix(), m.face_matrix())
    out = (verts, faces, crease_segments(verts, faces))
    for a in out:
        a.setflags(write=False)
    return out


def openscad_surface(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An OpenSCAD export, welded, and its exact sharp edges.

    The edges are the mesh edges whose faces turn by more than ``CREASE_ANGLE``: exact
    for these models, whose round surfaces have ``$fn >= 24`` (facets turn by at most
    15 degrees) and whose designed edges all turn by 45 degrees or more (the tests
    check that no dihedral angle lies between 16 and 40 degrees).

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    edges : (e, 2, 3) float64
    """
    if name not in OPENSCAD_PARTS:
        raise KeyError(f"unknown OpenSCAD part {name!r}; known: {', '.join(OPENSCAD_PARTS)}")
    return _openscad_cached(name)


def openscad_part(name: str) -> SamplePart:
    """An OpenSCAD export as a CAD tessellation (scored per vertex, see ``cad_part``)."""
    return _tessellation(name, *openscad_surface(name))


SCAN_NOISE = 0.1
"""Range noise of the simulated scan at the scanners' mean distance, in pixel footprints
there (it grows with the square of the range; see ``scan.scan``)."""


def _subdivide(segments: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Cut segments into pieces at most ``step`` long: (p, 2, 3) pieces and the (p,)
    index of the segment each comes from."""
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    counts = np.maximum(1, np.ceil(lengths / step).astype(np.int64))
    sid = np.repeat(np.arange(len(segments)), counts)
    k = np.arange(len(sid)) - np.repeat(np.cumsum(counts) - counts, counts)
    a, ab = segments[sid, 0], segments[sid, 1] - segments[sid, 0]
    t0 = (k / counts[sid])[:, None]
    t1 = ((k + 1) / counts[sid])[:, None]
    return np.stack([a + t0 * ab, a + t1 * ab], axis=1), sid


def seen_creases(
    verts: np.ndarray,
    faces: np.ndarray,
    surface: np.ndarray,
    normals: np.ndarray,
    spacing: np.ndarray,
    *,
    radius: float = 2.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The pieces of a mesh's sharp edges, and which of them a scan saw from both sides.

    The edges are cut into pieces of half the median spacing; a piece is
    seen when each of its two faces has a scan point within ``radius`` times that
    point's own spacing of it (a point is on face a when its normal is within 30 degrees
    of a's and nearer to a's than to b's; the two faces may be sampled at different
    densities). An edge seen from one side only, or not at all, cannot be found as a
    crease.

    Parameters
    ----------
    verts : (n, 3) float
    faces : (m, 3) int
        The scanned mesh.
    surface : (k, 3) float
        Exact positions of the scan points on the mesh (before noise).
    normals : (k, 3) float
        Normal of the triangle each scan point lies on.
    spacing : (k,) float
        Local spacing of the scan points.
    radius : float
        In spacings.

    Returns
    -------
    pieces : (p, 2, 3) float64
        The pieces of the sharp edges.
    seen : (p,) bool
        The pieces seen from both sides.
    """
    v = np.asarray(verts, np.float64)
    ends, fa, fb, fn = crease_edges(v, np.asarray(faces, np.int64), CREASE_ANGLE)
    if len(ends) == 0 or len(surface) == 0:
        return np.zeros((0, 2, 3)), np.zeros(0, bool)
    spacing = np.asarray(spacing, np.float64)
    pieces, sid = _subdivide(v[ends], float(np.median(spacing)) / 2)
    mid = pieces.mean(axis=1)
    reach = radius * float(np.percentile(spacing, 99))
    pairs = cKDTree(mid).sparse_distance_matrix(cKDTree(surface), reach, output_type="ndarray")
    pid, idx = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    near = pairs["v"] <= radius * spacing[idx]
    ca = np.einsum("kj,kj->k", normals[idx], fn[fa[sid[pid]]])
    cb = np.einsum("kj,kj->k", normals[idx], fn[fb[sid[pid]]])
    c30 = math.cos(math.radians(30.0))
    side_a = np.bincount(pid[near & (ca > c30) & (ca > cb)], minlength=len(mid)) > 0
    side_b = np.bincount(pid[near & (cb > c30) & (cb > ca)], minlength=len(mid)) > 0
    return pieces, side_a & side_b


def scan_part(
    name: str, *, n_points: int = DEFAULT_POINTS, seed: int = 0, noise: float = SCAN_NOISE
) -> SamplePart:
    """Part ``name`` scanned from four positions (``scan.scanner_positions``) and merged.

    About ``n_points`` points (see :func:`evaluation.scan.scan`): occlusion, density
    falling with range, range noise growing with range squared (``noise`` pixel
    footprints at the scanners' mean distance). ``extra["local_spacing"]`` (n,) is each
    point's spacing from the local density (``evaluation.density_spacing``: where views
    overlap, nearest-neighbour distances are no measure of the gaps), used for scoring;
    ``extra["visible_edges"]`` the
    pieces of the sharp edges seen from both sides (:func:`seen_creases`): coverage is
    measured on those only, precision against all the edges.
    """
    verts, faces, edges = reference_surface(name)
    res = scan(verts, faces, scanner_positions(verts), n_points=n_points, noise=noise, seed=seed)
    pts = float32_rounded(res.points)
    local = density_spacing(pts)
    pieces, seen = seen_creases(verts, faces, res.surface, res.normals, local)
    return SamplePart(
        name=name,
        vertices=pts,
        faces=None,
        edges=edges,
        spacing=float(local.mean()),
        normals=res.normals,
        outliers=np.zeros(len(pts), bool),
        kind="points",
        seed=seed,
        extra={
            "reference": (verts, faces),
            "local_spacing": local,
            "visible_edges": pieces[seen],
            "view": res.view,
        },
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
    return replace(part, vertices=float32_rounded(part.vertices + delta))


def iid_points(
    verts: np.ndarray, faces: np.ndarray, n: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """n points drawn independently, uniform over the mesh's area (as MeshLab's "sample
    points on mesh" does): (n, 3) points and (n, 3) their faces' unit normals."""
    rng = np.random.default_rng(seed)
    cross = np.cross(
        verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]]
    )
    area = np.linalg.norm(cross, axis=1)
    f = rng.choice(len(faces), size=n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    v = verts[faces[f]]
    pts = (
        (1 - r1)[:, None] * v[:, 0]
        + (r1 * (1 - r2))[:, None] * v[:, 1]
        + (r1 * r2)[:, None] * v[:, 2]
    )
    return pts, cross[f] / np.maximum(area[f], 1e-300)[:, None]


def iid_part(part: SamplePart, *, seed: int = 0) -> SamplePart:
    """The part's reference surface sampled with as many points drawn independently
    (:func:`iid_points`) instead of Poisson-disk ones; the spacing is kept (that of the
    Poisson-disk cloud, whose density it has)."""
    verts, faces = part.extra["reference"]
    pts, nrm = iid_points(np.asarray(verts, np.float64), np.asarray(faces), part.n, seed)
    return replace(part, vertices=float32_rounded(pts), normals=nrm)


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
    out = float32_rounded(out[:k])
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

    pts, nrm = sample_surface(verts, faces, part.n, part.seed if seed is None else seed, dens)
    pts = float32_rounded(pts)
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


# ----------------------------------------------------------------------------------
# The evaluation's conditions
# ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Condition:
    """One condition of the evaluation: how a part is turned into a detector's input.

    Attributes
    ----------
    name : str
        Key of ``CONDITIONS``.
    group : str
        The target it counts towards ("clean", "cad", "thin", "noise",
        "outliers_density", "acute", "scan", "mesh", "smooth").
    parts : tuple of str
        Parts it applies to.
    quick_parts : tuple of str
        Parts of the quick suite (may be empty).
    description : str
        One line for tables.
    """

    name: str
    group: str
    parts: tuple[str, ...]
    quick_parts: tuple[str, ...]
    description: str


_SCAN_PARTS = ("fandisk", "box", "drilled_plate", "concave_steps", "chamfered_box", "rounded_box")
_THIN = tuple(THIN_PARTS)


def _conditions() -> dict[str, Condition]:
    c = [
        Condition("clean", "clean", SHARP_PARTS, SHARP_PARTS, "Poisson-disk cloud, no noise"),
        Condition("noise10", "noise", SHARP_PARTS, (), "normal noise, sigma 10 % of spacing"),
        Condition("noise25", "noise", SHARP_PARTS, SHARP_PARTS, "normal noise, 25 % of spacing"),
        Condition("noise50", "noise", SHARP_PARTS, SHARP_PARTS, "normal noise, 50 % of spacing"),
        Condition("outliers1", "outliers_density", SHARP_PARTS, SHARP_PARTS, "1 % far outliers"),
        Condition(
            "density4",
            "outliers_density",
            SHARP_PARTS,
            SHARP_PARTS,
            "half the part 4x denser (scored with each side's spacing)",
        ),
        Condition("mesh", "mesh", SHARP_PARTS, SHARP_PARTS, "isotropic remesh, n/2 vertices"),
        Condition(
            "cad",
            "cad",
            SHARP_PARTS + SMOOTH_PARTS,
            SHARP_PARTS + SMOOTH_PARTS,
            "CSG kernel's triangulation, 128 segments/turn (per-vertex scores)",
        ),
        Condition(
            "cad_coarse",
            "cad",
            ROUND_PARTS,
            ROUND_PARTS,
            f"CSG triangulation, {COARSE_SEGMENTS} segments/turn (per-vertex scores)",
        ),
        Condition(
            "openscad",
            "cad",
            OPENSCAD_PARTS,
            OPENSCAD_PARTS,
            "STL exported by OpenSCAD, welded (per-vertex scores)",
        ),
    ]
    for t in (1, 2, 3):
        c.append(Condition(f"thin{t}", "thin", _THIN, _THIN, f"cloud, walls {t} spacings thick"))
        c.append(
            Condition(
                f"thin{t}_mesh",
                "thin",
                _THIN,
                _THIN if t == 1 else (),
                f"mesh, walls {t} edges thick",
            )
        )
    c += [
        Condition("acute", "acute", ACUTE_PARTS, ACUTE_PARTS, "cloud, edges of 30 to 60 degrees"),
        Condition(
            "acute_mesh", "acute", ACUTE_PARTS, ACUTE_PARTS, "mesh, edges of 30 to 60 degrees"
        ),
        Condition(
            "scan",
            "scan",
            _SCAN_PARTS,
            ("fandisk", "drilled_plate", "rounded_box"),
            "4 scanner views merged: occlusion, range noise, density falling with range",
        ),
        Condition("smooth", "smooth", SMOOTH_PARTS, SMOOTH_PARTS, "smooth control, clean cloud"),
        Condition("smooth_mesh", "smooth", SMOOTH_PARTS, (), "smooth control, isotropic mesh"),
    ]
    return {x.name: x for x in c}


CONDITIONS: dict[str, Condition] = _conditions()
"""Condition name -> Condition, in table order."""


def suite(
    *,
    quick: bool = False,
    conditions: Sequence[str] | None = None,
    parts: Sequence[str] | None = None,
) -> list[tuple[str, str]]:
    """The (part, condition) pairs of the evaluation, condition by condition.

    Parameters
    ----------
    quick : bool
        Only each condition's ``quick_parts``.
    conditions : sequence of str, optional
        Only these conditions (default all, in ``CONDITIONS`` order).
    parts : sequence of str, optional
        Only these parts.

    Returns
    -------
    list of (part, condition)
    """
    names = list(CONDITIONS) if conditions is None else list(conditions)
    unknown = [c for c in names if c not in CONDITIONS]
    if unknown:
        raise KeyError(f"unknown conditions {unknown}; known: {', '.join(CONDITIONS)}")
    out = []
    for c in names:
        cond = CONDITIONS[c]
        for p in cond.quick_parts if quick else cond.parts:
            if parts is None or p in parts:
                out.append((p, c))
    return out


def make_condition(name: str, condition: str, *, n_points: int, seed: int = 0) -> SamplePart:
    """Part ``name`` under ``condition`` (see ``CONDITIONS``), ready to detect and score.

    Parameters
    ----------
    name : str
        A part the condition applies to (``CONDITIONS[condition].parts``).
    condition : str
    n_points : int
        Points of a cloud; meshes get ``n_points // 2`` vertices (at least 200), a scan
        about ``n_points`` points; CAD tessellations do not depend on it.
    seed : int
        Seed of the sampling; noise and outliers use ``seed + 1``.

    Returns
    -------
    SamplePart
        ``extra["scoring"]`` is "vertices" for CAD tessellations (score with
        ``evaluation.score_part``, which reads it).
    """
    if condition not in CONDITIONS:
        raise KeyError(f"unknown condition {condition!r}; known: {', '.join(CONDITIONS)}")
    if name not in CONDITIONS[condition].parts:
        raise ValueError(f"condition {condition!r} does not apply to part {name!r}")
    n_mesh = max(n_points // 2, 200)
    if condition in ("clean", "acute", "smooth"):
        return make_part(name, n_points=n_points, seed=seed)
    if condition in ("mesh", "acute_mesh", "smooth_mesh"):
        return make_part(name, "mesh", n_points=n_mesh)
    if condition.startswith("noise"):
        clean = make_part(name, n_points=n_points, seed=seed)
        return add_noise(clean, int(condition[5:]) / 100.0, seed=seed + 1)
    if condition == "outliers1":
        return add_outliers(make_part(name, n_points=n_points, seed=seed), 0.01, seed=seed + 1)
    if condition == "density4":
        return density_gradient(make_part(name, n_points=n_points, seed=seed), 4.0)
    if condition == "cad":
        return cad_part(name)
    if condition == "cad_coarse":
        return cad_part(name, COARSE_SEGMENTS)
    if condition == "openscad":
        return openscad_part(name)
    if condition.startswith("thin"):
        t = int(condition[4])
        if condition.endswith("_mesh"):
            return make_thin_part(name, t, "mesh", n_points=n_mesh)
        return make_thin_part(name, t, n_points=n_points, seed=seed)
    if condition == "scan":
        return scan_part(name, n_points=n_points, seed=seed)
    raise AssertionError(condition)  # every CONDITIONS key is handled above
