#!/usr/bin/env python3
"""Evaluate the feature curves on generated parts with known sharp edges.

For every sharp part (``groundtruth.part_names(smooth=False)``) as a clean cloud, a
noisy cloud (normal noise of 25 % of the spacing), an iid cloud (as many points drawn
independently, ``groundtruth.iid_part``) and an isotropic mesh, runs
``detect(..., curves=True)`` in both modes and scores the curves with
:func:`evaluation.scoring.evaluate_curves` (precision, coverage, RMS distance in
spacings, curve count / exact curve count, corners found), and the time of the curves
over the time of detection. Writes ``docs/curves.md`` and ``docs/curves.json``.

    python3 scripts/evaluate_curves.py                 # 20,000 points per part
    python3 scripts/evaluate_curves.py --quick         # 6,000 points
    python3 scripts/evaluate_curves.py --timing 1000000 --timing-only   # extra time, 1M points
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path

import _venv  # scripts/, the script's own folder, is on sys.path

_venv.enter()

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from evaluation import groundtruth as gt  # noqa: E402
from evaluation.scoring import evaluate_curves  # noqa: E402
from meshlab_sharp import detect  # noqa: E402
from meshlab_sharp.curves import extract_curves  # noqa: E402

MODES = ("robust", "paper")
CONDITIONS = ("clean", "noise25", "iid", "mesh")
MEASURES = ("precision", "coverage", "rms", "count_ratio", "corners_found")
TARGETS = {
    "precision": (">= 0.95", lambda v: v >= 0.95),
    "coverage": (">= 0.90", lambda v: v >= 0.90),
    "rms": ("<= 0.35 spacing (clean clouds)", lambda v: v <= 0.35),
    "count_ratio": ("0.8 to 1.25", lambda v: 0.8 <= v <= 1.25),
    "corners_found": (">= 0.9", lambda v: v >= 0.9),
    "extra_time": ("<= 25 % on 1M points", lambda v: v <= 0.25),
}


def part_under(name: str, condition: str, n_points: int, seed: int) -> gt.SamplePart:
    """The part as a clean cloud, a noisy cloud, an iid cloud or a mesh."""
    if condition == "mesh":
        return gt.make_part(name, "mesh", n_points=max(n_points // 2, 200))
    part = gt.make_part(name, n_points=n_points, seed=seed)
    if condition == "iid":
        return gt.iid_part(part, seed=seed + 2)
    if condition == "noise25":
        part = gt.add_noise(part, 0.25, seed=seed + 1)
    return part


def score(part: gt.SamplePart, mode: str) -> dict:
    """Detect with curves and score them."""
    result = detect(part.vertices, part.faces, mode=mode, curves=True)
    assert result.curves is not None and result.corners is not None
    s = evaluate_curves(result.curves, result.corners.points, part.edges, part.spacing).as_dict()
    curves = result.timings["curves"]
    s["detect_s"] = result.timings["total"] - curves
    s["curves_s"] = curves
    s["kinds"] = {k: [c.kind for c in result.curves].count(k) for k in ("line", "arc", "freeform")}
    return s


def summarise(rows: list[dict]) -> dict:
    """Per condition and mode: mean of each measure over the parts (corners pooled)."""
    out: dict = {}
    for c in CONDITIONS:
        out[c] = {}
        for m in MODES:
            sel = [r[m] for r in rows if r["condition"] == c]
            if not sel:
                continue
            means = {k: float(np.nanmean([s[k] for s in sel])) for k in MEASURES}
            found = sum(
                s["corners_found"] * s["n_truth_corners"] for s in sel if s["n_truth_corners"]
            )
            total = sum(s["n_truth_corners"] for s in sel)
            means["corners_found"] = found / total if total else math.nan
            means["count_ratio_min"] = float(min(s["count_ratio"] for s in sel))
            means["count_ratio_max"] = float(max(s["count_ratio"] for s in sel))
            means["time_share"] = float(
                sum(s["curves_s"] for s in sel) / sum(s["detect_s"] for s in sel)
            )
            out[c][m] = means
    return out


def timing(n: int, repeat: int = 1) -> dict:
    """Extra time of the curves over detection on the benchmark's n-point CAD cloud (best
    of ``repeat``), robust and paper modes: wall-clock and CPU time (the latter less
    sensitive to a busy machine; detection runs on every core, the curves' neighbour
    queries, neighbourhood and refinement too, their other steps on one)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    from bench import cad_cloud

    points = cad_cloud(n)
    out = {"n": n}
    for mode in MODES:
        best_d, best_c, cpu_d, cpu_c = math.inf, math.inf, math.inf, math.inf
        for _ in range(repeat):
            t0 = time.process_time()
            r = detect(points, mode=mode)
            t1 = time.process_time()
            assert r.curves is None
            t = time.perf_counter()
            curves, _ = extract_curves(points, r.mask, None, r.kept)
            best_c = min(best_c, time.perf_counter() - t)
            cpu_c = min(cpu_c, time.process_time() - t1)
            cpu_d = min(cpu_d, t1 - t0)
            best_d = min(best_d, r.timings["total"])
        out[mode] = {
            "detect_s": best_d,
            "curves_s": best_c,
            "extra": best_c / best_d,
            "detect_cpu_s": cpu_d,
            "curves_cpu_s": cpu_c,
            "extra_cpu": cpu_c / cpu_d,
            "n_features": int(r.n_features),
            "n_curves": len(curves),
        }
        print(
            f"timing {mode}: {n} points, detect {best_d:.2f} s, curves {best_c:.2f} s "
            f"(+{100 * best_c / best_d:.1f} %; CPU time +{100 * cpu_c / cpu_d:.1f} %), "
            f"{r.n_features} features, "
            f"{len(curves)} curves",
            flush=True,
        )
    return out


