"""Polygons to triangles, shared by the mesh readers."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..errors import InputError

#: Most corners of one polygon. A polygon becomes a fan around its first corner, which
#: then neighbours every other corner, and the k-ring neighbourhoods around it grow with
#: the polygon: a larger one is refused when the file is read, before any work.
MAX_FACE_CORNERS = 1000


def too_many_corners(where: str, size: int | str) -> InputError:
    """The error for a face of ``size`` corners (its count as written, when too long to
    be a number) at ``where`` (``"NAME: line N"``)."""
    return InputError(
        f"{where}: a face with {size} corners, more than the {MAX_FACE_CORNERS} a face may "
        "have; split it into smaller polygons"
    )


def check_corner_limit(sizes: np.ndarray, where: Callable[[int], str]) -> None:
    """Refuse the first face above :data:`MAX_FACE_CORNERS`; ``where(k)`` names face k."""
    big = sizes > MAX_FACE_CORNERS
    if big.any():
        k = int(np.argmax(big))
        raise too_many_corners(where(k), int(sizes[k]))


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
