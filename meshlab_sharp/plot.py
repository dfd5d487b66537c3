"""The report picture: what Otsu's threshold saw at each scale, and the features drawn
on the object.

Layout (``save_report``): a title with the counts and the time; two rendered views of
the object (orthographic, points depth-sorted and shaded by their normal; strength as
colour, features red and drawn larger; with ``detect(..., curves=True)`` the feature
curves drawn over them, coloured by kind, and the corners as black dots); below, for
each scale, the histogram of the normalised projected distances (the 256 bins Otsu's
method uses, log counts) with the threshold marked and the candidates in red.

Needs matplotlib (the ``plot`` extra: ``pip install 'meshlab-sharp[plot]'``); it draws
with the Agg backend, so no display is needed.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError
from .extras import require
from .io import Geometry, OutputSet, atomic_write

__all__ = ["DEFAULT_SIZE", "VIEWS", "report_figure", "require_matplotlib", "save_report"]

#: Default picture size in pixels (width, height).
DEFAULT_SIZE = (1600, 1200)
#: The rendered views: (azimuth, elevation) in degrees, z up.
VIEWS = ((-60.0, 30.0), (120.0, 30.0))
_DPI = 100
_BINS = 256
_MAX_DRAWN = 120_000
#: Colour of each curve kind in the views.
CURVE_COLOURS = {"line": "#1f5fbf", "arc": "#1a9850", "freeform": "#8e24aa"}


#: What the histograms show, per mode: min-max normalised projected distances (paper)
#: or projected distances relative to the local spacing (robust).
DISTANCE_LABELS = {
    "paper": "normalised projected distance",
    "robust": "relative projected distance (pdis / local spacing)",
}


def require_matplotlib() -> Any:
    """Import matplotlib (drawing goes through its Agg canvas: no display, no pyplot
    state is touched), or raise a one-line error."""
    require("matplotlib.backends.backend_agg", "the report picture", "plot")
    return require("matplotlib", "the report picture", "plot")


def save_report(
    path: str | os.PathLike[str],
    result: Any,
    geometry: Geometry | None = None,
    *,
    title: str | None = None,
    size: tuple[int, int] = DEFAULT_SIZE,
    into: OutputSet | None = None,
) -> Path:
    """Write the report picture of a detection as a PNG (atomically).

    Parameters
    ----------
    path : path-like
        Destination ``.png``.
    result : DetectionResult
        From ``detect(..., return_details=True)`` (the histograms need the distances).
    geometry : Geometry, optional
        The input geometry the result is about (its vertices in the result's order).
        Not needed when the result carries preprocessing: the processed geometry is
        drawn, as detection saw it.
    title : str, optional
        First line of the title (default: the geometry's source).
    size : (int, int)
        Width and height in pixels.
    into : OutputSet, optional
        Only stage the picture in this set (see :func:`meshlab_sharp.io.atomic_write`).

    Returns
    -------
    Path
    """
    dest = Path(path)
    if dest.suffix.lower() != ".png":
        raise InputError(f"{dest}: the report picture must be a .png file")
    fig = report_figure(result, geometry, title=title, size=size)

    def write(tmp: str) -> None:
        fig.savefig(tmp, format="png", dpi=_DPI)

    return atomic_write(dest, write, into=into)


def report_figure(
    result: Any,
    geometry: Geometry | None = None,
    *,
    title: str | None = None,
    size: tuple[int, int] = DEFAULT_SIZE,
) -> Any:
    """The report as a matplotlib Figure (see :func:`save_report`)."""
    require_matplotlib()
    from matplotlib import colors as mcolors
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.figure import Figure
    from matplotlib.gridspec import GridSpec

    width, height = _check_size(size)
    shown, geom = _shown(result, geometry)
    if shown.distances is None or shown.normals is None:
        raise InputError("the report picture needs detect(..., return_details=True)")
    n_scales = len(shown.scales)
    cols = min(4, n_scales)
    rows = -(-n_scales // cols)

    fig = Figure(figsize=(width / _DPI, height / _DPI), dpi=_DPI)
    FigureCanvasAgg(fig)
    grid = GridSpec(
        1 + rows,
        cols,
        figure=fig,
        height_ratios=[2.6 if rows > 1 else 1.7] + [1.0] * rows,
        left=0.05,
        right=0.93,
        top=0.9,
        bottom=0.05,
        hspace=0.5,
        wspace=0.22,
    )
    fig.suptitle(_title(result, geom, title), fontsize=14)

    cmap = mcolors.LinearSegmentedColormap.from_list(
        "strength", ["#c8c8c8", "#f2c14e", "#f08a24", "#d7191c"]
    )
    half = cols // 2 if cols > 1 else 1
    view_axes = [fig.add_subplot(grid[0, :half]), fig.add_subplot(grid[0, half:])]
    points, normals, mask, strength = _drawable(shown, geom)
    for ax, (azim, elev) in zip(view_axes, VIEWS, strict=True):
        _render(ax, points, normals, mask, strength, azim, elev, cmap)
        if result.curves is not None:
            _draw_curves(ax, result, points, azim, elev)
    mappable = ScalarMappable(norm=mcolors.Normalize(0.0, 1.0), cmap=cmap)
    bar = fig.colorbar(mappable, ax=view_axes, fraction=0.02, pad=0.01, shrink=0.8)
    bar.set_label("feature strength (fraction of scales)", fontsize=11)

    unit = "k" if shown.kind == "points" else "ring"
    for i in range(n_scales):
        ax = fig.add_subplot(grid[1 + i // cols, i % cols])
        _histogram(
            ax, shown.distances[i], float(shown.thresholds[i]), int(shown.candidate_counts[i])
        )
        ax.set_title(f"{unit} = {shown.scales[i]}", fontsize=11)
        if i % cols == 0:
            ax.set_ylabel("points (log)", fontsize=10)
        if i // cols == rows - 1:
            ax.set_xlabel(DISTANCE_LABELS.get(shown.mode, DISTANCE_LABELS["paper"]), fontsize=10)
    return fig


def _check_size(size: tuple[int, int]) -> tuple[int, int]:
    try:
        width, height = (int(s) for s in size)
    except (TypeError, ValueError):
        raise InputError(f"size must be (width, height) in pixels, got {size!r}") from None
    if not (200 <= width <= 10000 and 200 <= height <= 10000):
        raise InputError(f"size must be 200..10000 pixels each way, got {size!r}")
    return width, height


def _shown(result: Any, geometry: Geometry | None) -> tuple[Any, Geometry]:
    """The result and geometry to draw: the processed ones when preprocessing ran."""
    report = getattr(result, "preprocessing", None)
    if report is not None and report.result is not None:
        return report.result, report.geometry
    if geometry is None:
        raise InputError("save_report needs the geometry the result is about")
    if len(geometry.vertices) != len(result.mask):
        raise InputError(
            f"the geometry has {len(geometry.vertices)} vertices but the result {len(result.mask)}"
        )
    return result, geometry


def _title(result: Any, geom: Geometry, title: str | None) -> str:
    n = len(result.mask)
    kind = "vertices" if result.kind == "mesh" else "points"
    head = title or str(geom.source).removesuffix(" (preprocessed)")
    line = (
        f"{head}: {n:,} {kind}, {result.mode} mode, {result.n_features:,} sharp features "
        f"({100.0 * result.n_features / max(n, 1):.1f}%), {len(result.scales)} scales, "
        f"{result.timings.get('total', 0.0):.2f} s"
    )
    report = getattr(result, "preprocessing", None)
    if report is not None:
        done = [s["step"].replace("_", " ") for s in report.steps if "skipped" not in s]
        added = int((report.to_input < 0).sum())
        dropped = int((~result.kept).sum())
        line += (
            f"\npreprocessing: {', '.join(done) or 'none applied'}; {dropped:,} input "
            f"{kind} removed, {added:,} added (drawn: the processed geometry)"
        )
    return line


def _drawable(shown: Any, geom: Geometry) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Points that took part, their normals (first scale), mask and strength; at most
    ``_MAX_DRAWN`` (non-features thinned evenly)."""
    keep = np.asarray(shown.kept, bool) & np.isfinite(shown.normals[0]).all(axis=1)
    idx = np.flatnonzero(keep)
    features = shown.mask[idx]
    if len(idx) > _MAX_DRAWN:
        rest = idx[~features]
        step = -(-len(rest) // max(_MAX_DRAWN - int(features.sum()), 1))
        idx = np.sort(np.concatenate([idx[features], rest[::step]]))
    return (
        geom.vertices[idx],
        shown.normals[0][idx],
        shown.mask[idx],
        shown.strength[idx],
    )


def _frame(points: np.ndarray, azim: float, elev: float) -> tuple[np.ndarray, np.ndarray]:
    """The view's screen axes (right, up, towards the viewer) as rows (3, 3), and the
    centre (3,) of the points' bounding box."""
    a, e = np.radians(azim), np.radians(elev)
    view = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])  # to viewer
    right = np.array([-np.sin(a), np.cos(a), 0.0])
    up = np.cross(view, right)
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0)) if len(points) else np.zeros(3)
    return np.stack([right, up, view]), centre


