"""An exact order statistic of a per-point store array, reduced over the tiles.

The k-th smallest value (the lower median, for robust mode's noise estimate) is found
by counting on the values' order-preserving 64-bit integer keys (the float's bits, the
negative ones' reversed): each pass counts the keys in ``BINS`` equal bins of a range
(and those below it), which reduces exactly as integer sums, and takes each bin's
smallest and largest key (reduced by min and max); the keys of the bin holding the
wanted rank, from its smallest to its largest, become the next range. Each pass cuts
the range by ``BINS`` = 2**12, so within ``PASSES`` passes the bin holds one value (the
answer, gathered from no tile: however many points share it, as the exact zeros of a
scan's planes, and however the values spread over orders of magnitude); a bin of at
most ``COLLECT`` values is gathered before that and the rank picked among them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .steps import Partial, Span, Step

if TYPE_CHECKING:
    from .run import Runner

#: Bins per counting pass (a power of two).
BINS = 4096
#: Values gathered at most for the final pick.
COLLECT = 1 << 21
#: Passes that always bring the range down to one key (64 bits, 12 per pass).
PASSES = 6

_LOW = np.int64(0x7FFFFFFFFFFFFFFF)


def _keys(v: np.ndarray) -> np.ndarray:
    """Order-preserving int64 keys of float64 values (-0.0 just below 0.0); the map is
    its own inverse on the bits."""
    bits = np.ascontiguousarray(v, np.float64).view(np.int64)
    return bits ^ ((bits >> 63) & _LOW)


def _value(key: int) -> float:
    """The float64 value of a key."""
    return float(_keys(np.array([key], np.int64).view(np.float64)).view(np.float64)[0])


def _keys_of(span: Span, name: str, kept: str) -> np.ndarray:
    d = span.distinct
    return _keys(span.read(name)[d[span.read(kept)[d]]])


def _bins(k: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """Bin of each key in [lo, hi] (others: -1): its offset from ``lo`` shifted right
    until the range fits in BINS bins."""
    shift = max(0, (hi - lo).bit_length() - (BINS.bit_length() - 1))
    inside = (k >= lo) & (k <= hi)
    off = k.view(np.uint64) - np.int64(lo).view(np.uint64)  # exact modulo 2**64
    return np.where(inside, (off >> np.uint64(shift)).astype(np.int64), -1)


def value_range(span: Span, *, name: str, kept: str) -> Partial:
    """Smallest and largest key."""
    k = _keys_of(span, name, kept)
    big = np.iinfo(np.int64)
    return {"k_min": np.array(k.min(initial=big.max)), "k_max": np.array(k.max(initial=big.min))}


def value_counts(span: Span, *, name: str, kept: str, lo: int, hi: int) -> Partial:
    """Keys below ``lo``, and per bin of [lo, hi] their number, smallest and largest."""
    k = _keys_of(span, name, kept)
    b = _bins(k, lo, hi)
    inside = b >= 0
    big = np.iinfo(np.int64)
    first, last = np.full(BINS, big.max), np.full(BINS, big.min)
    np.minimum.at(first, b[inside], k[inside])
    np.maximum.at(last, b[inside], k[inside])
    return {
        "below": np.array(int((k < lo).sum())),
        "counts": np.bincount(b[inside], minlength=BINS),
        "bin_min": first,
        "bin_max": last,
    }


def value_collect(span: Span, *, name: str, kept: str, lo: int, hi: int, bin: int) -> Partial:
    """The keys of one bin."""
    k = _keys_of(span, name, kept)
    return {"keys_cat": k[_bins(k, lo, hi) == bin]}


def order_statistic(runner: Runner, name: str, kept: str, rank: int) -> float:
    """The ``rank``-th smallest (0-based) value of store array ``name`` over the
    distinct points where ``kept`` is True."""
    where = {"name": name, "kept": kept}
    ends = runner.step(Step("noise range", value_range, None, where))
    lo, hi = int(ends["k_min"]), int(ends["k_max"])
    for passes in range(1, PASSES + 1):
        counted = runner.step(
            Step("noise counts", value_counts, None, {**where, "lo": lo, "hi": hi})
        )
        target = rank - int(counted["below"])
        cum = np.cumsum(counted["counts"])
        b = int(np.searchsorted(cum, target, side="right"))
        first, last = int(counted["bin_min"][b]), int(counted["bin_max"][b])
        if first == last:  # the bin holds one value, the rank's
            return _value(first)
        if int(counted["counts"][b]) <= COLLECT or passes == PASSES:
            got = runner.step(
                Step("noise pick", value_collect, None, {**where, "lo": lo, "hi": hi, "bin": b})
            )["keys_cat"]
            at = target - (int(cum[b - 1]) if b > 0 else 0)
            return _value(int(np.partition(got, at)[at]))
        lo, hi = first, last  # exactly the bin's keys lie in [first, last]
    raise AssertionError("unreachable: the last pass picks")
