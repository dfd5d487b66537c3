"""The inputs made from a CAD part loaded in gmsh: meshes, clouds and a scan.

- **fine mesh**: gmsh's Frontal-Delaunay mesh, edge ``h`` for about ``n`` vertices,
  refined where the surface curves (at least :data:`FINE_PER_TURN` elements per turn);
  the B-rep curves are mesh edges. It is also the surface the clouds are drawn from.
- **STL-like**: :data:`COARSE_PER_TURN` segments per turn, no size limit otherwise and
  no sizes carried from the boundary into the faces: long thin triangles, vertices
  only on the curves of planar faces.
- **blue noise**: Poisson-disk points (``meshlab_sharp.parts``' sampler) on the fine
  mesh; **noise 25 %**: the same moved along the true normal by N(0, (0.25 s)^2);
  **iid**: points drawn independently, uniform over the area;
- **scan**: ``evaluation.scan`` from four positions around the fine mesh. A piece of
  the exact edges is **seen** when a piece of the mesh's creases with scan points on
  both sides (``evaluation.groundtruth.seen_creases``) lies within half a spacing of
  its midpoint, on the same B-rep curve (a crease piece is on the curve of the exact
  piece nearest it; the end of a curve that was not seen is not seen through its
  neighbour's crease); ``extra["visible_edges"]`` holds the seen pieces and
  ``extra["seen"]`` marks them among the exact edges.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from evaluation.groundtruth import (
    SCAN_NOISE,
    SamplePart,
    add_noise,
    expected_spacing,
    iid_points,
    seen_creases,
    weld,
)
from evaluation.scan import scan, scanner_positions
from evaluation.scoring import density_spacing, sample_segments
from meshlab_sharp.parts import float32_rounded, mesh_spacing, sample_surface, vertex_normals

__all__ = [
    "COARSE_PER_TURN",
    "FINE_PER_TURN",
    "INPUTS",
    "gmsh_mesh",
    "make_inputs",
    "surface_area",
]

#: Elements per turn of a curved surface in the fine mesh.
FINE_PER_TURN = 48
#: Segments per turn in the STL-like tessellation.
COARSE_PER_TURN = 24
#: The inputs, in table order.
INPUTS = ("fine_mesh", "stl_like", "blue_noise", "noise25", "iid", "scan")


def surface_area() -> float:
    """Total area of the loaded model's surfaces."""
    import gmsh

    return float(sum(gmsh.model.occ.getMass(2, s) for _, s in gmsh.model.getEntities(2)))


