#!/usr/bin/env python3
"""Robust mode's choices, each measured by changing one of them (docs/method.md).

Runs robust mode as chosen and with one constant changed at a time on the evaluation's
inputs (``scripts/evaluate.py``'s generators and cache), and prints one markdown row per
variant: mean F1 per condition (share of points flagged for the smooth controls). The
native library has its constants compiled in, so every variant runs the Python-driven
sequence with the numpy backend (``backend="numpy"``, the same bits as the library
where nothing is changed), its rules taken from the numpy reference's statement
(:mod:`meshlab_sharp.reference.robust`), with the constant set there too.

    python3 scripts/robust_variants.py --quick
    python3 scripts/robust_variants.py --quick --conditions clean,noise25 --variants chosen
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import _venv  # scripts/, the script's own folder, is on sys.path

_venv.enter()

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import evaluate  # noqa: E402

from evaluation import groundtruth as gt  # noqa: E402
from evaluation.scoring import score_part  # noqa: E402
from meshlab_sharp import creases, detect, robust  # noqa: E402
from meshlab_sharp.reference import detect as reference_sequence  # noqa: E402
from meshlab_sharp.reference import robust as reference  # noqa: E402

#: name -> ((module, constant, value), ...) changed from the chosen mode.
VARIANTS: dict[str, tuple[tuple[object, str, object], ...]] = {
    "chosen": (),
    "no sheet filter": ((robust, "SHEET_MIN", 10**9),),
    "sheet gap 0.25": ((robust, "SHEET_GAP", 0.25),),
    "sheet gap 0.35": ((robust, "SHEET_GAP", 0.35),),
    "sheet gap 0.4": ((robust, "SHEET_GAP", 0.4),),
    "sheet gap 0.5": ((robust, "SHEET_GAP", 0.5),),
    "sheet gap 0.7": ((robust, "SHEET_GAP", 0.7),),
    "sheet filter drops >= 1": ((robust, "SHEET_MIN", 1),),
    "sheet filter drops >= 12": ((robust, "SHEET_MIN", 12),),
    "sheet filter: kept >= dropped": ((robust, "SHEET_OWN", 1.0),),
    "sheet filter: kept >= dropped / 3": ((robust, "SHEET_OWN", 0.33),),
    "no column rule (sheet rule 2)": ((robust, "SHEET_COLUMN", 0.0),),
    "sheet column 1.2": ((robust, "SHEET_COLUMN", 1.2),),
    "sheet column gap 0.7": ((robust, "SHEET_COLUMN_GAP", 0.7),),
    "sheet far span 1.0": ((robust, "SHEET_FAR_SPAN", 1.0),),
    "sheet far span 1.5": ((robust, "SHEET_FAR_SPAN", 1.5),),
    "no far-span check": ((robust, "SHEET_FAR_SPAN", math.inf),),
    "no acute tips": ((robust, "ACUTE_SCORE", math.inf),),
    "acute tips from score 0.45": ((robust, "ACUTE_SCORE", 0.45),),
    "acute tips: no score cap": ((robust, "ACUTE_SCORE_MAX", math.inf),),
    "no second sheet pass (trim)": ((robust, "SHEET_TRIM", 0.0),),
    "sheet pass 2 without turn limit": ((robust, "SHEET_TRIM_COS", 0.0),),
    "no support": ((robust, "SUPPORT_MIN", 0),),
    "support >= 1": ((robust, "SUPPORT_MIN", 1),),
    "support >= 3": ((robust, "SUPPORT_MIN", 3),),
    "support for every candidate (no free score)": ((robust, "SUPPORT_FREE_SCORE", 0.0),),
    "support free below score 0.3": ((robust, "SUPPORT_FREE_SCORE", 0.3),),
    "thinning compares 16 nearest": ((robust, "THIN_KNN", 16),),
    "thinning compares 8 nearest": ((robust, "THIN_KNN", 8),),
    "thinning list not grown with the scales": ((reference, "thin_knn", lambda growth: 12),),
    "thinning cone 45 deg": ((robust, "THIN_CONE_COS", math.cos(math.radians(45))),),
    "noisy clouds: thinning cone 60 deg (as quiet ones)": ((robust, "THIN_CONE_COS_NOISY", 0.5),),
    "noisy clouds: thinning cone 66 deg (cos 0.4)": ((robust, "THIN_CONE_COS_NOISY", 0.4),),
    "no sharp mesh edges": ((creases, "CREASE_ANGLE", 180.0),),
    "mesh edges: no noise factor": ((creases, "NOISE_FACTOR", 0.0),),
    "Otsu on clouds without noise too": ((reference, "otsu_splits", lambda mesh, noise: True),),
    "floor alone up to noise 0.15 (the scales' growth)": ((robust, "NOISE_QUIET", 0.15),),
    "no threshold floor (Otsu alone)": (
        (robust, "R_MIN", 0.0),
        (reference, "otsu_splits", lambda mesh, noise: True),
    ),
    "noise-scaled scales off": ((robust, "NOISE_TOLERATED", math.inf),),
    "noise tolerated 0.2": ((robust, "NOISE_TOLERATED", 0.2),),
    "noise tolerated 0.1": ((robust, "NOISE_TOLERATED", 0.1),),
    "noise plane of the smallest scale": ((robust, "NOISE_KNN", 12),),
    "noise growth at most x2": ((robust, "NOISE_MAX_FACTOR", 2.0),),
}


def run_variant(name: str, pairs: list[tuple[str, str]], n: int, cache: Path) -> dict[str, float]:
    """Mean F1 (or flagged share, in %) per condition with one variant."""
    changes: list[tuple[object, str, object]] = [(reference_sequence, "RULES", reference)]
    for m, a, v in VARIANTS[name]:
        changes.append((m, a, v))
        if m is robust and hasattr(reference, a):  # the rules' own copy
            changes.append((reference, a, v))
    saved = [(m, a, getattr(m, a)) for m, a, _ in changes]
    for m, a, v in changes:
        setattr(m, a, v)
    try:
        per: dict[str, list[float]] = {}
        for part_name, condition in pairs:
            part, _ = evaluate.generate(part_name, condition, n, 0, cache)
            found = detect(part.vertices, part.faces, mode="robust", backend="numpy")
            s = score_part(part, found.mask)
            if len(part.edges):
                per.setdefault(condition, []).append(s.f1)
            else:
                per.setdefault(f"{condition} flagged %", []).append(100 * s.fp_rate)
        return {c: float(np.mean(v)) for c, v in per.items()}
    finally:
        for m, a, v in reversed(saved):
            setattr(m, a, v)


def main(argv: list[str] | None = None) -> int:
    """Command line."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="6,000 points, quick parts")
    ap.add_argument("--conditions", help="comma-separated conditions (default: all)")
    ap.add_argument("--variants", help="comma-separated variant names (default: all)")
    args = ap.parse_args(argv)
    n = 6000 if args.quick else 20000
    pairs = gt.suite(
        quick=args.quick,
        conditions=args.conditions.split(",") if args.conditions else None,
    )
    cache = ROOT / "build" / "evaluation-cache" / evaluate._generator_hash()
    names = args.variants.split(",") if args.variants else list(VARIANTS)
    header = False
    for name in names:
        means = run_variant(name, pairs, n, cache)
        if not header:
            print("| variant | " + " | ".join(means) + " |")
            print("|---|" + "---|" * len(means))
            header = True
        cells = [f"{v:.2f}" if c.endswith("%") else f"{v:.3f}" for c, v in means.items()]
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
