"""Normals: Gaussian-weighted PCA for clouds, face averages for meshes, each with the
compiled kernels or the numpy reference (:mod:`meshlab_sharp.reference.normals`).

Only the orientation of a normal matters to the projected distance, never its sign.
"""

from __future__ import annotations

import numpy as np

from . import _kernels
from .reference import normals as reference
from .reference.normals import DEFAULT_WEIGHTING, WEIGHTINGS, ZERO_NORMAL, Weighting

__all__ = ["DEFAULT_WEIGHTING", "WEIGHTINGS", "ZERO_NORMAL", "Weighting", "face_average_normals"]


def face_average_normals(
    points: np.ndarray, faces: np.ndarray, *, backend: str | None = None
) -> np.ndarray:
    """Normalised sum of the unit normals of the faces around each vertex
    (:func:`meshlab_sharp.reference.normals.face_average_normals`).

    Parameters
    ----------
    points : (n, 3) float64
    faces : (m, 3) int
        Triangles of non-zero area.
    backend : {"compiled", "numpy"}, optional
        Default :func:`meshlab_sharp._kernels.default_backend`; the same bits.

    Returns
    -------
    (n, 3) float64
        Unit normals; a zero row where a vertex has no face or the sum vanishes
        (``|sum| <= ZERO_NORMAL``), to be replaced by a PCA normal.
    """
    if _kernels.resolve(backend) == "compiled":
        return _kernels.face_average_normals(points, faces, ZERO_NORMAL)
    return reference.face_average_normals(points, faces)
