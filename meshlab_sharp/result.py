"""What a detection returns: :class:`DetectionResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .curves import Corners, Curve
from .defaults import DEFAULT_MODE
from .preprocessing import PreprocessingReport


@dataclass
class DetectionResult:
    """Sharp features of one input, every per-vertex array in the input's order.

    Attributes
    ----------
    mask : (n,) bool
        True for the sharp feature points: the candidates at every scale (robust mode:
        with its own steps, docs/method.md).
    strength : (n,) float64
        Fraction of scales at which the point was a candidate, in [0, 1].
    kind : {"points", "mesh"}
        How the input was processed: kNN neighbourhoods or k-rings.
    scales : tuple of int
        The scales used (k of kNN, or rings).
    thresholds : (s,) float64
        The threshold at each scale: Otsu's (robust mode: with its floor).
    candidate_counts : (s,) int64
        Candidates at each scale (cleaned points; merged duplicates count once).
    kept : (n,) bool
        Input vertices that took part (False for unreferenced mesh vertices, which are
        dropped by cleaning, and in robust mode for isolated points, which are left
        out; neither is ever a feature). The MeshLab plugin reports the same.
    weighting : str
        The PCA weighting.
    n_clean : int
        Number of distinct points processed.
    timings : dict of str to float
        Seconds per stage.
    distances : (s, n) float64 or None
        Normalised projected distances per scale (robust mode: the relative distances)
        (``return_details=True``); NaN for dropped vertices.
    normals : (s, n, 3) float64 or None
        Unit normals used at each scale (``return_details=True``); NaN for dropped
        vertices. Their sign is arbitrary.
    preprocessing : PreprocessingReport or None
        With ``detect(..., preprocessing=...)``: the steps run, the processed geometry,
        its map to the input and the detection in its order.
    mode : str
        "paper" or "robust".
    curves : list of Curve or None
        With ``detect(..., curves=True)``: the feature curves (:mod:`meshlab_sharp.curves`),
        each with ``points`` (m, 3), ``indices`` (m,) of the input points, ``closed``,
        ``kind`` ("line", "arc", "freeform") and ``params``.
    corners : Corners or None
        With ``curves=True``: ``points`` (c, 3) and ``indices`` (c,) of the corners.
    tiling : dict or None
        Out of core (``max_memory``/``dask``): tiles, tasks, halo and peak memory.
    backend : {"compiled", "numpy"} or None
        The backend the detection's neighbourhoods were built with, and so every step
        ran with (None: a result made by other means).
    """

    mask: np.ndarray
    strength: np.ndarray
    kind: str
    scales: tuple[int, ...]
    thresholds: np.ndarray
    candidate_counts: np.ndarray
    kept: np.ndarray
    weighting: str
    n_clean: int
    timings: dict[str, float] = field(default_factory=dict)
    distances: np.ndarray | None = None
    normals: np.ndarray | None = None
    preprocessing: PreprocessingReport | None = None
    mode: str = DEFAULT_MODE
    curves: list[Curve] | None = None
    corners: Corners | None = None
    tiling: dict[str, Any] | None = None
    backend: str | None = None

    @property
    def indices(self) -> np.ndarray:
        """0-based input indices of the features, shape (f,)."""
        return np.flatnonzero(self.mask)

    @property
    def n_features(self) -> int:
        """Number of feature points."""
        return int(self.mask.sum())

    def summary(self) -> dict[str, Any]:
        """A JSON-ready summary: counts, per-scale thresholds, options and timings."""
        return {
            "kind": self.kind,
            "n_input": len(self.mask),
            "n_clean": self.n_clean,
            "n_dropped": int((~self.kept).sum()),
            "n_features": self.n_features,
            "options": {
                "scales": list(self.scales),
                "weighting": self.weighting,
                "mode": self.mode,
            },
            "scales": [
                {"scale": int(s), "threshold": float(t), "candidates": int(c)}
                for s, t, c in zip(self.scales, self.thresholds, self.candidate_counts, strict=True)
            ],
            "timings_s": {k: round(v, 6) for k, v in self.timings.items()},
            **(
                {}
                if self.preprocessing is None
                else {"preprocessing": self.preprocessing.summary()}
            ),
            **({} if self.curves is None else _curves_summary(self.curves, self.corners)),
            **({} if self.tiling is None else {"tiling": self.tiling}),
        }


def _curves_summary(curves: list[Curve], corners: Corners | None) -> dict[str, Any]:
    """The ``curves`` part of :meth:`DetectionResult.summary`."""
    kinds = [c.kind for c in curves]
    return {
        "curves": {
            "n_curves": len(curves),
            "n_corners": 0 if corners is None else len(corners),
            "kinds": {k: kinds.count(k) for k in sorted(set(kinds))},
            "list": [c.summary() for c in curves],
        }
    }
