"""Normals, the numpy reference: face averages for meshes (the compiled kernels give the
same bits: same products, sums in the same order), Gaussian-weighted PCA for clouds.

Only the orientation of a normal matters to the projected distance, never its sign.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .. import _header
from ..defaults import DEFAULT_WEIGHTING as _DEFAULT_WEIGHTING
from ..defaults import WEIGHTINGS as WEIGHTINGS  # re-exported
from .neighbourhoods import squared_distances

Weighting = Literal["gaussian", "none"]
DEFAULT_WEIGHTING: Weighting = _DEFAULT_WEIGHTING  # type: ignore[assignment]

#: A vertex whose summed face normals are shorter than this is treated as a point.
ZERO_NORMAL = _header.real("ZERO_NORMAL")


def face_average_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Normalised sum of the unit normals of the faces around each vertex.

    Parameters
    ----------
    points : (n, 3) float64
    faces : (m, 3) int
        Triangles of non-zero area.

    Returns
    -------
    (n, 3) float64
        Unit normals; a zero row where a vertex has no face or the sum vanishes
        (``|sum| <= ZERO_NORMAL``), to be replaced by a PCA normal.
    """
    p0, p1, p2 = (points[faces[:, c]] for c in range(3))
    fn = np.cross(p1 - p0, p2 - p0)
    length = np.sqrt(squared_distances(fn, 0.0))
    fn /= np.where(length > 0, length, 1.0)[:, None]
    acc = np.zeros_like(points)
    for c in range(3):
        np.add.at(acc, faces[:, c], fn)
    norm = np.sqrt(squared_distances(acc, 0.0))
    ok = norm > ZERO_NORMAL
    acc[ok] /= norm[ok, None]
    acc[~ok] = 0.0
    return acc


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
    _, vectors = np.linalg.eigh(cov)
    return vectors[:, :, 0]
