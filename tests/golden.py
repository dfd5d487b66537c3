"""Golden outputs of ``detect`` on a few deterministic shapes (``tests/data/golden``).

``scripts/make_golden.py`` writes them; ``tests/test_golden.py`` compares them exactly.
Each shape is chosen so that some constant of robust mode decides part of its answer
(the comments say which).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import shapes

import meshlab_sharp
from evaluation import groundtruth
from meshlab_sharp.reference import detect as reference_sequence

FOLDER = Path(__file__).parent / "data" / "golden"
MODES = ("robust", "paper")

Shape = Callable[[], tuple[np.ndarray, np.ndarray | None]]

SHAPES: dict[str, Shape] = {
    # isolation; support and thinning on clean lines
    "box_points_outliers": lambda: (
        shapes.with_outliers(shapes.random_box_points(1500, seed=2), 15),
        None,
    ),
    # 60 outliers, most of them isolated
    "box_points_many_outliers": lambda: (
        shapes.with_outliers(shapes.random_box_points(1500, seed=0), 60),
        None,
    ),
    # 40 clusters of 2-3 points 1-8 spacings off the surface: isolated or not by the
    # second rule (ISOLATED_NTH, ISOLATED_REF, ISOLATED_SPREAD); ACUTE_SCORE_MAX keeps
    # those near the surface and between candidates out of the candidates
    "box_points_stray_clusters": lambda: (
        shapes.with_stray_clusters(shapes.random_box_points(1500, seed=1), 40, 0.09),
        None,
    ),
    # a 45-degree wedge (the evaluation's Poisson-disk samples): its tip's points join
    # the candidates (reference.robust.acute_tips)
    "wedge45_points": lambda: (
        groundtruth.make_condition("wedge45", "acute", n_points=1500).vertices,
        None,
    ),
    # normal noise of 12 % of the spacing on uniform samples: the scales grow x2.76,
    # below the cap (the noise constants)
    "noisy_box_points": lambda: (shapes.noisy_box_points(1500, 0.12), None),
    # noise of 1.6 % / 1.7 %: noise ratios 0.0486 / 0.0511, either side of NOISE_QUIET
    # (0.05): thresholds at the floor / by Otsu
    "quiet_box_points": lambda: (shapes.noisy_box_points(1500, 0.016), None),
    "faintly_noisy_box_points": lambda: (shapes.noisy_box_points(1500, 0.017), None),
    # noise of 25 %: the growth is capped (x3)
    "noisier_box_points": lambda: (shapes.noisy_box_points(1500, 0.25), None),
    # a plate 1.7 spacings thick: thinning between the two rims
    "thin_plate_points": lambda: (
        shapes.random_box_points(1500, seed=3, size=(2.0, 1.6, 0.12)),
        None,
    ),
    # a plate about 1 spacing thick: the sheet filter (the other side, and how much of
    # the list it may take)
    "thinner_plate_points": lambda: (
        shapes.random_box_points(2500, seed=3, size=(2.0, 1.6, 0.06)),
        None,
    ),
    # noise of 20 % of the edge length: the quartile rule and the vote on rings
    "noisy_cube_mesh": lambda: shapes.noisy_mesh(*shapes.cube_grid_mesh(4), 0.2),
    # creases of 18.5 and 21.5 degrees: sharp or not by CREASE_ANGLE (20); thresholds
    # at the floor R_MIN
    "fold_18_5_mesh": lambda: shapes.fold_mesh(18.5)[:2],
    "fold_21_5_mesh": lambda: shapes.fold_mesh(21.5)[:2],
}


def outputs(
    points: np.ndarray, faces: np.ndarray | None, mode: str, python_driven: bool = False
) -> dict[str, Any]:
    """The scales, thresholds, candidates per scale and feature indices of one mode: of
    ``detect``'s default path (the native library's sequence), or with ``python_driven``
    of the Python-driven sequence (:mod:`meshlab_sharp.reference.detect`, compiled
    steps; it reads the Python modules' constants)."""
    if python_driven:
        result = reference_sequence.detect(points, faces, mode=mode, backend="compiled")
    else:
        result = meshlab_sharp.detect(points, faces, mode=mode)
    return {
        "scales": list(result.scales),
        "thresholds": [float(t) for t in result.thresholds],
        "candidate_counts": [int(c) for c in result.candidate_counts],
        "indices": [int(i) for i in result.indices],
    }


def record(points: np.ndarray, faces: np.ndarray | None) -> dict[str, Any]:
    """What the golden file of one shape holds: its size and coordinate sum (to tell a
    changed input from a changed answer) and :func:`outputs` per mode."""
    out: dict[str, Any] = {"n_points": len(points), "coordinate_sum": float(points.sum())}
    for mode in MODES:
        out[mode] = outputs(points, faces, mode)
    return out


def path(name: str) -> Path:
    """The golden file of a shape."""
    return FOLDER / f"{name}.json"


def load(name: str) -> dict[str, Any]:
    """The stored golden record of a shape."""
    return json.loads(path(name).read_text())
