#!/usr/bin/env python3
"""Measure the preprocessing steps' effect: ``--denoise`` against no denoising on parts
with exact edges, and (``--holes``) hole filling with and without refining the patch.

Per (condition, part): F1 of robust-mode detection without preprocessing and with
``denoise`` by each method (``auto`` and the others for the input's kind), scored with
``evaluation.score_part``, and what the step did (ran, skipped on a clean input, a
warning). Conditions: clean clouds, clouds with normal noise of 25 % and 50 % of the
spacing, clean isotropic meshes, CAD tessellations, and isotropic meshes with normal
noise of 10 % and 25 % of the spacing. Prints a Markdown table (docs/preprocessing.md).

    python3 scripts/evaluate_preprocessing.py            # 6,000 points, 3 parts (minutes)
    python3 scripts/evaluate_preprocessing.py --parts box --points 3000
    python3 scripts/evaluate_preprocessing.py --holes    # the sample mesh with two holes
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import _venv  # scripts/, the script's own folder, is on sys.path

_venv.enter()

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from evaluation import groundtruth as gt  # noqa: E402
from evaluation.scoring import score_part  # noqa: E402
from meshlab_sharp import detect  # noqa: E402
from meshlab_sharp.sample import sample_part  # noqa: E402

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


def holes() -> None:
    """The sample part as an 11,000-vertex mesh with two holes in its top (the faces
    within 4 units of two top faces drawn with seed 0), filled with and without
    refinement: the step's seconds, vertices added and the features."""
    part = sample_part("mesh", n_points=11000)
    v, f = part.vertices, part.faces
    centres = v[f].mean(axis=1)
    top = np.flatnonzero(np.abs(centres[:, 2] - centres[:, 2].max()) < 1e-6)
    hole = np.zeros(len(f), bool)
    for k in np.random.default_rng(0).choice(top, 2, replace=False):
        hole |= np.linalg.norm(centres - centres[k], axis=1) < 4.0
    kept = f[~hole]
    print(f"{len(v)} vertices, {hole.sum()} faces removed")
    print(f"no filling: {detect(v, kept).n_features} features")
    for refine in (True, False):
        t = time.perf_counter()
        result = detect(v, kept, preprocessing={"fill_holes": True, "refine_holes": refine})
        step = result.preprocessing.steps[0]
        print(
            f"refine_holes={refine}: step {step['seconds']:.2f} s, {step['added']} vertices "
            f"added, {step['boundary_edges_after']} boundary edges left, "
            f"{result.n_features} features, {time.perf_counter() - t:.2f} s in all"
        )


def main() -> None:
    """Print the table (or, with ``--holes``, the hole-filling figures)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="fandisk,box,drilled_plate")
    parser.add_argument("--points", type=int, default=6000)
    parser.add_argument("--holes", action="store_true", help="measure hole filling instead")
    args = parser.parse_args()
    if args.holes:
        holes()
        return
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
