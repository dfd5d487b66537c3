"""The multiscale decision: candidates at every scale are sharp features."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import _kernels
from .defaults import DEFAULT_KNN_SCALES as DEFAULT_KNN_SCALES  # re-exported
from .defaults import DEFAULT_RING_SCALES as DEFAULT_RING_SCALES
from .neighbourhoods import KnnNeighbourhoods, RingNeighbourhoods
from .normals import DEFAULT_WEIGHTING, Weighting
from .reference.projected_distance import projected_distances
from .threshold import FLAT_TOLERANCE, normalise, otsu_threshold

if TYPE_CHECKING:
    from .reference.robust import SheetNeighbourhoods


@dataclass
class ScaleResults:
    """What every scale produced, per cleaned point.

    Attributes
    ----------
    scales : tuple of int
    thresholds : (s,) float64
        Otsu's threshold T at each scale.
    candidate_counts : (s,) int64
        Number of candidates at each scale.
    votes : (m,) int64
        Number of scales at which each point was a candidate.
    distances : (s, m) float64 or None
        Normalised projected distances, when kept.
    normals : (s, m, 3) float64 or None
        Normals used at each scale, when kept.
    """

    scales: tuple[int, ...]
    thresholds: np.ndarray
    candidate_counts: np.ndarray
    votes: np.ndarray
    distances: np.ndarray | None = None
    normals: np.ndarray | None = None


def run_scales(
    points: np.ndarray,
    neighbourhoods: KnnNeighbourhoods | RingNeighbourhoods | SheetNeighbourhoods,
    scales: Sequence[int],
    *,
    normals: np.ndarray | None = None,
    weighting: Weighting = DEFAULT_WEIGHTING,
    keep_details: bool = False,
    on_scale: Callable[[int], None] | None = None,
    rule: Callable[..., tuple[np.ndarray, float]] | None = None,
    relative: bool = False,
    fused: _kernels.ScalePass | None = None,
) -> ScaleResults:
    """Projected distance, normalisation and Otsu's threshold at each scale.

    Parameters
    ----------
    points : (m, 3) float64
        Cleaned points.
    neighbourhoods : KnnNeighbourhoods, RingNeighbourhoods or SheetNeighbourhoods
        (robust mode on a cloud with the numpy backend: the lists less other sheets)
    scales : sequence of int
        Increasing scales.
    normals : (m, 3) float64, optional
        Fixed normals of a mesh (zero rows fall back to PCA); None for a cloud.
    weighting : {"gaussian", "none"}
    keep_details : bool, default False
        Keep the per-scale normalised distances and normals.
    on_scale : callable, optional
        Called with each scale when it is done (progress reporting).
    rule : callable, optional
        ``rule(i, scale, pdis) -> (values, threshold)`` replaces min-max normalisation
        and Otsu's threshold (robust mode, :class:`meshlab_sharp.reference.detect.RelativeRule`).
        None: the paper's rule.
    relative : bool, default False
        Robust mode (``rule`` a :class:`meshlab_sharp.reference.detect.RelativeRule`): where the
        compiled pass over a cloud or a mesh's rings computes the projected distances it
        also computes what the rule computes from them, bit for bit (the relative
        distances and the score; on a cloud, on the neighbourhoods less ``rule.sheet``'s
        other sheets), ``rule.from_pass`` takes the score and the C kernel thresholds
        the relative distances; elsewhere the rule is called.
    fused : ScalePass, optional
        The compiled pass over these points at these scales, already run
        (:class:`meshlab_sharp.reference.detect.RobustSetup` runs it to read the isolated points
        and the noise from the same search); None: run it here.

    The backend is the neighbourhoods': with "compiled", the projected distances of
    every scale come from one pass of the C kernels over the points (neighbourhoods
    searched and used at once), then each scale is normalised, thresholded and voted in
    one C call (:func:`meshlab_sharp._kernels.scale_vote`, the same arithmetic as
    "numpy").
    """
    m, s = len(points), len(scales)
    if fused is None:
        sheet = getattr(rule, "sheet", None) if relative else None
        fused = _compiled_projected_distances(
            points, neighbourhoods, scales, normals, weighting, keep_details, relative, sheet,
            tree_order=rule is None or relative,  # read by scale_vote only
        )  # fmt: skip
    # read by the paper's rule only
    flat_span = _flat_span(points, fused is not None) if rule is None else 0.0
    thresholds = np.empty(s)
    counts = np.empty(s, dtype=np.int64)
    votes = np.zeros(m, dtype=np.int64)
    distances = np.empty((s, m)) if keep_details else None
    used_normals = np.empty((s, m, 3)) if keep_details else None
    for i, scale in enumerate(scales):
        used = None if fused is None or fused.normals is None else fused.normals[i]
        out = None if distances is None else distances[i]
        if fused is not None and fused.relative is not None and fused.score is not None:
            otsu, floor = rule.from_pass(fused.score, i, fused.relative[i])  # type: ignore[union-attr]
            thresholds[i], counts[i] = _kernels.scale_vote(
                fused.relative[i], votes, otsu=otsu, floor=floor, out=out
            )
        elif fused is not None and fused.pdis is not None and rule is None:
            thresholds[i], counts[i] = _kernels.scale_vote(
                fused.pdis[i], votes, flat_span=flat_span, out=out
            )
        else:
            if fused is not None and fused.pdis is not None:
                assert fused.order is None, "a rule reads the distances in cleaned order"
                pdis = fused.pdis[i]
            else:
                pdis, used = projected_distances(
                    points, neighbourhoods.at(scale), normals, weighting=weighting
                )
            if rule is None:
                v = normalise(pdis, flat_span=flat_span)
                thresholds[i] = otsu_threshold(v)
            else:
                v, thresholds[i] = rule(i, scale, pdis)
            candidate = v >= thresholds[i]
            counts[i] = int(candidate.sum())
            votes += candidate
            if out is not None:
                out[:] = v
        if used_normals is not None:
            used_normals[i] = used
        if on_scale is not None:
            on_scale(scale)
    order = None if fused is None else fused.order
    del fused  # its per-scale arrays (when made here) freed before the move's scratch
    if order is not None:  # the votes and the details were in the pass's order
        kept = [] if distances is None or used_normals is None else [*distances, *used_normals]
        _kernels.to_cleaned_order([votes, *kept], order)
    return ScaleResults(
        scales=tuple(scales),
        thresholds=thresholds,
        candidate_counts=counts,
        votes=votes,
        distances=distances,
        normals=used_normals,
    )


def _flat_span(points: np.ndarray, compiled: bool) -> float:
    """``FLAT_TOLERANCE`` times the diagonal of the bounding box of ``points`` (m, 3),
    the box taken column by column (the same values; a reduce over the first axis of an
    (m, 3) array is many times slower), in one C pass when ``compiled``."""
    if compiled:
        span = _kernels.extent(points)
    else:
        span = np.array([np.ptp(points[:, a]) for a in range(3)])
    return FLAT_TOLERANCE * float(np.linalg.norm(span))


def projected_distances_all(
    points: np.ndarray,
    neighbourhoods: KnnNeighbourhoods | RingNeighbourhoods,
    scales: Sequence[int],
    *,
    normals: np.ndarray | None = None,
    weighting: Weighting = DEFAULT_WEIGHTING,
) -> np.ndarray:
    """Raw projected distances (s, m) of every scale, with the neighbourhoods' backend
    (what :func:`run_scales` thresholds; for benchmarks and tests)."""
    fused = _compiled_projected_distances(
        points, neighbourhoods, scales, normals, weighting, False, False
    )
    if fused is not None and fused.pdis is not None:
        return fused.pdis
    return np.stack(
        [
            projected_distances(points, neighbourhoods.at(k), normals, weighting=weighting)[0]
            for k in scales
        ]
    )


def _compiled_projected_distances(
    points: np.ndarray,
    neighbourhoods: KnnNeighbourhoods | RingNeighbourhoods,
    scales: Sequence[int],
    normals: np.ndarray | None,
    weighting: Weighting,
    keep_normals: bool,
    relative: bool,
    sheet: _kernels.SheetParameters | None = None,
    *,
    tree_order: bool = False,
) -> _kernels.ScalePass | None:
    """Projected distances (s, m) and normals (s, m, 3) or None, or (when ``relative``)
    robust mode's relative distances and score instead of the distances,
    of every scale at once with the compiled kernels; None when the neighbourhoods are
    the numpy ones. ``sheet``: robust mode's sheet filter (``RelativeRule.sheet``).
    ``tree_order``: a cloud's per-scale arrays may stay in its kd-tree's order
    (:attr:`meshlab_sharp._kernels.ScalePass.order`)."""
    if not scales:
        return None
    if list(scales) != sorted(set(scales)):
        return None
    if isinstance(neighbourhoods, KnnNeighbourhoods) and neighbourhoods.tree is not None:
        if max(scales) > neighbourhoods.k_max or min(scales) < 1:
            return None
        return _kernels.cloud_projected_distances(
            neighbourhoods.tree,
            scales,
            weighting,
            keep_normals=keep_normals,
            relative=relative,
            sheet=sheet,
            workers=neighbourhoods.workers,
            tree_order=tree_order,
        )
    if isinstance(neighbourhoods, RingNeighbourhoods) and neighbourhoods.adjacency is not None:
        if min(scales) < 1:
            return None
        indptr, indices = neighbourhoods.adjacency
        return _kernels.ring_projected_distances(
            points,
            indptr,
            indices,
            scales,
            normals,
            weighting,
            keep_normals=keep_normals,
            relative=relative,
        )
    return None


def decide(votes: np.ndarray, n_scales: int) -> tuple[np.ndarray, np.ndarray]:
    """Features are candidates at every scale; strength is the fraction of scales.

    Parameters
    ----------
    votes : (m,) int
        Scales at which each point was a candidate.
    n_scales : int

    Returns
    -------
    mask : (m,) bool
    strength : (m,) float64
    """
    return votes == n_scales, votes / float(n_scales)
