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
(:class:`meshlab_sharp.robust.RobustSetup`).
"""

from __future__ import annotations

import numpy as np

from . import _kernels
from .reference import creases as reference
from .reference.creases import CREASE_ANGLE, NOISE_FACTOR, crease_threshold

__all__ = [
    "CREASE_ANGLE",
    "NOISE_FACTOR",
    "crease_threshold",
    "dihedral_angles",
    "sharp_vertices",
]


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
        ``u = cross(p1 - p0, p2 - p0) / |.|`` (``|.|`` = sqrt of the sum of squares).
        The orientation of the faces does not matter for a consistently oriented mesh;
        an edge between faces of opposite orientation gets the supplementary angle.
    """
    faces = np.asarray(faces, np.int64)
    if len(faces) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    if _kernels.resolve(backend) == "compiled":
        edges, dot = _kernels.two_face_edges(faces, points)
        return edges, _angles(dot)
    return reference.dihedral_angles(points, faces)


def _angles(dot: np.ndarray) -> np.ndarray:
    """``acos(clamp(dot, -1, 1))`` of the dot products (e,) of two unit face normals, in
    place (:func:`dihedral_angles`' angles)."""
    return np.arccos(np.clip(dot, -1.0, 1.0, out=dot), out=dot)


def _angles_and_threshold(dot: np.ndarray, flat: int) -> tuple[np.ndarray, float]:
    """The angles (t,) of the turned edges' dot products ``dot`` (overwritten) and the
    :func:`crease_threshold` of all the edges' angles: these and ``flat`` zeros."""
    angles = _angles(dot)
    return angles, crease_threshold(angles, zeros=flat)


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
    return reference.sharp_vertices(points, faces)