def gmsh_mesh(size: float, per_turn: int, *, extend: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate the loaded model's surfaces; identical nodes welded.

    Parameters
    ----------
    size : float
        Largest element size.
    per_turn : int
        Elements per turn on curved curves and surfaces (0: off).
    extend : bool
        Carry the curves' element sizes into the faces (False: planar faces get
        long thin triangles between their boundary nodes).

    Returns
    -------
    vertices : (n, 3) float64, faces : (m, 3) int64
    """
    import gmsh

    gmsh.model.mesh.clear()
    for key, value in (
        ("Mesh.MeshSizeMin", 0.0),
        ("Mesh.MeshSizeMax", size),
        ("Mesh.MeshSizeFromCurvature", per_turn),
        ("Mesh.MeshSizeExtendFromBoundary", int(extend)),
        ("Mesh.MeshSizeFromPoints", 0),
        ("Mesh.MeshSizeFactor", 1.0),
        ("Mesh.Algorithm", 6 if extend else 1),
        ("General.NumThreads", 1),
    ):
        gmsh.option.setNumber(key, value)
    gmsh.model.mesh.generate(2)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(tags.max()) + 1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    _, nodes = gmsh.model.mesh.getElementsByType(2)
    faces = index[np.asarray(nodes, np.int64)].reshape(-1, 3)
    verts = np.asarray(coords, np.float64).reshape(-1, 3)
    used = np.unique(faces)
    remap = np.zeros(len(verts), np.int64)
    remap[used] = np.arange(len(used))
    verts, faces = weld(float32_rounded(verts[used]), remap[faces])
    return verts, faces


def _part(
    name: str,
    verts: np.ndarray,
    faces: np.ndarray | None,
    normals: np.ndarray,
    edges: np.ndarray,
    spacing: float,
    reference: tuple,
    **extra: object,
) -> SamplePart:
    return SamplePart(
        name=name,
        vertices=float32_rounded(verts),
        faces=faces,
        edges=edges,
        spacing=spacing,
        normals=normals,
        outliers=np.zeros(len(verts), bool),
        kind="points" if faces is None else "mesh",
        extra={"reference": reference, **extra},
    )


def _seen_pieces(
    edges: np.ndarray, curve: np.ndarray, pieces: np.ndarray, seen: np.ndarray, spacing: float
) -> np.ndarray:
    """Which pieces of the exact edges a scan saw: those within half a spacing of a seen
    piece of the mesh's creases on the same curve (a crease piece is on the curve of
    the exact piece nearest it).

    Parameters
    ----------
    edges : (e, 2, 3) float
        The exact edges' pieces.
    curve : (e,) int
        The curve of each.
    pieces : (p, 2, 3) float, seen : (p,) bool
        ``evaluation.groundtruth.seen_creases``.
    spacing : float

    Returns
    -------
    (e,) bool
    """
    near = np.zeros(len(edges), bool)
    if not np.any(seen) or len(edges) == 0:
        return near
    exact, _, sid = sample_segments(edges, spacing / 8)
    crease, _, _ = sample_segments(pieces[seen], spacing / 8)
    crease_curve = curve[sid[cKDTree(exact).query(crease)[1]]]
    pairs = cKDTree(edges.mean(axis=1)).sparse_distance_matrix(
        cKDTree(crease), spacing / 2, output_type="ndarray"
    )
    i, j = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    near[i[curve[i] == crease_curve[j]]] = True
    return near


def make_inputs(
    name: str,
    edges: np.ndarray,
    n: int,
    *,
    seed: int = 0,
    which: tuple[str, ...] = INPUTS,
    curve: np.ndarray | None = None,
) -> dict[str, SamplePart]:
    """The inputs of the part loaded in gmsh.

    Parameters
    ----------
    name : str
    edges : (e, 2, 3) float
        The exact sharp edges (``BrepTruth.segments``).
    n : int
        Points per cloud and about the fine mesh's vertex count.
    seed : int
    which : tuple of str
        Names from :data:`INPUTS`.
    curve : (e,) int, optional
        The B-rep curve of each piece of ``edges`` (``BrepTruth.segment_curve``): the
        scan's seen pieces are matched to creases of their own curve (default: one
        curve).

    Returns
    -------
    dict of str to SamplePart
        ``stl_like``'s ``spacing`` is the blue-noise spacing (its curves are scored at
        the clouds' tolerance); ``fine_mesh``'s is its mean edge length; ``scan``'s is
        its mean local spacing, with ``extra`` ``local_spacing``, ``visible_edges`` and
        ``seen`` (the module's docstring).
    """
    area = surface_area()
    h = expected_spacing(area, n, "mesh")
    s = expected_spacing(area, n, "points")
    fv, ff = gmsh_mesh(h, FINE_PER_TURN)
    ref = (fv, ff)
    out: dict[str, SamplePart] = {}
    if "fine_mesh" in which:
        out["fine_mesh"] = _part(
            name, fv, ff, vertex_normals(fv, ff), edges, mesh_spacing(fv, ff), ref
        )
    if {"blue_noise", "noise25"} & set(which):
        pts, nrm = sample_surface(fv, ff, n, seed)
        blue = _part(name, pts, None, nrm, edges, s, ref)
        out["blue_noise"] = blue
        out["noise25"] = add_noise(blue, 0.25, seed=seed + 1)
    if "iid" in which:
        pts, nrm = iid_points(fv, ff, n, seed + 2)
        out["iid"] = _part(name, pts, None, nrm, edges, s, ref)
    if "scan" in which:
        res = scan(fv, ff, scanner_positions(fv), n_points=n, noise=SCAN_NOISE, seed=seed + 3)
        local = density_spacing(float32_rounded(res.points))
        creases = seen_creases(fv, ff, res.surface, res.normals, local)
        curves = np.zeros(len(edges), np.int64) if curve is None else np.asarray(curve)
        near = _seen_pieces(edges, curves, *creases, s)
        out["scan"] = _part(
            name,
            res.points,
            None,
            res.normals,
            edges,
            float(local.mean()),
            ref,
            local_spacing=local,
            visible_edges=edges[near],
            seen=near,
        )
    if "stl_like" in which:
        diag = math.dist(fv.min(axis=0), fv.max(axis=0))
        cv, cf = gmsh_mesh(diag, COARSE_PER_TURN, extend=False)
        out["stl_like"] = _part(name, cv, cf, vertex_normals(cv, cf), edges, s, ref)
    return {k: out[k] for k in which}
