"""Feature curves in numpy: the reference of the native library's curves
(native/src/curves*.cpp), step by step and with the same arithmetic.

A mesh's sharp edges chained (:mod:`.mesh`); the feature graph and its skeleton
(:mod:`.graph`), traced into polylines cut at corners and joined across gaps
(:mod:`.trace`), positions refined below the spacing on clouds (:mod:`.refine`), and the
whole sequence with the corners (:mod:`.extract`).
:func:`meshlab_sharp.curves.extract_curves` runs it with ``backend="numpy"`` and where
the native library is not built.
"""

from .extract import CurveSet, extract_curves, support_radius

__all__ = ["CurveSet", "extract_curves", "support_radius"]
