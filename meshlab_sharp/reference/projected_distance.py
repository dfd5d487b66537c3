"""The projected distance, the numpy reference: how far a point lies from its
neighbourhood's centroid, measured along its normal (Tran et al., Eq. 1), one scale at
a time. The compiled pass (:func:`meshlab_sharp._kernels.cloud_projected_distances`,
:func:`~meshlab_sharp._kernels.ring_projected_distances`) gives the same bits.
"""

from __future__ import annotations

import numpy as np

from .neighbourhoods import Neighbourhood
from .normals import DEFAULT_WEIGHTING, Weighting, weighted_pca_normals

#: Points per block: bounds the (block * k, 3) temporaries.
BLOCK = 32768


def projected_distances(
    points: np.ndarray,
    neighbourhood: Neighbourhood,
    normals: np.ndarray | None = None,
    *,
    weighting: Weighting = DEFAULT_WEIGHTING,
) -> tuple[np.ndarray, np.ndarray]:
    """``|(p_i - c_i) . n_i|`` for every point, ``c_i`` the plain centroid of its neighbours.

    Parameters
    ----------
    points : (n, 3) float64
    neighbourhood : Neighbourhood
        Neighbours of every point at this scale.
    normals : (n, 3) float64, optional
        Fixed unit normals (meshes). Rows of zeros, and every row when ``normals`` is
        None (clouds), get the weighted PCA normal of the neighbourhood instead.
    weighting : {"gaussian", "none"}, default "gaussian"
        Weighting of the PCA normals.

    Returns
    -------
    pdis : (n,) float64
        Projected distances.
    used_normals : (n, 3) float64
        The normals used.
    """
    n = len(points)
    pdis = np.empty(n)
    used = np.empty((n, 3))
    indptr, indices = neighbourhood.indptr, neighbourhood.indices
    for start in range(0, n, BLOCK):
        stop = min(start + BLOCK, n)
        lo, hi = indptr[start], indptr[stop]
        counts = np.diff(indptr[start : stop + 1])
        starts = indptr[start:stop] - lo
        owner = np.repeat(np.arange(start, stop), counts)
        offsets = points[indices[lo:hi]] - points[owner]
        mean = np.add.reduceat(offsets, starts, axis=0) / counts[:, None]
        if normals is None:
            block_normals = weighted_pca_normals(offsets, starts, counts, mean, weighting)
        else:
            block_normals = normals[start:stop].copy()
            missing = ~block_normals.any(axis=1)
            if missing.any():
                pca = weighted_pca_normals(offsets, starts, counts, mean, weighting)
                block_normals[missing] = pca[missing]
        used[start:stop] = block_normals
        m, nb = mean, block_normals
        pdis[start:stop] = np.abs(m[:, 0] * nb[:, 0] + m[:, 1] * nb[:, 1] + m[:, 2] * nb[:, 2])
    return pdis, used
