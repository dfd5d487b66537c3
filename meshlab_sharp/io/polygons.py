"""Polygons to triangles, shared by the mesh readers."""

from __future__ import annotations

import numpy as np


def fan_triangles(corners: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Split polygons into triangle fans: (c0, ci, ci+1) for i = 1..m-2.

    Parameters
    ----------
    corners : (s,) int64
        The polygons' vertex indices, one polygon after another.
    sizes : (p,) int64
        Corners of each polygon, all >= 3, summing to s.

    Returns
    -------
    (t, 3) int64
        t = sum(sizes - 2) triangles, in polygon order.
    """
    offsets = np.cumsum(sizes) - sizes
    if (sizes == 3).all():
        return corners.reshape(-1, 3)
    per = sizes - 2
    owner = np.repeat(np.arange(len(sizes)), per)
    k = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
    base = offsets[owner]
    return np.stack([corners[base], corners[base + k + 1], corners[base + k + 2]], axis=1).astype(
        np.int64
    )
