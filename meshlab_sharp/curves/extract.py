"""Feature curves from a detection: the skeleton of the feature points, traced into
polylines, refined (clouds), cut and joined at corners (the native library, or its numpy
reference :mod:`meshlab_sharp.reference.curves`), and classified (:mod:`.fit`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _kernels
from ..reference import curves as reference
from . import _native
from .fit import classify

__all__ = ["Corners", "Curve", "extract_curves"]


@dataclass
class Curve:
    """One feature curve.

    Attributes
    ----------
    points : (m, 3) float64
        Vertices in order. Clouds: refined positions; meshes: mesh vertices.
    indices : (m,) int64
        The input point (mesh vertex) each vertex came from; on clouds a vertex moved
        onto a corner keeps the index of the point it came from, an added corner vertex
        has the corner's index.
    closed : bool
        A loop: the last vertex connects to the first (which is not repeated).
    kind : {"line", "arc", "freeform"}
    params : dict
        See :func:`meshlab_sharp.curves.fit.classify` (``length`` and ``rms`` always;
        line: ``point``, ``direction``; arc: ``centre``, ``radius``, ``normal``,
        ``angle``).
    """

    points: np.ndarray
    indices: np.ndarray
    closed: bool
    kind: str
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def length(self) -> float:
        """Polyline length (closing segment included for loops)."""
        return float(self.params["length"])

    @property
    def segments(self) -> np.ndarray:
        """Vertex pairs of the polyline's segments, local indices, shape (s, 2)."""
        m = len(self.points)
        a = np.arange(m if self.closed else m - 1)
        return np.stack([a, (a + 1) % m], axis=1)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: kind, closed, vertex count and parameters."""
        params = {
            k: (v.tolist() if isinstance(v, np.ndarray) else float(v))
            for k, v in self.params.items()
        }
        return {"kind": self.kind, "closed": self.closed, "vertices": len(self.points), **params}


@dataclass
class Corners:
    """Where curves meet at an angle or three or more curves meet.

    Attributes
    ----------
    points : (c, 3) float64
        Positions (clouds: where the curves' end lines meet; meshes: a mesh vertex).
    indices : (c,) int64
        The input point (mesh vertex) nearest each corner among the curves' ends.
    """

    points: np.ndarray
    indices: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


def extract_curves(
    vertices: np.ndarray,
    mask: np.ndarray,
    faces: np.ndarray | None = None,
    valid: np.ndarray | None = None,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    *,
    backend: str | None = None,
) -> tuple[list[Curve], Corners]:
    """Feature curves and corners of a detection.

    Parameters
    ----------
    vertices : (n, 3) float64
        The input's points (mesh vertices), in input order.
    mask : (n,) bool
        Detected features (``DetectionResult.mask``).
    faces : (m, 3) int, optional
        Triangles: the curves are chains of mesh edges. None: a cloud.
    valid : (n,) bool, optional
        Points that took part in detection (``DetectionResult.kept``); the others are
        not used to refine positions.
    bounds : ((3,), (3,)) float64, optional
        Clouds: bounding box of the whole input's valid points when ``vertices`` is only
        the part of it that the curves read: the features and the valid points in the
        cells of side :func:`meshlab_sharp.reference.curves.support_radius` around them
        (out of core, :func:`meshlab_sharp.tiles.curves.curves_out_of_core`). Default:
        the valid vertices' (the others, a far point the detection dropped, may lie
        anywhere).
    backend : {"compiled", "numpy"}, optional
        "compiled": the native library, where it is built (else the numpy reference,
        which gives the same bits); "numpy": the reference. Default: the detection's
        backend (:func:`meshlab_sharp._kernels.default_backend`).

    Returns
    -------
    curves : list of Curve
        In a deterministic order (by first vertex), independent of the input's order.
    corners : Corners

    Raises
    ------
    ValueError
        A NaN or infinite coordinate among the points the curves read: a cloud's valid
        points (the others are never read and may lie anywhere), every vertex of a mesh.
    """
    chosen = _kernels.default_backend() if backend is None else backend
    if chosen not in _kernels.BACKENDS:
        raise ValueError(f"unknown backend {chosen!r}; choose from {', '.join(_kernels.BACKENDS)}")
    finite = np.isfinite(np.asarray(vertices, np.float64).reshape(-1, 3))
    if not finite.all():  # rare: then the rows the curves read decide
        read = np.ones(len(finite), bool) if faces is not None or valid is None else valid
        if (~finite.all(axis=1) & np.asarray(read, bool)).any():
            raise ValueError("the curves need finite coordinates: a point they read is NaN or inf")
    native = chosen == "compiled" and _native.available()
    run = _native.extract_curves if native else reference.extract_curves
    found = run(vertices, mask, faces, valid, bounds)
    curves = [
        Curve(points, indices, closed, *classify(points, closed, found.spacing))
        for points, indices, closed, _ in found.curves
    ]
    return curves, Corners(found.corner_points, found.corner_indices)
