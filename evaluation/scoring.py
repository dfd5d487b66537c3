"""Scores of a detected feature set against known sharp-edge segments.

Definitions (``s`` is the point spacing, a scalar or one value per point):

- **true positive**: a detected point within ``1 * s`` of a truth segment;
  **precision** = true positives / detected points (0 when nothing is detected).
- **coverage**: the truth segments are sampled every ``s / 8`` or finer; a sample is
  covered when a detected point lies within ``1.5 * s`` of it; coverage = covered
  length / total length.
- **F1** = 2 P C / (P + C) (0 when P + C = 0).
- **thickness**: detected points within ``band * s`` (default 2) of the edges, divided
  by the covered edge length measured in spacings: ``n_band * s / L_covered``. A line
  one point wide, one point every ``s`` along the edge, gives 1.0; a band of two such
  rows gives 2.0. NaN when nothing is covered.
- **false-positive rate**: detected points farther than ``1 * s`` from every truth
  segment, over all points (the score for smooth parts, which have no truth).

With no truth segments (smooth parts), precision, coverage, F1 and thickness are NaN.

A simulated scan measures coverage on the edges it saw (``cover``), precision against
all the edges: a detection on a true edge is right even where the scan did not see
enough of it to count it as findable. Its curves likewise (``evaluate_curves``'s
``cover``): coverage, the truth curves counted and their corners on the seen edges.

**CAD tessellations** (long thin triangles, vertices only where faces meet) are scored
per vertex (``evaluate_vertices``): a vertex is a true feature when it lies on an exact
edge (within ``1e-6`` of the part's size); precision = true features detected /
detected, coverage = recall = true features detected / true features. A spacing-based
score means nothing there: vertices are far apart along the edges and nearly all of
them are on edges. Thickness is NaN (one vertex per vertex).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

if TYPE_CHECKING:
    from meshlab_sharp.parts import SamplePart

__all__ = [
    "POISSON_NN",
    "CurveScores",
    "Scores",
    "density_spacing",
    "distance_to_segments",
    "evaluate",
    "evaluate_curves",
    "evaluate_vertices",
    "local_spacing",
    "sample_segments",
    "score_part",
    "truth_curves",
]


def sample_segments(segments: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points along segments, at most ``step`` apart, each standing for a piece of length.

    Parameters
    ----------
    segments : (e, 2, 3) float
    step : float > 0

    Returns
    -------
    points : (s, 3) float64
        Midpoints of equal pieces of each segment.
    length : (s,) float64
        Length of the piece each point stands for (sums to the total length).
    segment : (s,) int64
        Index of the segment each point lies on.
    """
    seg = np.asarray(segments, np.float64).reshape(-1, 2, 3)
    if len(seg) == 0:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64)
    lengths = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    counts = np.maximum(1, np.ceil(lengths / step).astype(np.int64))
    sid = np.repeat(np.arange(len(seg)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    t = (np.arange(len(sid)) - first + 0.5) / counts[sid]
    pts = seg[sid, 0] + t[:, None] * (seg[sid, 1] - seg[sid, 0])
    return pts, (lengths / counts)[sid], sid


def distance_to_segments(
    points: np.ndarray, segments: np.ndarray, *, step: float | None = None
) -> np.ndarray:
    """Euclidean distance from each point to the nearest of the segments.

    Exact for the candidate segments found through a kd-tree of samples taken every
    ``step`` along the segments (default: 1/200 of the segments' bounding-box
    diagonal); the candidates are the segments of the 8 nearest samples, so the
    result is never more than ``step / 2`` above the true distance.

    Parameters
    ----------
    points : (n, 3) float
    segments : (e, 2, 3) float

    Returns
    -------
    (n,) float64; ``inf`` everywhere when there are no segments.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    seg = np.asarray(segments, np.float64).reshape(-1, 2, 3)
    if len(seg) == 0:
        return np.full(len(pts), np.inf)
    if len(pts) == 0:
        return np.zeros(0)
    if step is None:
        diag = float(np.linalg.norm(np.ptp(seg.reshape(-1, 3), axis=0)))
        step = diag / 200 if diag > 0 else 1.0
    samples, _, sid = sample_segments(seg, step)
    k = min(8, len(samples))
    _, idx = cKDTree(samples).query(pts, k=k)
    idx = idx.reshape(len(pts), k)
    cand = sid[idx]  # (n, k)
    a = seg[cand, 0]
    ab = seg[cand, 1] - a
    ap = pts[:, None, :] - a
    denom = np.einsum("nkj,nkj->nk", ab, ab)
    t = np.clip(np.einsum("nkj,nkj->nk", ap, ab) / np.where(denom > 0, denom, 1.0), 0.0, 1.0)
    d = np.linalg.norm(ap - t[..., None] * ab, axis=2)
    return d.min(axis=1)


def local_spacing(points: np.ndarray, k: int = 16) -> np.ndarray:
    """Per-point spacing: mean nearest-neighbour distance over each point's k nearest.

    Parameters
    ----------
    points : (n, 3) float

    Returns
    -------
    (n,) float64
    """
    pts = np.asarray(points, np.float64)
    tree = cKDTree(pts)
    d, _ = tree.query(pts, k=2)
    nn = d[:, 1]
    _, idx = tree.query(pts, k=min(k, len(pts)))
    return nn[idx].reshape(len(pts), -1).mean(axis=1)


POISSON_NN = 0.78
"""Mean nearest-neighbour distance of a maximal Poisson-disk point set, in units of
``sqrt(area per point)`` (measured on ``groundtruth``'s clouds: 0.775 to 0.783)."""


def density_spacing(points: np.ndarray, k: int = 16) -> np.ndarray:
    """Per-point spacing from the local density: ``POISSON_NN * sqrt(pi r_k^2 / k)``.

    ``r_k`` is the distance to the k-th nearest neighbour, so ``pi r_k^2 / k`` is the
    surface area per point around the point; the result is the mean nearest-neighbour
    distance that a Poisson-disk cloud of that density has. Unlike ``local_spacing``
    it is not shrunk by close pairs, as where the views of a scan overlap at random.

    Parameters
    ----------
    points : (n, 3) float

    Returns
    -------
    (n,) float64
    """
    pts = np.asarray(points, np.float64)
    kk = min(k, len(pts) - 1)
    d, _ = cKDTree(pts).query(pts, k=kk + 1)
    return POISSON_NN * np.sqrt(np.pi / kk) * d[:, -1]


@dataclass(frozen=True)
class Scores:
    """Scores of one detection (see the module docstring for definitions)."""

    precision: float
    coverage: float
    f1: float
    thickness: float
    fp_rate: float
    n_points: int
    n_detected: int
    n_true_positive: int
    edge_length: float

    def as_dict(self) -> dict:
        """Plain dict (for JSON and tables)."""
        return asdict(self)


def evaluate(
    points: np.ndarray,
    mask: np.ndarray,
    segments: np.ndarray,
    spacing: float | np.ndarray,
    *,
    band: float = 2.0,
    cover: np.ndarray | None = None,
) -> Scores:
    """Score a detected mask against truth segments.

    Parameters
    ----------
    points : (n, 3) float
        All points (mesh vertices), including any outliers.
    mask : (n,) bool
        Detected features.
    segments : (e, 2, 3) float
        Truth sharp-edge segments (may be empty).
    spacing : float or (n,) float
        Point spacing, global or per point (e.g. ``local_spacing`` or a density
        gradient's ``extra["local_spacing"]``). Per-point spacing applies at each
        point; along the edges, the spacing of the nearest point is used.
    band : float
        Half-width, in spacings, of the band whose detected points count for thickness.
    cover : (c, 2, 3) float, optional
        The segments whose coverage is measured (default ``segments``): for a scan, the
        pieces of the edges it saw. ``edge_length`` is their length.

    Returns
    -------
    Scores
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    det = np.asarray(mask, bool).reshape(-1)
    if det.shape[0] != pts.shape[0]:
        raise ValueError("mask and points differ in length")
    sp = np.broadcast_to(np.asarray(spacing, np.float64), (len(pts),))
    seg = np.asarray(segments, np.float64).reshape(-1, 2, 3)
    n_det = int(det.sum())
    dist = distance_to_segments(pts[det], seg, step=float(sp.min()) / 4 if len(pts) else None)
    near = dist <= sp[det]
    n_tp = int(near.sum())
    fp_rate = (n_det - n_tp) / len(pts) if len(pts) else 0.0
    cov_seg = seg if cover is None else np.asarray(cover, np.float64).reshape(-1, 2, 3)
    if len(seg) == 0 or len(cov_seg) == 0:
        nan = math.nan
        return Scores(nan, nan, nan, nan, fp_rate, len(pts), n_det, n_tp, 0.0)
    total = float(np.linalg.norm(cov_seg[:, 1] - cov_seg[:, 0], axis=1).sum())
    precision = n_tp / n_det if n_det else 0.0
    samples, piece, _ = sample_segments(cov_seg, float(sp.min()) / 8)
    # spacing along the edges: that of the nearest point
    _, nearest = cKDTree(pts).query(samples)
    sp_edge = sp[nearest]
    if n_det:
        d_cov, _ = cKDTree(pts[det]).query(samples)
        covered = d_cov <= 1.5 * sp_edge
    else:
        covered = np.zeros(len(samples), bool)
    cov_len = float(piece[covered].sum())
    coverage = cov_len / total if total > 0 else 0.0
    f1 = 2 * precision * coverage / (precision + coverage) if precision + coverage > 0 else 0.0
    if cov_len > 0:
        in_band = dist <= band * sp[det]
        # covered length in units of spacing
        cov_sp = float((piece[covered] / sp_edge[covered]).sum())
        thickness = float(in_band.sum()) / cov_sp
    else:
        thickness = math.nan
    return Scores(precision, coverage, f1, thickness, fp_rate, len(pts), n_det, n_tp, total)


def evaluate_vertices(
    points: np.ndarray, mask: np.ndarray, segments: np.ndarray, *, tol: float | None = None
) -> Scores:
    """Score a detected mask per vertex: a vertex is a true feature when it lies on a
    truth segment.

    Parameters
    ----------
    points : (n, 3) float
        Mesh vertices.
    mask : (n,) bool
        Detected features.
    segments : (e, 2, 3) float
        Truth sharp-edge segments (may be empty: precision, coverage, F1 NaN).
    tol : float, optional
        Distance under which a vertex is on a segment (default ``1e-6`` times the
        bounding-box diagonal of the points: float32 rounding, nothing more).

    Returns
    -------
    Scores
        ``coverage`` is the recall (true features detected / true features),
        ``n_true_positive`` the true features detected, thickness NaN.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    det = np.asarray(mask, bool).reshape(-1)
    if det.shape[0] != pts.shape[0]:
        raise ValueError("mask and points differ in length")
    seg = np.asarray(segments, np.float64).reshape(-1, 2, 3)
    diag = float(np.linalg.norm(np.ptp(pts, axis=0))) if len(pts) else 1.0
    tol = 1e-6 * diag if tol is None else float(tol)
    n_det = int(det.sum())
    nan = math.nan
    if len(seg) == 0:
        return Scores(nan, nan, nan, nan, n_det / max(len(pts), 1), len(pts), n_det, 0, 0.0)
    lengths = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    step = min(float(np.median(lengths)) / 4, diag / 200)
    true = distance_to_segments(pts, seg, step=step) <= tol
    n_tp = int((true & det).sum())
    precision = n_tp / n_det if n_det else 0.0
    recall = n_tp / int(true.sum()) if true.any() else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    fp_rate = (n_det - n_tp) / len(pts)
    return Scores(precision, recall, f1, nan, fp_rate, len(pts), n_det, n_tp, float(lengths.sum()))


def score_part(part: SamplePart, mask: np.ndarray) -> Scores:
    """Score a detection on a generated part the way its condition asks.

    CAD tessellations (``part.extra["scoring"] == "vertices"``) per vertex
    (``evaluate_vertices``); everything else with ``evaluate`` and the part's spacing:
    ``extra["local_spacing"]`` when present (density gradient, scan), else
    ``part.spacing``; a scan's coverage on ``extra["visible_edges"]``.

    Parameters
    ----------
    part : meshlab_sharp.parts.SamplePart
    mask : (n,) bool

    Returns
    -------
    Scores
    """
    if part.extra.get("scoring") == "vertices":
        return evaluate_vertices(part.vertices, mask, part.edges)
    spacing = part.extra.get("local_spacing", part.spacing)
    return evaluate(part.vertices, mask, part.edges, spacing, cover=part.extra.get("visible_edges"))


# ----------------------------------------------------------------------------------
# Feature curves
# ----------------------------------------------------------------------------------

#: Degrees: exact edges are split into curves where they turn by more than this (the
#: curve extraction's ``trace.CORNER_TURN``).
TRUTH_CORNER_TURN = 45.0


def truth_curves(segments: np.ndarray) -> tuple[int, np.ndarray]:
    """The exact edges as curves between corners, and the corners.

    Segments are chained at shared end points; a chain ends where the degree is not 2
    or where consecutive segments turn by more than :data:`TRUTH_CORNER_TURN` degrees.

    Parameters
    ----------
    segments : (e, 2, 3) float

    Returns
    -------
    n_curves : int
        Chains (closed loops count once).
    corners : (c, 3) float64
        End points where three or more segments meet or the edges turn sharply.
    """
    seg = np.asarray(segments, np.float64).reshape(-1, 2, 3)
    if len(seg) == 0:
        return 0, np.zeros((0, 3))
    ends = seg.reshape(-1, 3)
    scale = float(np.linalg.norm(np.ptp(ends, axis=0))) or 1.0
    _, node = np.unique(np.round(ends / (scale * 1e-7)), axis=0, return_inverse=True)
    node = node.reshape(-1, 2)
    n = int(node.max()) + 1
    pos = np.zeros((n, 3))
    pos[node.reshape(-1)] = ends
    incident: list[list[int]] = [[] for _ in range(n)]
    for i, (a, b) in enumerate(node):
        incident[a].append(i)
        incident[b].append(i)
    limit = math.cos(math.radians(TRUTH_CORNER_TURN))

    def direction(i: int, away_from: int) -> np.ndarray:
        a, b = node[i]
        d = pos[b] - pos[a] if a == away_from else pos[a] - pos[b]
        return d / np.linalg.norm(d)

    corner = np.zeros(n, bool)
    for v, inc in enumerate(incident):
        if len(inc) >= 3 or (
            len(inc) == 2 and -float(direction(inc[0], v) @ direction(inc[1], v)) < limit
        ):
            corner[v] = True
    stop = corner | np.array([len(inc) != 2 for inc in incident])
    # chains: union segments through non-stop vertices
    parent = np.arange(len(seg))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = int(parent[i])
        return i

    for v, inc in enumerate(incident):
        if not stop[v]:
            ra, rb = root(inc[0]), root(inc[1])
            parent[max(ra, rb)] = min(ra, rb)
    n_curves = len({root(i) for i in range(len(seg))})
    return n_curves, pos[corner]


@dataclass(frozen=True)
class CurveScores:
    """Scores of extracted curves against exact edges (see :func:`evaluate_curves`)."""

    precision: float
    coverage: float
    rms: float
    count_ratio: float
    corners_found: float
    n_curves: int
    n_truth_curves: int
    n_corners: int
    n_truth_corners: int

    def as_dict(self) -> dict:
        """Plain dict (for JSON and tables)."""
        return asdict(self)


def evaluate_curves(
    curves: list,
    corners: np.ndarray,
    segments: np.ndarray,
    spacing: float,
    *,
    cover: np.ndarray | None = None,
) -> CurveScores:
    """Score feature curves against exact edge segments.

    - **precision**: share of the curves' length within ``1 * spacing`` of an edge;
    - **coverage**: share of the edges' length within ``1.5 * spacing`` of a curve;
    - **rms**: RMS distance of the curves' vertices to the edges, in spacings;
    - **count_ratio**: number of curves / number of exact curves between corners
      (:func:`truth_curves`);
    - **corners_found**: share of the exact corners with a corner within
      ``2 * spacing`` (NaN when the part has none).

    With ``cover``, coverage, count ratio and corners are measured on those segments
    (for a scan, the pieces of the edges it saw, as :func:`evaluate`'s ``cover``);
    precision and RMS on all of ``segments``.

    Parameters
    ----------
    curves : list of Curve
        ``DetectionResult.curves`` (anything with ``points`` (m, 3) and ``closed``).
    corners : (c, 3) float
        Corner positions (``DetectionResult.corners.points``).
    segments : (e, 2, 3) float
        Exact sharp edges (``SamplePart.edges``).
    spacing : float
        Point spacing (``SamplePart.spacing``).
    cover : (c, 2, 3) float, optional
        The segments whose coverage, curves and corners are measured (default
        ``segments``).

    Returns
    -------
    CurveScores
    """
    seg = np.asarray(segments, np.float64).reshape(-1, 2, 3)
    cov_seg = seg if cover is None else np.asarray(cover, np.float64).reshape(-1, 2, 3)
    n_truth, truth_corners = truth_curves(cov_seg)
    pieces = [
        np.stack([c.points, np.roll(c.points, -1, axis=0)], axis=1)[
            : len(c.points) if c.closed else len(c.points) - 1
        ]
        for c in curves
    ]
    curve_seg = np.concatenate(pieces) if pieces else np.zeros((0, 2, 3))
    step = spacing / 4
    nan = math.nan
    if len(curve_seg):
        samples, piece, _ = sample_segments(curve_seg, step)
        near = distance_to_segments(samples, seg, step=step) <= spacing
        precision = float(piece[near].sum() / piece.sum()) if piece.sum() > 0 else nan
        verts = np.concatenate([c.points for c in curves])
        rms = float(np.sqrt(np.mean((distance_to_segments(verts, seg, step=step) / spacing) ** 2)))
    else:
        precision, rms = nan, nan
    if len(cov_seg) and len(curve_seg):
        samples, piece, _ = sample_segments(cov_seg, spacing / 8)
        covered = distance_to_segments(samples, curve_seg, step=step) <= 1.5 * spacing
        coverage = float(piece[covered].sum() / piece.sum())
    else:
        coverage = 0.0 if len(cov_seg) else nan
    c = np.asarray(corners, np.float64).reshape(-1, 3)
    if len(truth_corners):
        found = (
            cKDTree(c).query(truth_corners)[0] <= 2 * spacing
            if len(c)
            else np.zeros(len(truth_corners), bool)
        )
        corners_found = float(found.mean())
    else:
        corners_found = nan
    ratio = len(curves) / n_truth if n_truth else nan
    return CurveScores(
        precision,
        coverage,
        rms,
        ratio,
        corners_found,
        len(curves),
        n_truth,
        len(c),
        len(truth_corners),
    )
