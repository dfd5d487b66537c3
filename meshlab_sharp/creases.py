"""Sharp mesh edges from the mesh's own dihedral angles (robust mode, meshes).

A CAD export (STL-style tessellation) has vertices only where faces meet: nearly every
vertex lies on a sharp edge, rings of 1-4 edges span the whole part, and the projected
distance has nothing to compare a vertex with. The mesh itself says where its sharp
edges are: an edge is sharp when its two faces turn by more than ``CREASE_ANGLE``
degrees, the definition of "sharp" used everywhere in the project (the ground truth,
``robust.R_MIN``). On a noisy dense mesh, noise alone turns adjacent faces by up to tens
of degrees; the threshold then rises with the mesh's lower quartile of dihedral angles
(the noise level: at least a quarter of the edges of a mesh lie inside flat or smooth
regions, where a clean mesh, CAD or remeshed, turns by 0-3 degrees), and robust mode's
multiscale vote
finds the creases that the raised threshold no longer sees
(:class:`meshlab_sharp.reference.detect.RobustSetup`).
"""

from __future__ import annotations

import math

import numpy as np

from . import _header, _kernels
from .reference import creases as reference

__all__ = [
    "CREASE_ANGLE",
    "NOISE_FACTOR",
    "crease_threshold",
    "dihedral_angles",
    "face_windings",
    "sharp_vertices",
]


#: Degrees: the smallest turn of the surface that counts as a sharp edge (the ground
#: truth's crease angle, ``meshlab_sharp.parts.CREASE_ANGLE``).
CREASE_ANGLE = _header.real("CREASE_ANGLE")
#: On a noisy mesh the dihedral angles of flat regions are close to half-normal
#: (measured: median / lower quartile = 2.1, half-normal 2.11): their lower quartile is
#: ``0.3186 sigma`` (``Phi^-1(0.625)``), and 4 sigma (one false alarm per 16,000 edges)
#: is ``4 / 0.3186 = 12.6`` lower quartiles. Sharp edges must turn by more than
#: ``NOISE_FACTOR * lower quartile`` as well as by more than ``CREASE_ANGLE``. The
#: quartile, not the median: on a small CAD mesh (a box: 24 edges) half the edges can
#: be creases, a quarter cannot (the triangulation's diagonals turn by 0).
NOISE_FACTOR = _header.real("NOISE_FACTOR")


