"""Feature curves of a tiled detection, from the few points near the features.

:func:`meshlab_sharp.curves.extract_curves` on a cloud reads the feature points and
the valid points in the grid cells of side
:func:`~meshlab_sharp.reference.curves.support_radius` around them (for the refinement),
nothing else. Two streaming passes over the input gather exactly those points (the
features' coordinates and the bounding box of the cloud's valid points; then the valid
points in the features' cells), and ``extract_curves`` runs on them with that box, so
that its grid is the in-memory run's: the curves and corners are the in-memory
ones, their indices mapped back to the input's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..curves import Corners, Curve, extract_curves
from ..io.source import PointSource
from ..reference.curves import support_radius
from ..reference.curves.refine import CellGrid
from .layout import bounds

#: Points per block of the streaming passes.
BLOCK = 1 << 20


def curves_out_of_core(
    source: PointSource, mask: np.ndarray, kept: np.ndarray, backend: str
) -> tuple[list[Curve], Corners]:
    """The feature curves and corners of a cloud read in blocks.

    Parameters
    ----------
    source : PointSource
        The cloud, n points.
    mask, kept : (n,) bool
        The detection's features and the points that took part (input order).
    backend : {"compiled", "numpy"}
        The detection's backend, which extracts the curves too.

    Returns
    -------
    curves : list of Curve
    corners : Corners
        As :func:`meshlab_sharp.curves.extract_curves` on the whole cloud; ``indices``
        index the input's points.
    """
    valid = np.flatnonzero(mask & kept)
    lo, hi, found = _bounds_and_rows(source, kept, valid)
    features = np.unique(found, axis=0)
    if len(features) < 2:  # extract_curves finds no curve in fewer than 2 features
        part, points = valid, found
    else:
        grid = CellGrid(lo, hi, support_radius(features))
        wanted = grid.around(features)
        parts, coords, start = [], [], 0
        for block in source.blocks(BLOCK):
            inside = np.flatnonzero(
                kept[start : start + len(block)]
            )  # the others may lie outside the grid
            near = inside[np.isin(grid.keys(block[inside]), wanted)]
            parts.append(start + near)
            coords.append(block[near])
            start += len(block)
        part, points = np.concatenate(parts), np.concatenate(coords)  # every valid feature too
    curves, corners = extract_curves(
        points, mask[part], None, kept[part], bounds=(lo, hi), backend=backend
    )
    curves = [dataclasses.replace(c, indices=part[c.indices]) for c in curves]
    return curves, dataclasses.replace(corners, indices=part[corners.indices])


def _bounds_and_rows(
    source: PointSource, kept: np.ndarray, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One pass: the bounding box of the source's ``kept`` (n,) points, (3,) and (3,),
    and the coordinates of the given ascending rows, (r, 3) float64."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    out, start = [np.zeros((0, 3))], 0
    for block in source.blocks(BLOCK):
        inside = block[kept[start : start + len(block)]]
        if len(inside):
            blo, bhi = bounds(inside)
            lo, hi = np.minimum(lo, blo), np.maximum(hi, bhi)
        a, b = np.searchsorted(rows, [start, start + len(block)])
        out.append(block[rows[a:b] - start])
        start += len(block)
    return lo, hi, np.concatenate(out)
