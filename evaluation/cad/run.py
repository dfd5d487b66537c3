"""Run the default mode on a CAD part's inputs and score it against the B-rep truth.

- **detection** per point (``evaluation.scoring.score_part``: precision, coverage,
  F1 within one spacing of the exact sharp edges), on every input but the STL-like
  tessellation (a vertex labelling cannot cover a long edge);
- **curves** (``detect(..., curves=True)``) by ``evaluation.scoring.evaluate_curves``'s
  precision, coverage and count ratio, and corners found against the B-rep corners
  (vertices of three or more sharp curves) within two spacings;
- on a **scan**, detection coverage, curve coverage, count ratio and corners are
  measured on the truth the scanner saw (``evaluation.cad.inputs``: the seen pieces of
  the exact edges); a corner is seen when the seen pieces of three or more of its
  sharp curves end at it. Precision is measured against all the exact edges;
- **parts** are *clear*, *ambiguous* (an angle between 15 and 30 degrees somewhere on
  a curve, or two separate sharp features closer than 3 blue-noise spacings) or
  *filleted* (no sharp curve: the score is the share of points flagged).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from evaluation.groundtruth import SamplePart, expected_spacing
from evaluation.scoring import evaluate_curves, score_part
from meshlab_sharp import detect

from .inputs import INPUTS, make_inputs, surface_area
from .sources import CadSource, load
from .truth import CLOSE_SPACINGS, BrepTruth, brep_truth, closest_gap

__all__ = [
    "CLASSES",
    "classify",
    "curve_scores",
    "evaluate_part",
    "score_input",
    "seen_corners",
    "summarise",
]

#: Part classes, in table order.
CLASSES = ("clear", "ambiguous", "filleted")


def classify(truth: BrepTruth, spacing: float) -> tuple[str, list[str]]:
    """The class of a part's truth at a spacing, and the reasons it is ambiguous."""
    if len(truth.segments) == 0:
        return "filleted", []
    reasons = []
    angles = truth.ambiguous_angles()
    if angles:
        reasons.append(f"{len(angles)} curves with angles in 15-30 degrees")
    gap = closest_gap(truth, CLOSE_SPACINGS * spacing)
    if gap < CLOSE_SPACINGS * spacing:
        reasons.append(f"features {gap / spacing:.2f} spacings apart")
    return ("ambiguous" if reasons else "clear"), reasons


def score_input(part: SamplePart, truth: BrepTruth, condition: str) -> dict:
    """Detect (default mode, with curves) and score detection and curves."""
    t0 = time.perf_counter()
    result = detect(part.vertices, part.faces, curves=True)
    seconds = time.perf_counter() - t0
    row: dict = {"n": part.n, "seconds": seconds}
    mask = result.mask
    row["flagged"] = float(mask.mean())
    if condition != "stl_like":
        row["detection"] = score_part(part, mask).as_dict()
    assert result.curves is not None and result.corners is not None
    seen = part.extra.get("seen")
    row["curves"] = curve_scores(
        result.curves, result.corners.points, truth, part.spacing, seen=seen
    )
    return row


def seen_corners(truth: BrepTruth, seen: np.ndarray) -> np.ndarray:
    """The B-rep corners where the seen pieces of three or more sharp curves end.

    Parameters
    ----------
    truth : BrepTruth
    seen : (e,) bool
        The seen pieces among ``truth.segments``.

    Returns
    -------
    (c, 3) float64
    """
    if len(truth.corners) == 0 or not np.any(seen):
        return np.zeros((0, 3))
    ends = truth.segments[seen].reshape(-1, 3)
    curve = np.repeat(truth.segment_curve[seen], 2)
    # a piece ends at a corner where its end point is the corner's position (float
    # rounding aside)
    near = cKDTree(ends).query_ball_point(truth.corners, 1e-6 * truth.diagonal)
    keep = [len(set(curve[k].tolist())) >= 3 for k in near]
    return truth.corners[np.asarray(keep, bool)]


