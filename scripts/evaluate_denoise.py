#!/usr/bin/env python3
"""Measure ``--denoise`` against no denoising on parts with exact edges.

Per (condition, part): F1 of robust-mode detection without preprocessing and with
``denoise`` by each method (``auto`` and the others for the input's kind), scored with
``evaluation.score_part``, and what the step did (ran, skipped on a clean input, a
warning). Conditions: clean clouds, clouds with normal noise of 25 % and 50 % of the
spacing, clean isotropic meshes, CAD tessellations, and isotropic meshes with normal
noise of 10 % and 25 % of the spacing. Prints a Markdown table (docs/preprocessing.md).

    python3 scripts/evaluate_denoise.py                  # 6,000 points, 3 parts (minutes)
    python3 scripts/evaluate_denoise.py --parts box --points 3000
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from evaluation import groundtruth as gt  # noqa: E402
from evaluation.scoring import score_part  # noqa: E402
from meshlab_sharp import detect  # noqa: E402

#: Condition -> (evaluation condition, normal noise as a fraction of the spacing).
CONDITIONS = {
    "clean cloud": ("clean", 0.0),
    "cloud, noise 25 %": ("clean", 0.25),
    "cloud, noise 50 %": ("clean", 0.5),
    "clean mesh": ("mesh", 0.0),
    "CAD tessellation": ("cad", 0.0),
    "mesh, noise 10 %": ("mesh", 0.1),
    "mesh, noise 25 %": ("mesh", 0.25),
}
MESH_METHODS = ("auto", "two_steps")
CLOUD_METHODS = ("auto", "apss")


def part_under(name: str, condition: str, noise: float, n_points: int) -> gt.SamplePart:
    """The part under the evaluation condition, with normal noise added."""
    part = gt.make_condition(name, condition, n_points=n_points)
    return gt.add_noise(part, noise, seed=1) if noise else part


def measure(part: gt.SamplePart, method: str | None) -> tuple[float, str]:
    """F1 with the method (None: no preprocessing) and what the step did."""
    steps = None if method is None else {"denoise": True, "denoise_method": method}
    result = detect(part.vertices, part.faces, preprocessing=steps)
    note = ""
    if result.preprocessing is not None:
        step = result.preprocessing.steps[0]
        note = "skipped (clean)" if "skipped" in step else step.get("method", "")
        note += " (warning)" if "warning" in step and "skipped" not in step else ""
    return float(score_part(part, result.mask).f1), note


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="fandisk,box,drilled_plate")
    parser.add_argument("--points", type=int, default=6000)
    args = parser.parse_args()
    print("| input | part | no denoising | --denoise (auto) | meshes two_steps, clouds apss |")
    print("| --- | --- | --- | --- | --- |")
    means: dict[str, list[list[float]]] = {}
    for label, (condition, noise) in CONDITIONS.items():
        for name in args.parts.split(","):
            part = part_under(name, condition, noise, args.points)
            methods = MESH_METHODS if part.faces is not None else CLOUD_METHODS
            base, _ = measure(part, None)
            cells, row = [], [base]
            for method in methods:
                f1, note = measure(part, method)
                cells.append(f"{method}: {f1:.3f} ({f1 - base:+.3f}) {note}")
                row.append(f1)
            means.setdefault(label, []).append(row)
            print(f"| {label} | {name} | {base:.3f} | " + " | ".join(cells) + " |", flush=True)
    print("\nmean F1 per input (none, then each method):")
    for label, rows in means.items():
        print(f"  {label}: " + " / ".join(f"{v:.3f}" for v in np.mean(rows, axis=0)))


if __name__ == "__main__":
    main()
