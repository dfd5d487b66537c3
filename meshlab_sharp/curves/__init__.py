"""Feature curves: the polylines along the detected sharp features.

>>> result = meshlab_sharp.detect("part.ply", curves=True)   # doctest: +SKIP
>>> [(c.kind, c.closed, len(c.points)) for c in result.curves]  # doctest: +SKIP

Built from a detection's mask and the geometry (:func:`extract_curves`): the feature
graph and its skeleton, traced into polylines cut at corners and joined across gaps,
positions refined below the spacing on clouds (the native library's
native/src/curves.cpp, or its numpy reference :mod:`meshlab_sharp.reference.curves`,
which gives the same bits), and each curve classified (:mod:`.fit`). Deterministic.
"""

from .extract import Corners, Curve, extract_curves
from .fit import KINDS, classify

__all__ = ["KINDS", "Corners", "Curve", "classify", "extract_curves"]
