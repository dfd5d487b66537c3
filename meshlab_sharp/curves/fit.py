"""What a curve is: a straight line, a circular arc, or free-form, with its parameters.

A curve is a line when every vertex lies within the tolerance of the line fitted to it
(principal axis), a circular arc when it lies within the tolerance of its fitted plane
and of the circle fitted in that plane (algebraic least-squares fit), and free-form
otherwise. The tolerance is :data:`FIT_TOLERANCE` spacings for the RMS distance and
:data:`FIT_MAX` times that for the largest one.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._header import CURVES

__all__ = ["FIT_MAX", "FIT_TOLERANCE", "KINDS", "classify"]

#: Curve kinds.
KINDS = ("line", "arc", "freeform")
# The numbers are defined once, in native/include/meshlab_sharp.h.
#: RMS distance to the fitted line or circle, in spacings, up to which it fits: a
#: refined cloud curve lies within about 0.3 spacing of its edge (docs/curves.md), and a
#: mesh curve's vertices lie on the edge.
FIT_TOLERANCE = CURVES.real("FIT_TOLERANCE")
#: The largest distance may be this many times the tolerance (single stray vertices).
FIT_MAX = CURVES.real("FIT_MAX")
#: A circle is reported only up to this radius, in multiples of the curve's extent:
#: flatter arcs are lines within the tolerance or too flat to place a centre reliably.
MAX_RADIUS_RATIO = CURVES.real("MAX_RADIUS_RATIO")


def _fits(residual: np.ndarray, tol: float) -> bool:
    return bool(np.sqrt(np.mean(residual**2)) <= tol and np.max(np.abs(residual)) <= FIT_MAX * tol)


def classify(points: np.ndarray, closed: bool, spacing: float) -> tuple[str, dict[str, Any]]:
    """Kind and parameters of a curve.

    Parameters
    ----------
    points : (m, 3) float64
        Vertices in order.
    closed : bool
        The curve is a loop.
    spacing : float
        Point spacing; the tolerance is ``FIT_TOLERANCE * spacing``.

    Returns
    -------
    kind : {"line", "arc", "freeform"}
    params : dict
        Always ``length`` (float) and ``rms`` (RMS distance to the fitted shape; NaN for
        free-form). Line: ``point`` (3,) (the centroid), ``direction`` (3,) unit, from
        the first vertex towards the last. Arc: ``centre`` (3,), ``radius`` (float),
        ``normal`` (3,) unit (the curve turns counter-clockwise about it), ``angle``
        (degrees swept; 360 for a closed circle).
    """
    p = np.asarray(points, np.float64)
    tol = FIT_TOLERANCE * spacing
    seg = np.diff(np.vstack([p, p[:1]]) if closed else p, axis=0)
    length = float(np.linalg.norm(seg, axis=1).sum())
    free: dict[str, Any] = {"length": length, "rms": math.nan}
    if len(p) < 3 and not closed:
        if len(p) < 2:
            return "freeform", free
        d = p[-1] - p[0]
        return "line", {**free, "rms": 0.0, "point": p.mean(axis=0), "direction": d / length}
    centroid = p.mean(axis=0)
    rel = p - centroid
    _, _, vt = np.linalg.svd(rel, full_matrices=False)
    if not closed:
        axis = vt[0] if float((p[-1] - p[0]) @ vt[0]) >= 0 else -vt[0]
        off = rel - np.outer(rel @ axis, axis)
        dist = np.linalg.norm(off, axis=1)
        if _fits(dist, tol):
            return "line", {
                **free,
                "rms": float(np.sqrt(np.mean(dist**2))),
                "point": centroid,
                "direction": axis,
            }
    if len(p) < 4:
        return "freeform", free
    normal = np.cross(vt[0], vt[1])  # right-handed with the in-plane axes
    height = rel @ normal
    if not _fits(height, tol):
        return "freeform", free
    e1, e2 = vt[0], vt[1]
    x, y = rel @ e1, rel @ e2
    a = np.stack([x, y, np.ones_like(x)], axis=1)
    sol, *_ = np.linalg.lstsq(a, -(x**2 + y**2), rcond=None)
    cx, cy = -sol[0] / 2, -sol[1] / 2
    r2 = cx**2 + cy**2 - sol[2]
    extent = float(np.linalg.norm(np.ptp(p, axis=0)))
    if not r2 > 0 or math.sqrt(r2) > MAX_RADIUS_RATIO * max(extent, spacing):
        return "freeform", free
    radius = math.sqrt(r2)
    radial = np.hypot(x - cx, y - cy) - radius
    dist = np.hypot(radial, height)
    if not _fits(dist, tol):
        return "freeform", free
    angles = np.unwrap(np.arctan2(y - cy, x - cx))
    sweep = float(angles[-1] - angles[0])
    if sweep < 0:
        normal, sweep = -normal, -sweep
    centre = centroid + cx * e1 + cy * e2
    params = {
        **free,
        "rms": float(np.sqrt(np.mean(dist**2))),
        "centre": centre,
        "radius": radius,
        "normal": normal,
        "angle": 360.0 if closed else math.degrees(sweep),
    }
    return "arc", params