def _draw_curves(ax: Any, result: Any, points: np.ndarray, azim: float, elev: float) -> None:
    """The result's curves over a view (on top: the views are small), coloured by kind,
    with the corners as black dots and a legend of the kinds."""
    axes, centre = _frame(points, azim, elev)
    kinds: dict[str, int] = {}
    for c in result.curves:
        p = (np.vstack([c.points, c.points[:1]]) if c.closed else c.points) - centre
        colour = CURVE_COLOURS.get(c.kind, "k")
        ax.plot(p @ axes[0], p @ axes[1], color=colour, linewidth=1.6, solid_capstyle="round")
        kinds[c.kind] = kinds.get(c.kind, 0) + 1
    if result.corners is not None and len(result.corners):
        q = result.corners.points - centre
        ax.scatter(q @ axes[0], q @ axes[1], s=14, c="k", zorder=3, linewidths=0)
    if kinds:
        from matplotlib.lines import Line2D

        handles = [
            Line2D([], [], color=CURVE_COLOURS[k], linewidth=2, label=f"{n} {k}")
            for k, n in sorted(kinds.items())
        ]
        ax.legend(handles=handles, loc="lower left", fontsize=8, frameon=False)


def _render(
    ax: Any,
    points: np.ndarray,
    normals: np.ndarray,
    mask: np.ndarray,
    strength: np.ndarray,
    azim: float,
    elev: float,
    cmap: Any,
) -> None:
    """Orthographic view: points sorted back to front, shaded by |n . light|."""
    (right, up, view), centre = _frame(points, azim, elev)
    rel = points - centre
    x, y, depth = rel @ right, rel @ up, rel @ view
    light = view + 0.6 * up + 0.3 * right
    light /= np.linalg.norm(light)
    shade = 0.45 + 0.55 * np.abs(normals @ light)

    rgba = cmap(np.clip(strength, 0.0, 1.0))
    rgba[:, :3] *= np.where(mask, 1.0, shade)[:, None]
    order = np.lexsort((mask, depth))  # back to front; features last among equals
    ax.set_aspect("equal")
    ax.axis("off")
    if not len(points):
        ax.text(0.5, 0.5, "nothing to draw", ha="center", transform=ax.transAxes)
        return
    span = max(float(np.ptp(x)), float(np.ptp(y)), 1e-12)
    pad = 0.04 * span
    ax.set_xlim(x.min() - pad, x.max() + pad)
    ax.set_ylim(y.min() - pad, y.max() + pad)
    # marker diameter about 2 point spacings (so the surface hides what is behind it)
    fig = ax.figure
    bbox = ax.get_window_extent().transformed(fig.dpi_scale_trans.inverted())
    pts_per_unit = 72.0 * min(bbox.width, bbox.height) / (span + 2 * pad)
    spacing = _spacing(points)
    size = np.where(mask, 2.4, 1.9) * spacing * pts_per_unit
    size = np.clip(size, 0.6, 12.0) ** 2
    ax.scatter(x[order], y[order], s=size[order], c=rgba[order], marker="o", linewidths=0)
    ax.set_title(f"view azimuth {azim:g}°, elevation {elev:g}°", fontsize=10, color="0.35")


