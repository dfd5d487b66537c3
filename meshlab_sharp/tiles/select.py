"""An exact order statistic of a per-point store array, reduced over the tiles.

The k-th smallest value (the lower median, for robust mode's noise estimate) is found
by counting: each pass counts the values in ``BINS`` equal bins of a range (and those
below it), which reduces exactly as integer sums, and takes each bin's smallest and
largest value (reduced by min and max); the values of the bin holding the wanted rank,
from its smallest to its largest, become the next range, until they are all equal (the
answer, gathered from no tile: a cloud with many points of the same ratio, such as
exact planes, would otherwise gather them all) or at most ``COLLECT`` values, which are
then gathered and the rank picked among them. The bin of a value is computed by one
expression in every pass, so the counts, the ranges and the gathered values always
agree.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .steps import Partial, Span, Step

if TYPE_CHECKING:
    from .run import Runner

#: Bins per counting pass.
BINS = 4096
#: Values gathered at most for the final pick ...
COLLECT = 1 << 21
#: ... or after this many passes (values too close together for the bins to split).
PASSES = 6


def _values(span: Span, name: str, kept: str) -> np.ndarray:
    d = span.distinct
    return span.read(name)[d[span.read(kept)[d]]]


def _bins(v: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Bin of each value in [lo, hi] (others: -1)."""
    width = hi - lo
    b = np.floor((v - lo) / width * BINS) if width > 0 else np.zeros(len(v))
    b = np.clip(b, 0, BINS - 1).astype(np.int64)
    return np.where((v >= lo) & (v <= hi), b, -1)


def value_range(span: Span, *, name: str, kept: str) -> Partial:
    """Smallest and largest value."""
    v = _values(span, name, kept)
    return {"v_min": np.array(v.min(initial=np.inf)), "v_max": np.array(v.max(initial=-np.inf))}


def value_counts(span: Span, *, name: str, kept: str, lo: float, hi: float) -> Partial:
    """Values below ``lo``, and per bin of [lo, hi] their number, smallest and largest
    (inf and -inf in an empty bin)."""
    v = _values(span, name, kept)
    b = _bins(v, lo, hi)
    inside = b >= 0
    first, last = np.full(BINS, np.inf), np.full(BINS, -np.inf)
    np.minimum.at(first, b[inside], v[inside])
    np.maximum.at(last, b[inside], v[inside])
    return {
        "below": np.array(int((v < lo).sum())),
        "counts": np.bincount(b[inside], minlength=BINS),
        "bin_min": first,
        "bin_max": last,
    }


def value_collect(span: Span, *, name: str, kept: str, lo: float, hi: float, bin: int) -> Partial:
    """The values of one bin."""
    v = _values(span, name, kept)
    return {"values_cat": v[_bins(v, lo, hi) == bin]}


def order_statistic(runner: Runner, name: str, kept: str, rank: int) -> float:
    """The ``rank``-th smallest (0-based) value of store array ``name`` over the
    distinct points where ``kept`` is True."""
    where = {"name": name, "kept": kept}
    ends = runner.step(Step("noise range", value_range, None, where))
    lo, hi = float(ends["v_min"]), float(ends["v_max"])
    for passes in range(1, PASSES + 1):
        counted = runner.step(
            Step("noise counts", value_counts, None, {**where, "lo": lo, "hi": hi})
        )
        target = rank - int(counted["below"])
        cum = np.cumsum(counted["counts"])
        b = int(np.searchsorted(cum, target, side="right"))
        first, last = float(counted["bin_min"][b]), float(counted["bin_max"][b])
        if first == last:  # every value of the bin, the rank's among them, is this one
            return first
        if int(counted["counts"][b]) <= COLLECT or passes == PASSES:
            got = runner.step(
                Step("noise pick", value_collect, None, {**where, "lo": lo, "hi": hi, "bin": b})
            )["values_cat"]
            at = target - (int(cum[b - 1]) if b > 0 else 0)
            return float(np.partition(got, at)[at])
        lo, hi = first, last  # exactly the bin's values lie in [first, last]
    raise AssertionError("unreachable: the last pass picks")
