"""Min-max normalisation and Otsu's threshold on a 256-bin histogram.

The arithmetic is the one pinned down in ``docs/contributing.md``, shared with
the MeshLab plugin: Otsu's criterion is evaluated in an integer form that is a constant
multiple of ``w0 * w1 * (m0 - m1)**2`` with bin centres ``(b + 0.5) / B``.
"""

from __future__ import annotations

import numpy as np

from . import _header

#: Histogram bins, ALGORITHM.md's B.
BINS = _header.integer("BINS")
#: A scale whose projected distances span at most this fraction of the bounding-box
#: diagonal is flat (round-off only): no point is a candidate there.
FLAT_TOLERANCE = _header.real("FLAT_TOLERANCE")


def normalise(pdis: np.ndarray, *, flat_span: float = 0.0) -> np.ndarray:
    """Min-max normalise to [0, 1]; all zeros when ``max - min <= flat_span``.

    Parameters
    ----------
    pdis : (n,) float64
        Projected distances.
    flat_span : float, default 0.0
        Spans up to this are round-off: every value becomes 0.

    Returns
    -------
    (n,) float64
    """
    if len(pdis) == 0:
        return np.zeros(0)
    lo, hi = float(pdis.min()), float(pdis.max())
    if hi - lo <= flat_span:
        return np.zeros_like(pdis)
    return (pdis - lo) / (hi - lo)


def histogram(values: np.ndarray, bins: int = BINS) -> np.ndarray:
    """Counts of ``values`` in [0, 1] over ``bins`` equal bins; bin = min(floor(v * B), B - 1).

    Returns
    -------
    (bins,) int64
    """
    b = np.minimum(np.floor(values * bins), bins - 1).astype(np.int64)
    return np.bincount(b, minlength=bins)


def otsu_threshold(values: np.ndarray, bins: int = BINS) -> float:
    """Otsu's threshold ``T = t / B`` of normalised values; candidates are ``v >= T``.

    Parameters
    ----------
    values : (n,) float64
        Normalised projected distances in [0, 1].
    bins : int, default 256

    Returns
    -------
    float
        The threshold; 1.0 when there is nothing to split (no values, or all in one bin
        such as the all-zero output of a flat scale), so that no point passes unless it
        equals 1.
    """
    return otsu_from_histogram(histogram(values, bins))


def otsu_from_histogram(counts: np.ndarray) -> float:
    """:func:`otsu_threshold` from the histogram's counts (B,) int: the same threshold,
    so that histograms summed over parts of the points give the whole's threshold."""
    bins = len(counts)
    n = counts.sum()
    weighted = counts * (2 * np.arange(bins, dtype=np.int64) + 1)
    n0 = np.cumsum(counts)[:-1].astype(np.float64)
    s0 = np.cumsum(weighted)[:-1].astype(np.float64)
    n1 = float(n) - n0
    s1 = float(weighted.sum()) - s0
    valid = (n0 > 0) & (n1 > 0)
    if not valid.any():
        return 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        diff = s0 * n1 - s1 * n0
        crit = np.where(valid, diff * diff / (n0 * n1), -1.0)
    t = int(np.argmax(crit)) + 1  # argmax returns the first maximum: the smallest t
    return t / bins
