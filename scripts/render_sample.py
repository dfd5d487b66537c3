"""Render the built-in sample part: points shaded by normal, truth sharp edges in red.

Usage: python scripts/render_sample.py [OUT.png]   (default docs/sample-part.png)
Needs matplotlib (a plotting dependency only: pip install matplotlib).
"""

from __future__ import annotations

import sys
from pathlib import Path

import _venv  # scripts/, the script's own folder, is on sys.path

_venv.enter()

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Line3DCollection  # noqa: E402

from meshlab_sharp.sample import sample_part  # noqa: E402


def render(out: Path, n_points: int = 50_000) -> None:
    """Draw the sample part from two viewpoints into ``out``."""
    part = sample_part("points", n_points=n_points)
    p, nrm = part.vertices, part.normals
    light = np.array([0.4, -0.5, 0.75])
    light /= np.linalg.norm(light)
    shade = 0.35 + 0.65 * np.abs(nrm @ light)
    fig = plt.figure(figsize=(14, 6.5), dpi=110)
    for k, (elev, azim) in enumerate([(32, -58), (38, 125)]):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        ax.scatter(
            p[:, 0],
            p[:, 1],
            p[:, 2],
            c=shade,
            cmap="Blues_r",
            vmin=0,
            vmax=1.4,
            s=0.4,
            linewidths=0,
            depthshade=False,
        )
        ax.add_collection3d(Line3DCollection(part.edges, colors="red", linewidths=1.2))
        ax.set_box_aspect(np.ptp(p, axis=0))
        ax.view_init(elev=elev, azim=azim)
        ax.set_axis_off()
    fig.suptitle(
        f"meshlab-sharp sample part ({part.n:,} points, spacing {part.spacing:.2f} mm): "
        f"truth sharp edges in red ({part.edge_length:.0f} mm)"
    )
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    print(f"wrote {out}")


if __name__ == "__main__":
    if len(sys.argv) > 2 or (len(sys.argv) == 2 and sys.argv[1].startswith("-")):
        sys.exit(__doc__)
    render(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/sample-part.png"))