def _f(x: float, digits: int = 3) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


#: Where the generated part of the page starts: the guide above it is kept.
EVALUATION_HEADING = "## Evaluation"


def write_page(path: Path, generated: str) -> None:
    """Replace the evaluation section of the page at ``path`` (everything from
    :data:`EVALUATION_HEADING` on) by ``generated``, keeping the guide above it."""
    old = path.read_text() if path.exists() else ""
    guide = old.split("\n" + EVALUATION_HEADING + "\n", 1)[0].rstrip("\n")
    path.write_text((guide + "\n\n" if guide else "") + generated)


def markdown(rows: list[dict], summary: dict, meta: dict, time_rows: dict | None) -> str:
    """docs/curves.md."""
    lines = [
        EVALUATION_HEADING,
        "",
        "`python3 scripts/evaluate_curves.py` "
        f"({meta['n_points']:,} points per cloud, about half as many mesh vertices; seed "
        f"{meta['seed']}; {meta['machine']}). Every sharp part of the evaluation "
        "([evaluation](evaluation.md)) as a clean cloud, a cloud with normal noise of 25 % "
        "of the spacing, an iid cloud (as many points drawn independently, uniform over the "
        "area, as MeshLab's sample points on mesh does; scored at the clean cloud's spacing) "
        "and an isotropic mesh; `detect(..., curves=True)` in robust and paper mode; scores:",
        "",
        "- **precision**: share of the curves' length within 1 spacing of an exact edge;",
        "- **coverage**: share of the exact edges' length within 1.5 spacings of a curve;",
        "- **RMS**: RMS distance of the curve vertices to the exact edges, in spacings;",
        "- **count**: number of curves / number of exact edges between corners (chains of "
        "exact segments cut where three or more meet or they turn by more than 45 degrees);",
        "- **corners**: share of the exact corners with a found corner within 2 spacings "
        "(pooled over the parts);",
        "- **time**: curve extraction time / detection time (these small inputs; the 1M-point "
        "figure is below).",
        "",
        f"### Means over the {len({r['part'] for r in rows})} parts",
        "",
        "| condition | mode | precision | coverage | RMS (spacings) | count (min-max) "
        "| corners | time |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for c in CONDITIONS:
        for m in MODES:
            s = summary.get(c, {}).get(m)
            if s is None:
                continue
            lines.append(
                f"| {c} | {m} | {_f(s['precision'])} | {_f(s['coverage'])} | {_f(s['rms'], 2)} "
                f"| {_f(s['count_ratio'], 2)} ({_f(s['count_ratio_min'], 2)}-"
                f"{_f(s['count_ratio_max'], 2)}) | {_f(s['corners_found'])} "
                f"| {100 * s['time_share']:.0f} % |"
            )
    lines += ["", "Against the targets (the default, robust mode):", ""]
    lines += ["| measure | target | condition | robust | met |", "|---|---|---|---:|---|"]
    for k in MEASURES:
        label, ok = TARGETS[k]
        conds = ("clean",) if k == "rms" else CONDITIONS
        for c in conds:
            v = summary.get(c, {}).get("robust", {}).get(k)
            if v is None:
                continue
            lines.append(f"| {k} | {label} | {c} | {_f(v)} | {'yes' if ok(v) else 'no'} |")
    if time_rows:
        for m in MODES:
            t = time_rows[m]
            label, ok = TARGETS["extra_time"]
            lines.append(
                f"| extra time | {label} | {time_rows['n']:,}-point CAD cloud "
                f"(`scripts/bench.py`), {m} | wall {100 * t['extra']:.1f} % "
                f"({t['curves_s']:.2f} s over {t['detect_s']:.2f} s), CPU "
                f"{100 * t['extra_cpu']:.1f} % ({t['curves_cpu_s']:.2f} s over "
                f"{t['detect_cpu_s']:.2f} s) | {'yes' if ok(t['extra']) else 'no'} |"
            )
    lines += ["", "### Per part", ""]
    lines += [
        "| part | condition | mode | precision | coverage | RMS | curves / exact "
        "| corners found / exact | kinds (line/arc/free) |",
        "|---|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        for m in MODES:
            s = r[m]
            k = s["kinds"]
            corners = (
                f"{round(s['corners_found'] * s['n_truth_corners'])} / {s['n_truth_corners']}"
                if s["n_truth_corners"]
                else f"- / 0 ({s['n_corners']} found)"
            )
            lines.append(
                f"| {r['part']} | {r['condition']} | {m} | {_f(s['precision'])} | "
                f"{_f(s['coverage'])} | {_f(s['rms'], 2)} | {s['n_curves']} / "
                f"{s['n_truth_curves']} | {corners} | {k['line']}/{k['arc']}/{k['freeform']} |"
            )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="6,000 points per part")
    parser.add_argument("--points", type=int, default=None, help="points per cloud")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timing", type=int, default=0, help="also time N-point clouds")
    parser.add_argument("--timing-only", action="store_true", help="only the timing")
    parser.add_argument(
        "--add-timing",
        type=int,
        default=0,
        metavar="N",
        help="time N-point clouds (best of 3) and add the figures to the existing docs/curves.*",
    )
    parser.add_argument("--out", default=str(ROOT / "docs" / "curves"), help="output stem")
    args = parser.parse_args(argv)
    n_points = args.points or (6000 if args.quick else 20000)
    out = Path(args.out)
    if args.add_timing:
        done = json.loads(out.with_suffix(".json").read_text())
        done["timing"] = timing(args.add_timing, repeat=3)
        write_page(
            out.with_suffix(".md"),
            markdown(done["rows"], done["summary"], done["meta"], done["timing"]),
        )
        out.with_suffix(".json").write_text(json.dumps(done, indent=1) + "\n")
        return 0
    time_rows = timing(args.timing) if args.timing else None
    if args.timing_only:
        print(json.dumps(time_rows, indent=2))
        return 0
    rows = []
    for name in gt.part_names(smooth=False):
        for condition in CONDITIONS:
            part = part_under(name, condition, n_points, args.seed)
            row = {"part": name, "condition": condition, "n": part.n}
            for mode in MODES:
                row[mode] = score(part, mode)
            rows.append(row)
            print(
                f"{name:14s} {condition:8s} n={part.n:6d}  "
                + "  ".join(
                    f"{m}: P {s['precision']:.3f} C {s['coverage']:.3f} rms {s['rms']:.2f} "
                    f"n {s['n_curves']}/{s['n_truth_curves']} corners {_f(s['corners_found'], 2)}"
                    for m, s in ((m, row[m]) for m in MODES)
                ),
                flush=True,
            )
    summary = summarise(rows)
    meta = {
        "n_points": n_points,
        "seed": args.seed,
        "machine": f"{platform.machine()}, Python {platform.python_version()}",
    }
    write_page(out.with_suffix(".md"), markdown(rows, summary, meta, time_rows))
    out.with_suffix(".json").write_text(
        json.dumps({"meta": meta, "summary": summary, "rows": rows, "timing": time_rows}, indent=1)
        + "\n"
    )
    print(f"wrote {out.with_suffix('.md')} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
