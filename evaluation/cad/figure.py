"""The picture of one CAD part: B-rep truth, detected features and curves side by side."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from evaluation.groundtruth import SamplePart
from meshlab_sharp.io.writers import atomic_write
from meshlab_sharp.plot import _draw_curves, _frame, _render, require_matplotlib

from .truth import BrepTruth

__all__ = ["save_figure"]

VIEW = (-60.0, 30.0)
TRUTH_COLOUR = "#d7191c"


def save_figure(path: Path, part: SamplePart, truth: BrepTruth, result: Any, title: str) -> Path:
    """Write a PNG (atomically): the cloud with the B-rep's sharp edges, the detected
    features (coloured by strength) and the feature curves with their corners.

    Parameters
    ----------
    path : Path
    part : SamplePart
        The input the detection ran on.
    truth : BrepTruth
    result : DetectionResult
        ``detect(part.vertices, part.faces, curves=True)``.
    title : str
    """
    require_matplotlib()
    from matplotlib import colors as mcolors
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cmap = mcolors.LinearSegmentedColormap.from_list(
        "strength", ["#c8c8c8", "#f2c14e", "#f08a24", "#d7191c"]
    )
    fig = Figure(figsize=(15, 5.4), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 3)
    fig.subplots_adjust(left=0.01, right=0.99, top=0.86, bottom=0.02, wspace=0.02)
    fig.suptitle(title, fontsize=13)
    pts, nrm = part.vertices, part.normals
    none = np.zeros(part.n, bool)
    zero = np.zeros(part.n)
    azim, elev = VIEW
    (right, up, _), centre = _frame(pts, azim, elev)
    _render(axes[0], pts, nrm, none, zero, azim, elev, cmap)
    for a, b in truth.segments - centre:
        axes[0].plot([a @ right, b @ right], [a @ up, b @ up], color=TRUTH_COLOUR, linewidth=1.4)
    if len(truth.corners):
        q = truth.corners - centre
        axes[0].scatter(q @ right, q @ up, s=14, c="k", zorder=3, linewidths=0)
    axes[0].set_title(
        f"B-rep truth: {len(truth.sharp_curves)} sharp curves, {len(truth.corners)} corners",
        fontsize=10,
    )
    _render(axes[1], pts, nrm, result.mask, result.strength, azim, elev, cmap)
    axes[1].set_title(f"features: {int(result.mask.sum()):,} of {part.n:,} points", fontsize=10)
    _render(axes[2], pts, nrm, none, zero, azim, elev, cmap)
    _draw_curves(axes[2], result, pts, azim, elev)
    axes[2].set_title(f"curves: {len(result.curves)}, corners: {len(result.corners)}", fontsize=10)

    def write(tmp: str) -> None:
        fig.savefig(tmp, format="png", dpi=100)

    return atomic_write(path, write)
