"""Normals: Gaussian-weighted PCA for clouds, face averages for meshes, each with the
compiled kernels or the numpy reference (:mod:`meshlab_sharp.reference.normals`).

Only the orientation of a normal matters to the projected distance, never its sign.
"""

from __future__ import annotations

import warnings

import numpy as np

from . import _kernels
from .errors import InputWarning
from .reference import normals as reference
from .reference.normals import (
    DEFAULT_WEIGHTING,
    EIG_TIE_DIRECTION,
    WEIGHTINGS,
    ZERO_NORMAL,
    Weighting,
    largest_eigenvectors,
    smallest_eigenvectors,
)

__all__ = [
    "DEFAULT_WEIGHTING",
    "EIG_TIE_DIRECTION",
    "WEIGHTINGS",
    "ZERO_NORMAL",
    "Weighting",
    "face_average_normals",
    "largest_eigenvectors",
    "smallest_eigenvectors",
]


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

    Each face's normal is turned where :func:`meshlab_sharp.creases.face_windings` turns
    the face, so that the faces' winding does not change the normals' lines; faces in a
    part with no consistent winding (non-orientable) are summed as they are wound, with an
    :class:`~meshlab_sharp.errors.InputWarning`.
    """
    if _kernels.resolve(backend) == "compiled":
        acc, unoriented = _kernels.face_average_normals(points, faces, ZERO_NORMAL)
    else:
        acc, unoriented = reference.face_average_normals(points, faces)
    if unoriented:
        warnings.warn(
            InputWarning(
                f"{unoriented} faces lie in parts with no consistent winding "
                "(non-orientable): their vertex normals are summed as the faces are wound"
            ),
            stacklevel=2,
        )
    return acc
