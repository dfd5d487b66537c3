"""Normals, the numpy reference: face averages for meshes (the compiled kernels give the
same bits: same products, sums in the same order), Gaussian-weighted PCA for clouds, and
the eigenvector chosen where a covariance's extreme eigenvalue is not single.

Only the orientation of a normal matters to the projected distance, never its sign.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .. import _header
from ..defaults import DEFAULT_WEIGHTING as _DEFAULT_WEIGHTING
from ..defaults import WEIGHTINGS as WEIGHTINGS  # re-exported
from .creases import face_windings
from .neighbourhoods import squared_distances

Weighting = Literal["gaussian", "none"]
DEFAULT_WEIGHTING: Weighting = _DEFAULT_WEIGHTING  # type: ignore[assignment]

#: A vertex whose summed face normals are shorter than this is treated as a point.
ZERO_NORMAL = _header.real("ZERO_NORMAL")
#: Where the smallest eigenvalue of a covariance is triple or double, and the unit vector
#: that picks its eigenvector then (:func:`smallest_eigenvectors`).
EIG_TRIPLE_ROOT = _header.real("EIG_TRIPLE_ROOT")
EIG_DOUBLE_ROOT = _header.real("EIG_DOUBLE_ROOT")
EIG_TIE_DIRECTION = np.array(_header.reals("EIG_TIE_DIRECTION"))


def face_average_normals(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, int]:
    """Normalised sum of the unit normals of the faces around each vertex, each face's
    normal turned where :func:`meshlab_sharp.reference.creases.face_windings` turns the
    face (the faces' winding does not change the normals' lines).

    Parameters
    ----------
    points : (n, 3) float64
    faces : (m, 3) int
        Triangles of non-zero area.

    Returns
    -------
    normals : (n, 3) float64
        Unit normals; a zero row where a vertex has no face or the sum vanishes
        (``|sum| <= ZERO_NORMAL``), to be replaced by a PCA normal.
    unoriented : int
        Faces in parts with no consistent winding (non-orientable), summed as they are
        wound.
    """
    flip, unoriented = face_windings(np.asarray(faces, np.int64), len(points))
    p0, p1, p2 = (points[faces[:, c]] for c in range(3))
    fn = np.cross(p1 - p0, p2 - p0)
    length = np.sqrt(squared_distances(fn, 0.0))
    fn /= np.where(length > 0, length, 1.0)[:, None]
    fn[flip] *= -1.0
    acc = np.zeros_like(points)
    for c in range(3):
        np.add.at(acc, faces[:, c], fn)
    norm = np.sqrt(squared_distances(acc, 0.0))
    ok = norm > ZERO_NORMAL
    acc[ok] /= norm[ok, None]
    acc[~ok] = 0.0
    return acc, unoriented


def weighted_pca_normals(
    offsets: np.ndarray,
    starts: np.ndarray,
    counts: np.ndarray,
    mean: np.ndarray,
    weighting: Weighting = DEFAULT_WEIGHTING,
) -> np.ndarray:
    """PCA normals of a block of neighbourhoods given as offsets from their centre point.

    Parameters
    ----------
    offsets : (e, 3) float64
        ``p_j - p_i`` for every neighbour j of every point i of the block, grouped by i.
    starts : (c,) int
        Start of each point's group in ``offsets``.
    counts : (c,) int
        Size of each group (>= 1).
    mean : (c, 3) float64
        Mean offset of each group (centroid minus the point).
    weighting : {"gaussian", "none"}, default "gaussian"
        ``gaussian``: ``mu_j = exp(-d_j^2 / h^2)`` with ``h`` the distance to the
        farthest neighbour (all ones when ``h == 0``); ``none``: plain PCA.

    Returns
    -------
    (c, 3) float64
        Unit eigenvector of the smallest eigenvalue of each weighted covariance.
    """
    owner = np.repeat(np.arange(len(counts)), counts)
    r = offsets - mean[owner]
    if weighting == "gaussian":
        d2 = squared_distances(offsets, 0.0)
        h2 = np.maximum.reduceat(d2, starts)
        safe = np.where(h2 > 0, h2, 1.0)
        mu = np.where(h2[owner] > 0, np.exp(-d2 / safe[owner]), 1.0)
    elif weighting == "none":
        mu = np.ones(len(offsets))
    else:
        raise ValueError(f"unknown weighting {weighting!r}; choose from {WEIGHTINGS}")
    cov = np.empty((len(counts), 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = np.add.reduceat(mu * r[:, a] * r[:, b], starts)
            cov[:, b, a] = cov[:, a, b]
    return smallest_eigenvectors(cov)


def smallest_eigenvectors(cov: np.ndarray) -> np.ndarray:
    """Unit eigenvectors of the smallest eigenvalues of symmetric 3x3 matrices, one line
    chosen the same way by every path where that eigenvalue is not single.

    Parameters
    ----------
    cov : (c, 3, 3) float64
        Symmetric (covariances).

    Returns
    -------
    (c, 3) float64
        LAPACK's (``np.linalg.eigh``) eigenvector; where the smallest eigenvalue is double
        or triple (``EIG_DOUBLE_ROOT``, ``EIG_TRIPLE_ROOT``) the vector of its eigenspace
        that the header names (``EIG_TIE_DIRECTION``), else on a diagonal matrix the unit
        vector of the smallest diagonal entry (the first of equals), as the
        native library's closed form chooses them: a grid's symmetric neighbourhoods get
        the same normals in memory, out of core and with numpy.
    """
    return _extreme_eigenvectors(cov, 0)


def largest_eigenvectors(cov: np.ndarray) -> np.ndarray:
    """:func:`smallest_eigenvectors` of ``-cov``, from ``np.linalg.eigh(cov)``: unit
    eigenvectors (c, 3) of the largest eigenvalues of ``cov`` (c, 3, 3)."""
    return _extreme_eigenvectors(cov, 2)


def _extreme_eigenvectors(cov: np.ndarray, column: int) -> np.ndarray:
    """LAPACK's eigenvectors of the smallest (``column`` 0) or largest (2) eigenvalues
    of ``cov`` (c, 3, 3), the native library's choice where those are not single."""
    vectors = np.linalg.eigh(cov)[1]
    out = vectors[:, :, column].copy()
    sign = 1.0 if column == 0 else -1.0
    a, d, f = (sign * cov[:, i, i] for i in range(3))
    b, c, e = sign * cov[:, 0, 1], sign * cov[:, 0, 2], sign * cov[:, 1, 2]
    scale = np.abs(a) + np.abs(b) + np.abs(c) + np.abs(d) + np.abs(e) + np.abs(f)
    out[scale == 0.0] = (1.0, 0.0, 0.0)
    rest = np.flatnonzero(scale != 0.0)
    # the closed form's p, q and r (on entries scaled to O(1): the same ratios)
    a, b, c, d, e, f = (x[rest] / scale[rest] for x in (a, b, c, d, e, f))
    diagonal = (b * b + c * c + e * e) == 0.0
    q = (a + d + f) / 3.0
    p = np.sqrt(((a - q) ** 2 + (d - q) ** 2 + (f - q) ** 2 + 2.0 * (b * b + c * c + e * e)) / 6.0)
    with np.errstate(divide="ignore", invalid="ignore"):  # p = 0: a multiple of I
        b00, b11, b22, b01, b02, b12 = (x / p for x in (a - q, d - q, f - q, b, c, e))
        r = 0.5 * (
            b00 * (b11 * b22 - b12 * b12)
            - b01 * (b01 * b22 - b12 * b02)
            + b02 * (b01 * b12 - b11 * b02)
        )
    triple = p <= EIG_TRIPLE_ROOT * np.abs(q)
    double = ~triple & (1.0 - r <= EIG_DOUBLE_ROOT)
    diagonal &= ~triple & ~double
    out[rest[triple]] = EIG_TIE_DIRECTION
    if double.any():
        v = vectors[rest[double], :, 2 - column]  # the single eigenvalue's line
        w = EIG_TIE_DIRECTION - (v @ EIG_TIE_DIRECTION)[:, None] * v
        out[rest[double]] = w / np.sqrt(squared_distances(w, 0.0))[:, None]
    # a diagonal matrix: the axis of its smallest entry (the first of equals)
    axes = np.argmin(np.stack([a, d, f], axis=1)[diagonal], axis=1)
    out[rest[diagonal]] = np.eye(3)[axes]
    return out