def curve_scores(
    curves: list,
    corners: np.ndarray,
    truth: BrepTruth,
    spacing: float,
    *,
    seen: np.ndarray | None = None,
) -> dict:
    """Curves scored by ``evaluation.scoring.evaluate_curves`` (precision, coverage, RMS,
    count ratio), corners against the B-rep corners: found when a corner lies within
    ``2 * spacing``; ``corners_hit`` counts them. With ``seen`` (which of
    ``truth.segments`` a scan saw), coverage, count ratio and corners are measured on
    the seen truth (:func:`seen_corners`)."""
    cover = None if seen is None else truth.segments[seen]
    scores = evaluate_curves(curves, corners, truth.segments, spacing, cover=cover)
    truth_corners = truth.corners if seen is None else seen_corners(truth, seen)
    c = np.asarray(corners, np.float64).reshape(-1, 3)
    if len(truth_corners) and len(c):
        hit = int((cKDTree(c).query(truth_corners)[0] <= 2 * spacing).sum())
    else:
        hit = 0
    found = hit / len(truth_corners) if len(truth_corners) else math.nan
    scores = replace(scores, corners_found=found, n_truth_corners=len(truth_corners))
    return {**scores.as_dict(), "corners_hit": hit}


def evaluate_part(
    source: CadSource,
    n: int,
    workdir: Path,
    *,
    seed: int = 0,
    inputs: tuple[str, ...] = INPUTS,
) -> dict:
    """Load one part, build its truth and inputs, and score every input.

    Returns
    -------
    dict
        ``name``, ``package``, ``file``, ``class``, ``reasons``, truth counts and
        ``inputs``: input name to :func:`score_input`'s row.
    """
    import gmsh

    t0 = time.perf_counter()
    load(source, workdir)
    truth = brep_truth()
    spacing = expected_spacing(surface_area(), n, "points")
    parts = make_inputs(
        source.name, truth.segments, n, seed=seed, which=inputs, curve=truth.segment_curve
    )
    cls, reasons = classify(truth, spacing)
    n_curves = len(gmsh.model.getEntities(1))
    built = time.perf_counter() - t0
    rows = {k: score_input(p, truth, k) for k, p in parts.items()}
    return {
        "name": source.name,
        "package": source.package,
        "file": str(source.path) + (f":{source.member}" if source.member else ""),
        "class": cls,
        "reasons": reasons,
        "brep_curves": n_curves,
        "sharp_curves": len(truth.sharp_curves),
        "corners": len(truth.corners),
        "edge_length_spacings": truth.edge_length / spacing,
        "spacing": spacing,
        "build_seconds": built,
        "inputs": rows,
    }


def _mean(values: list[float]) -> float:
    vals = [v for v in values if not math.isnan(v)]
    return float(np.mean(vals)) if vals else math.nan


def summarise(rows: list[dict]) -> dict:
    """Per class and input: mean detection F1 (precision, coverage), mean share
    flagged, mean curve precision and coverage, median count ratio, corners found
    (pooled over the parts), number of parts."""
    out: dict = {}
    for cls in CLASSES:
        sel = [r for r in rows if r["class"] == cls]
        if not sel:
            continue
        out[cls] = {}
        for name in INPUTS:
            res = [r["inputs"][name] for r in sel if name in r["inputs"]]
            if not res:
                continue
            s: dict = {"parts": len(res), "flagged": _mean([x["flagged"] for x in res])}
            det = [x["detection"] for x in res if "detection" in x]
            if det and cls != "filleted":
                for k in ("f1", "precision", "coverage"):
                    s[k] = _mean([d[k] for d in det])
            if cls != "filleted":
                cur = [x["curves"] for x in res]
                s["curve_precision"] = _mean([c["precision"] for c in cur])
                s["curve_coverage"] = _mean([c["coverage"] for c in cur])
                s["count_ratio_median"] = float(np.nanmedian([c["count_ratio"] for c in cur]))
                hit = sum(c["corners_hit"] for c in cur)
                total = sum(c["n_truth_corners"] for c in cur)
                s["corners_found"] = hit / total if total else math.nan
            out[cls][name] = s
    return out