def _spacing(points: np.ndarray) -> float:
    """Median nearest-neighbour distance (on at most 20,000 points)."""
    if len(points) < 2:
        return 1.0
    sample = points[:: max(1, len(points) // 20000)]
    d, _ = cKDTree(points).query(sample, k=2)
    positive = d[:, 1][d[:, 1] > 0]
    return float(np.median(positive)) if len(positive) else 1.0


def _histogram(ax: Any, distances: np.ndarray, threshold: float, candidates: int) -> None:
    """256-bin histogram of v in [0, 1], candidates (v >= T) in red, T dashed."""
    v = distances[np.isfinite(distances)]
    counts, edges = np.histogram(v, bins=_BINS, range=(0.0, 1.0))
    centres = 0.5 * (edges[:-1] + edges[1:])
    above = centres >= threshold
    width = 1.0 / _BINS
    ax.bar(centres[~above], counts[~above], width=width, color="0.55", linewidth=0)
    ax.bar(centres[above], counts[above], width=width, color="#d7191c", linewidth=0)
    ax.axvline(threshold, color="k", linestyle="--", linewidth=1.2)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(0, max(int(counts.max()), 1) * 3)
    ax.tick_params(labelsize=8)
    ax.text(
        0.98,
        0.92,
        f"T = {threshold:.3f}\n{candidates:,} candidates",
        transform=ax.transAxes,
        ha="right",
        va="top",
        fontsize=9,
        bbox={"boxstyle": "round,pad=0.25", "fc": "white", "ec": "0.7", "alpha": 0.9},
    )