def dihedral_angles(
    points: np.ndarray, faces: np.ndarray, *, backend: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Edges with exactly two faces and the angle between their face normals.

    Parameters
    ----------
    points : (n, 3) float64
    faces : (f, 3) int
        Triangles of non-zero area (cleaned).
    backend : {"compiled", "numpy"}, optional
        Default :func:`meshlab_sharp._kernels.default_backend`; the same result.

    Returns
    -------
    edges : (e, 2) int64
        Vertex pairs ``(a, b)``, ``a < b``, sorted lexicographically; edges with one
        face (boundaries) or more than two (non-manifold) are left out.
    angles : (e,) float64
        Radians in [0, pi]: ``acos(clamp(u . v, -1, 1))`` of the two unit face normals
        ``u = cross(p1 - p0, p2 - p0) / |.|`` (``|.|`` = sqrt of the sum of squares),
        ``v`` negated where the two faces go the same way along the edge (one of them is
        wound the other way round): the angle is the same whatever the faces' winding,
        and only the line of each normal counts.
    """
    faces = np.asarray(faces, np.int64)
    if len(faces) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    if _kernels.resolve(backend) == "compiled":
        edges, dot = _kernels.two_face_edges(faces, points)
        return edges, _angles(dot)
    return reference.dihedral_angles(points, faces)


def face_windings(
    faces: np.ndarray, n: int, *, backend: str | None = None
) -> tuple[np.ndarray, int]:
    """Which faces to turn so that every face is wound as its neighbours are
    (:func:`meshlab_sharp.reference.creases.face_windings`).

    Faces are joined through the edges with exactly two faces; two joined faces are
    wound alike when they go opposite ways along their edge. In each part so joined the
    lowest face keeps its winding, and the others are turned where they are wound the
    other way round from it. Only the line of each face's normal then counts, never the
    winding a file gave it.

    Parameters
    ----------
    faces : (m, 3) int
        Triangles over ``n`` vertices (three distinct vertices each).
    n : int
        Number of vertices.
    backend : {"compiled", "numpy"}, optional
        Default :func:`meshlab_sharp._kernels.default_backend`; the same result.

    Returns
    -------
    flip : (m,) bool
        True where the face is turned (none on a consistently wound mesh).
    unoriented : int
        Faces in parts with no consistent winding (non-orientable, a Moebius strip),
        left as they are wound.
    """
    faces = np.asarray(faces, np.int64)
    if _kernels.resolve(backend) == "compiled":
        return _kernels.face_windings(faces, n)
    return reference.face_windings(faces, n)


def _angles(dot: np.ndarray) -> np.ndarray:
    """``acos(clamp(dot, -1, 1))`` of the dot products (e,) of two unit face normals, in
    place (:func:`dihedral_angles`' angles)."""
    return np.arccos(np.clip(dot, -1.0, 1.0, out=dot), out=dot)


def _angles_and_threshold(dot: np.ndarray, flat: int) -> tuple[np.ndarray, float]:
    """The angles (t,) of the turned edges' dot products ``dot`` (overwritten) and the
    :func:`crease_threshold` of all the edges' angles: these and ``flat`` zeros."""
    angles = _angles(dot)
    return angles, crease_threshold(angles, zeros=flat)


#: Angles per block of crease_threshold's count.
_BLOCK = 1 << 16


def crease_threshold(angles: np.ndarray, *, zeros: int = 0) -> float:
    """Radians: ``max(CREASE_ANGLE, NOISE_FACTOR * lower quartile of the angles)``.

    Parameters
    ----------
    angles : (e,) float64
        Dihedral angles of the mesh's two-face edges (radians).
    zeros : int, default 0
        How many more angles are 0 (edges left out of ``angles``, the compiled
        :func:`sharp_vertices`' flat ones): the same threshold as with them in.

    Returns
    -------
    float
        The lower quartile is element ``(e + zeros - 1) // 4`` of all the angles sorted in
        increasing order (``CREASE_ANGLE`` when there are none).
    """
    floor = math.radians(CREASE_ANGLE)
    if len(angles) + zeros == 0:
        return floor
    at = (len(angles) + zeros - 1) // 4
    # When more than ``at`` angles a give NOISE_FACTOR * a <= floor, so does the quartile
    # (rounding is monotonic) and the floor wins: no partial sort (most of a mesh's edges
    # are flat; the zeros among them). Otherwise the zeros are the ``zeros`` smallest
    # angles (at most ``at`` of them), and the quartile is among ``angles``.
    # (counted in blocks: no temporary as long as the angles)
    below = zeros + sum(
        int(np.count_nonzero(NOISE_FACTOR * angles[i : i + _BLOCK] <= floor))
        for i in range(0, len(angles), _BLOCK)
    )
    if below > at:
        return floor
    quartile = float(np.partition(angles, at - zeros)[at - zeros])
    return max(floor, NOISE_FACTOR * quartile)


def sharp_vertices(
    points: np.ndarray, faces: np.ndarray, *, backend: str | None = None
) -> tuple[np.ndarray, float]:
    """Vertices on a sharp edge: two faces turning by more than :func:`crease_threshold`.

    Parameters
    ----------
    points : (n, 3) float64
    faces : (f, 3) int
        Triangles of non-zero area (cleaned: three distinct vertices), as
        :func:`dihedral_angles` takes them.
    backend : {"compiled", "numpy"}, optional
        Default :func:`meshlab_sharp._kernels.default_backend`; the same result. The
        compiled one lists no edges (:func:`meshlab_sharp._kernels.crease_vertices`).

    Returns
    -------
    mask : (n,) bool
    threshold : float
        The angle used (radians).
    """
    faces = np.asarray(faces, np.int64)
    if _kernels.resolve(backend) == "compiled":
        return _kernels.crease_vertices(points, faces, _angles_and_threshold)
    return reference.sharp_vertices(points, faces, crease_threshold)
