"""A simulated range scanner: perspective depth cameras around a triangle mesh.

Each scanner is a pinhole depth camera (a structured-light or time-of-flight sensor)
looking at the centre of the part's bounding box, with a square grid of pixels that
just covers the part's bounding sphere, the same angular step in every view (one
scanner moved around the part). Every pixel casts one ray; the ray's first hit
on the mesh (exact ray-triangle intersection, so occlusion is exact) is a point. This
gives what a scanner gives:

- **occlusion**: only surfaces seen from a viewpoint are sampled;
- **density falling with distance**: pixels are a fixed angle apart, so the spacing of
  the points grows with range (and with the incidence angle);
- **grazing angles dropped**: hits more than ``max_incidence`` degrees from head-on
  are lost, as a real sensor loses them;
- **noise growing with range**: each point moves along its ray by N(0, sigma^2) with
  ``sigma = noise * footprint(D) * (range / D)^2``, where D is the scanners' mean
  distance to the part's centre and ``footprint(D)`` the pixel spacing at that
  distance: the depth error of triangulation and time-of-flight sensors grows with
  the square of the range.

The views are merged into one cloud (overlaps are denser: no resampling).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["ScanResult", "first_hits", "scan", "scanner_positions"]


@dataclass(frozen=True)
class ScanResult:
    """The merged cloud of a simulated scan.

    Attributes
    ----------
    points : (n, 3) float64
        Measured points (with noise).
    surface : (n, 3) float64
        The exact hits on the mesh (before noise).
    normals : (n, 3) float64
        Unit normal of the triangle each ray hit.
    face : (n,) int64
        Index of the triangle each ray hit.
    view : (n,) int64
        Index of the scanner that measured each point.
    footprint : (n,) float64
        Pixel spacing at each point's range (range times the pixel's angle).
    """

    points: np.ndarray
    surface: np.ndarray
    normals: np.ndarray
    face: np.ndarray
    view: np.ndarray
    footprint: np.ndarray


def scanner_positions(
    verts: np.ndarray,
    azimuths: tuple[float, ...] = (30.0, 125.0, 215.0, 305.0),
    elevations: tuple[float, ...] = (35.0, 50.0, 25.0, 40.0),
    distances: tuple[float, ...] = (2.2, 3.0, 2.6, 3.4),
) -> np.ndarray:
    """Scanner positions around a part, as a user places a scanner on a table.

    Parameters
    ----------
    verts : (n, 3) float
        The part's vertices (z up; the underside is never seen).
    azimuths, elevations : degrees, one per scanner
    distances : distance from the bounding-box centre, in bounding-sphere radii

    Returns
    -------
    (k, 3) float64
    """
    v = np.asarray(verts, np.float64)
    centre = 0.5 * (v.min(0) + v.max(0))
    radius = float(np.linalg.norm(v - centre, axis=1).max())
    az = np.radians(azimuths)
    el = np.radians(elevations)
    d = np.asarray(distances, np.float64) * radius
    return centre + d[:, None] * np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]


def _camera(centre: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(3, 3) rows: right, up, forward of a camera at origin looking at centre."""
    f = centre - origin
    f /= np.linalg.norm(f)
    up = np.array([0.0, 0.0, 1.0]) if abs(f[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    return np.stack([r, np.cross(r, f), f])


def first_hits(
    verts: np.ndarray, faces: np.ndarray, origin: np.ndarray, frame: np.ndarray, half: float, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cast the rays of an n x n pinhole camera and find their first hits.

    The pixel (i, j) centre is at image coordinates ``u = -half + (i + 1/2) 2 half / n``
    (and v likewise with j); its ray is ``origin + t * frame.T @ (u, v, 1)``. The mesh
    must lie in front of the camera (every vertex at positive depth). A triangle's
    image is the triangle of its vertices' images, so each triangle is tested against
    the pixels of its image's bounding box only (Moller-Trumbore, both sides).

    Parameters
    ----------
    verts : (n_v, 3) float
    faces : (m, 3) int
    origin : (3,) float
    frame : (3, 3) float
        Rows: the camera's right, up and forward unit vectors.
    half : float
        Tangent of the half field of view.
    n : int
        Pixels per side.

    Returns
    -------
    pixel : (h,) int64
        Pixels with a hit (``i * n + j``).
    t : (h,) float64
        Ray parameter of the first hit (depth along the forward axis).
    face : (h,) int64
        Triangle of the first hit.
    """
    cam = (np.asarray(verts, np.float64) - origin) @ frame.T  # (n_v, 3): x, y, depth
    if cam[:, 2].min() <= 0:
        raise ValueError("the mesh must lie in front of the camera")
    uv = cam[:, :2] / cam[:, 2:]
    tri_uv = uv[faces]  # (m, 3, 2)
    step = 2.0 * half / n
    lo = np.ceil((tri_uv.min(1) + half) / step - 0.5).astype(np.int64).clip(0, n)
    hi = np.floor((tri_uv.max(1) + half) / step - 0.5).astype(np.int64).clip(-1, n - 1)
    ni = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    nj = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    count = ni * nj
    tri = np.repeat(np.arange(len(faces)), count)
    k = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    i = lo[tri, 0] + k // nj[tri]
    j = lo[tri, 1] + k % nj[tri]
    d = np.c_[-half + (i + 0.5) * step, -half + (j + 0.5) * step, np.ones(len(i))]
    a = cam[faces[tri, 0]]
    e1 = cam[faces[tri, 1]] - a
    e2 = cam[faces[tri, 2]] - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12 * np.abs(e1).max() * np.abs(e2).max()
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = -a
    bu = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    bv = np.einsum("ij,ij->i", d, q) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (t > 0)
    pix = (i * n + j)[hit]
    t, tri = t[hit], tri[hit]
    order = np.lexsort((t, pix))  # by pixel, nearest first
    pix, t, tri = pix[order], t[order], tri[order]
    first = np.r_[True, pix[1:] != pix[:-1]]
    return pix[first], t[first], tri[first]


def scan(
    verts: np.ndarray,
    faces: np.ndarray,
    scanners: np.ndarray,
    *,
    n_points: int,
    noise: float = 0.1,
    max_incidence: float = 75.0,
    seed: int = 0,
) -> ScanResult:
    """Scan a closed triangle mesh from several positions and merge the views.

    One scanner, moved to each position: the same angular step in every view (found so
    that the merged cloud has about ``n_points`` points), so farther views give fewer,
    sparser points.

    Parameters
    ----------
    verts : (n_v, 3) float
    faces : (m, 3) int
        A closed, outward-oriented mesh.
    scanners : (k, 3) float
        Scanner positions, outside the part's bounding sphere.
    n_points : int
        About how many points the merged cloud has (within a few %).
    noise : float
        Standard deviation of the range noise at the scanners' mean distance D to the
        part's centre, in pixel footprints there (``angle step * D``); it grows with
        the square of the range: ``sigma(r) = noise * step * r^2 / D``.
    max_incidence : float
        Degrees: hits farther than this from head-on are dropped.
    seed : int
        Seed of the noise.

    Returns
    -------
    ScanResult
    """
    v = np.asarray(verts, np.float64)
    f = np.asarray(faces, np.int64)
    origins = np.asarray(scanners, np.float64).reshape(-1, 3)
    centre = 0.5 * (v.min(0) + v.max(0))
    radius = float(np.linalg.norm(v - centre, axis=1).max())
    dists = np.linalg.norm(origins - centre, axis=1)
    if np.any(dists <= radius):
        raise ValueError("every scanner must lie outside the part's bounding sphere")
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    cos_max = math.cos(math.radians(max_incidence))
    frames = [_camera(centre, o) for o in origins]
    # image half-widths (tangent of the half field of view) covering the bounding sphere
    halves = 1.02 * np.tan(np.arcsin(radius / dists))

    def shoot(step: float) -> list[tuple[np.ndarray, ...]]:
        views = []
        for origin, frame, half in zip(origins, frames, halves, strict=True):
            n = max(4, math.ceil(2.0 * half / step))
            h = 0.5 * n * step
            pix, t, tri = first_hits(v, f, origin, frame, h, n)
            uv = np.c_[-h + (pix // n + 0.5) * step, -h + (pix % n + 0.5) * step]
            ray = np.c_[uv, np.ones(len(uv))] @ frame  # world direction, unit depth
            cosi = np.abs(np.einsum("ij,ij->i", ray, fn[tri])) / np.linalg.norm(ray, axis=1)
            keep = cosi >= cos_max
            views.append((t[keep], tri[keep], ray[keep]))
        return views

    step = 2.0 * halves.min() / 64
    hits = sum(len(t) for t, _, _ in shoot(step))
    step *= math.sqrt(hits / n_points)
    rng = np.random.default_rng(seed)
    d_mean = float(dists.mean())
    out: dict[str, list[np.ndarray]] = {k: [] for k in ScanResult.__dataclass_fields__}
    for view, (origin, (t, tri, ray)) in enumerate(zip(origins, shoot(step), strict=True)):
        ray2 = np.einsum("ij,ij->i", ray, ray)
        rng_len = t * np.sqrt(ray2)
        unit = ray / np.sqrt(ray2)[:, None]
        surface = origin + t[:, None] * ray
        sigma = noise * step * rng_len**2 / d_mean
        out["points"].append(surface + unit * (rng.normal(0.0, 1.0, len(t)) * sigma)[:, None])
        out["surface"].append(surface)
        out["normals"].append(fn[tri])
        out["face"].append(tri)
        out["view"].append(np.full(len(t), view, np.int64))
        # a pixel subtends about step / (1 + u^2 + v^2) radians
        out["footprint"].append(rng_len * step / ray2)
    return ScanResult(**{k: np.concatenate(a) for k, a in out.items()})
