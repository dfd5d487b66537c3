#!/usr/bin/env python3
"""Evaluate detection modes on generated parts with known sharp edges.

Every (part, condition) pair of ``groundtruth.suite()`` is generated with
``groundtruth.make_condition`` (clean clouds, noise, outliers, a density gradient,
isotropic meshes, CAD tessellations (the CSG kernel's own, a coarse one, OpenSCAD
exports), thin walls 1 to 3 spacings thick, acute edges, a simulated scan, smooth
controls), detected with each mode and scored with ``evaluation.score_part``
(precision, edge coverage, F1, thickness; per vertex on CAD tessellations; the share
of points flagged on smooth controls). Prints every row, then per-condition means per
mode and the targets; writes ``docs/evaluation.md`` and ``docs/evaluation.json``
unless ``--no-write``.

    python3 scripts/evaluate.py                          # 20,000 points, all (minutes)
    python3 scripts/evaluate.py --quick --no-write       # 6,000 points, fewer parts
    python3 scripts/evaluate.py --quick --modes robust --conditions thin1,cad --no-write

Generated inputs are cached in ``build/evaluation-cache/`` (keyed by the generators'
source), so a second run only detects.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
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
from evaluation.scoring import score_part  # noqa: E402
from meshlab_sharp import detect  # noqa: E402
from meshlab_sharp.io import atomic_write  # noqa: E402

SCORE_KEYS = ("precision", "coverage", "f1", "thickness", "fp_rate")

# (label, conditions, statistic, bound): statistic "f1" (mean F1 >= bound), "fp" (max
# share flagged on smooth parts <= bound)
TARGETS = (
    ("clean clouds", ("clean",), "f1", 0.97),
    ("CAD tessellations", ("cad", "cad_coarse", "openscad"), "f1", 0.97),
    ("CAD: no part below", ("cad", "cad_coarse", "openscad"), "min_f1", 0.90),
    (
        "thin walls",
        ("thin1", "thin2", "thin3", "thin1_mesh", "thin2_mesh", "thin3_mesh"),
        "f1",
        0.92,
    ),
    ("noise 25 %", ("noise25",), "f1", 0.90),
    ("noise 50 %", ("noise50",), "f1", 0.75),
    ("1 % outliers", ("outliers1",), "f1", 0.95),
    ("density gradient", ("density4",), "f1", 0.95),
    ("acute edges", ("acute", "acute_mesh"), "f1", 0.93),
    ("smooth controls (max flagged)", ("smooth", "smooth_mesh", "scan", "cad"), "fp", 0.005),
)


# ----------------------------------------------------------------------------------
# Generated inputs, cached on disk
# ----------------------------------------------------------------------------------


def _generator_hash() -> str:
    """Hash of everything that decides the generated inputs."""
    h = hashlib.sha256()
    tools = ROOT / "evaluation"
    files = [ROOT / "meshlab_sharp" / "parts.py"]
    files += [tools / n for n in ("parts.py", "groundtruth.py", "scan.py", "scoring.py")]
    files += sorted(gt.OPENSCAD_DIR.glob("*.stl"))
    for f in files:
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _save(path: Path, part: gt.SamplePart) -> None:
    arrays = {
        "vertices": part.vertices,
        "edges": part.edges,
        "normals": part.normals,
        "outliers": part.outliers,
    }
    if part.faces is not None:
        arrays["faces"] = part.faces
    for key in ("local_spacing", "visible_edges"):
        if key in part.extra:
            arrays[key] = part.extra[key]
    meta = {
        "name": part.name,
        "kind": part.kind,
        "seed": part.seed,
        "spacing": part.spacing,
        "scoring": part.extra.get("scoring"),
        "wall": part.extra.get("wall"),
    }
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, meta=json.dumps(meta), **arrays)
    tmp.replace(path)


def _load(path: Path) -> gt.SamplePart:
    with np.load(path) as z:
        meta = json.loads(str(z["meta"]))
        extra = {k: z[k] for k in ("local_spacing", "visible_edges") if k in z}
        extra |= {k: meta[k] for k in ("scoring", "wall") if meta[k] is not None}
        return gt.SamplePart(
            name=meta["name"],
            vertices=z["vertices"],
            faces=z.get("faces"),
            edges=z["edges"],
            spacing=meta["spacing"],
            normals=z["normals"],
            outliers=z["outliers"],
            kind=meta["kind"],
            seed=meta["seed"],
            extra=extra,
        )


def generate(
    part: str, condition: str, n_points: int, seed: int, cache: Path | None
) -> tuple[gt.SamplePart, float]:
    """The part under the condition, and the seconds it took (0 when cached)."""
    path = None
    if cache is not None:
        path = cache / f"{part}-{condition}-{n_points}-{seed}.npz"
        if path.exists():
            return _load(path), 0.0
    t = time.perf_counter()
    sample = gt.make_condition(part, condition, n_points=n_points, seed=seed)
    seconds = time.perf_counter() - t
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        _save(path, sample)
    return sample, seconds


# ----------------------------------------------------------------------------------
# Running and summarising
# ----------------------------------------------------------------------------------


def score(part: gt.SamplePart, mode: str) -> dict:
    """Detect with one mode and score against the part's truth."""
    t = time.perf_counter()
    result = detect(part.vertices, part.faces, mode=mode)
    seconds = time.perf_counter() - t
    s = score_part(part, result.mask).as_dict()
    s["seconds"] = seconds
    return s


def _fmt(s: dict) -> str:
    if math.isnan(s["f1"]):
        return f"flagged {100 * s['fp_rate']:.2f}%  {s['seconds']:.2f}s"
    return (
        f"F1 {s['f1']:.3f} P {s['precision']:.3f} C {s['coverage']:.3f} "
        f"th {s['thickness']:.2f}  {s['seconds']:.2f}s"
    )


def run(
    pairs: list[tuple[str, str]], modes: list[str], n_points: int, seed: int, cache: Path | None
) -> list[dict]:
    """One row per (part, condition): part, condition, n, kind, generation seconds and
    one score dict per mode."""
    rows = []
    for name, condition in pairs:
        part, gen_s = generate(name, condition, n_points, seed, cache)
        row = {
            "part": name,
            "condition": condition,
            "n": part.n,
            "kind": part.kind,
            "scoring": part.extra.get("scoring", "distance"),
            "sharp": bool(len(part.edges)),
            "generate_seconds": gen_s,
        }
        for mode in modes:
            row[mode] = score(part, mode)
        rows.append(row)
        print(
            f"{condition:12s} {name:18s} n={part.n:6d}  "
            + "  |  ".join(f"{m}: {_fmt(row[m])}" for m in modes),
            flush=True,
        )
    return rows


def _mean(values: list[float]) -> float:
    vals = [v for v in values if not math.isnan(v)]
    return float(np.mean(vals)) if vals else math.nan


def summarise(rows: list[dict], modes: list[str]) -> dict:
    """Per condition and mode: means of the scores over the sharp parts, min F1, max
    share flagged on smooth parts, seconds; and the generation seconds."""
    out = {}
    for c in dict.fromkeys(r["condition"] for r in rows):
        sel = [r for r in rows if r["condition"] == c]
        sharp = [r for r in sel if r["sharp"]]
        smooth = [r for r in sel if not r["sharp"]]
        entry: dict = {
            "parts": len(sel),
            "points": int(np.mean([r["n"] for r in sel])),
            "generate_seconds": float(sum(r["generate_seconds"] for r in sel)),
        }
        for m in modes:
            e = {k: _mean([r[m][k] for r in sharp]) for k in SCORE_KEYS}
            e["min_f1"] = min((r[m]["f1"] for r in sharp), default=math.nan)
            e["smooth_flagged_max"] = max((r[m]["fp_rate"] for r in smooth), default=math.nan)
            e["seconds"] = float(sum(r[m]["seconds"] for r in sel))
            entry[m] = e
        out[c] = entry
    return out


def targets(rows: list[dict], summary: dict, modes: list[str]) -> list[dict]:
    """The targets, per mode, over the conditions that were run; thickness: the
    range of the per-condition mean thickness."""
    res = []
    for label, conds, stat, bound in TARGETS:
        sel = [r for r in rows if r["condition"] in conds]
        sharp = [r for r in sel if r["sharp"]]
        smooth = [r for r in sel if not r["sharp"]]
        if (stat == "fp" and not smooth) or (stat != "fp" and not sharp):
            continue
        t = {
            "target": label,
            "conditions": [c for c in conds if any(r["condition"] == c for r in sel)],
        }
        for m in modes:
            if stat == "fp":
                v = max(r[m]["fp_rate"] for r in smooth)
                t[m] = {"value": v, "met": v <= bound}
            elif stat == "min_f1":
                worst = min(sharp, key=lambda r, m=m: r[m]["f1"])
                v = worst[m]["f1"]
                t[m] = {"value": v, "met": v >= bound, "part": worst["part"]}
            else:
                v = _mean([r[m]["f1"] for r in sharp])
                t[m] = {"value": v, "met": v >= bound}
        t["required"] = f"<= {100 * bound:.1f} %" if stat == "fp" else f">= {bound:.2f}"
        res.append(t)
    entry = {"target": "thickness", "conditions": [], "required": "0.8 to 1.3"}
    for m in modes:
        vals = [
            (s[m]["thickness"], c) for c, s in summary.items() if not math.isnan(s[m]["thickness"])
        ]
        if vals:
            (lo, c_lo), (hi, c_hi) = min(vals), max(vals)
            entry[m] = {"value": [lo, hi], "met": lo >= 0.8 and hi <= 1.3}
            entry[m]["part"] = f"min on {c_lo}, max on {c_hi}"
    if all(m in entry for m in modes):
        entry["conditions"] = [
            c for c, s in summary.items() if not math.isnan(s[modes[0]]["thickness"])
        ]
        res.append(entry)
    return res


def no_worse_than_paper(summary: dict, modes: list[str], slack: float = 0.01) -> dict:
    """Per non-paper mode: the conditions whose mean F1 is below paper's by more than
    ``slack`` (or whose smooth share flagged is above paper's by more than 0.5 %)."""
    out = {}
    for m in modes:
        if m == "paper" or "paper" not in modes:
            continue
        worse = []
        for c, s in summary.items():
            if not math.isnan(s[m]["f1"]) and s[m]["f1"] < s["paper"]["f1"] - slack:
                worse.append(c)
            fm, fp = s[m]["smooth_flagged_max"], s["paper"]["smooth_flagged_max"]
            if not math.isnan(fm) and fm > fp + 0.005:
                worse.append(f"{c} (smooth)")
        out[m] = worse
    return out


def _f(x: float | None, digits: int = 3) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def print_summary(summary: dict, checks: list[dict], worse: dict, modes: list[str]) -> None:
    """Per-condition means per mode, then the targets."""
    head = f"{'condition':12s} {'parts':>5s} {'n':>6s} {'gen s':>6s}"
    for m in modes:
        head += f" | {m:>8s} F1   min    P     C   thick flagged  sec"
    print("\n" + head)
    for c, s in summary.items():
        line = f"{c:12s} {s['parts']:5d} {s['points']:6d} {s['generate_seconds']:6.1f}"
        for m in modes:
            e = s[m]
            fl = e["smooth_flagged_max"]
            line += (
                f" | {_f(e['f1']):>11s} {_f(e['min_f1']):>5s} {_f(e['precision']):>5s} "
                f"{_f(e['coverage']):>5s} {_f(e['thickness'], 2):>5s} "
                f"{'-' if math.isnan(fl) else f'{100 * fl:.2f}%':>7s} {e['seconds']:5.1f}"
            )
        print(line)
    print()
    for t in checks:
        print(
            f"target {t['target']} ({t['required']}): "
            + "; ".join(
                f"{m} {_target_value(t[m])} {'met' if t[m]['met'] else 'NOT met'}" for m in modes
            )
        )
    for m, w in worse.items():
        print(f"{m} worse than paper by > 0.01 F1 on: {', '.join(w) or 'none'}")


def _target_value(v: dict) -> str:
    x = v["value"]
    s = f"{x[0]:.2f}..{x[1]:.2f}" if isinstance(x, list) else f"{x:.3f}"
    return s + (f" ({v['part']})" if "part" in v else "")


METHOD = """## How the inputs are made and scored

**Parts** (`evaluation/parts.py`; conditions: `evaluation/groundtruth.py`): closed
triangle meshes of exact solids, built from numpy primitives and pymeshlab's exact mesh
booleans; round surfaces have 128 segments per turn (facets turn by 2.8 degrees). The
**truth** is every edge of that mesh whose faces turn by more than 20 degrees, as
straight segments.

**Conditions** (`groundtruth.CONDITIONS`, generated by `groundtruth.make_condition`):

- *clean, noise, outliers, density, mesh*: Poisson-disk clouds of exactly n points
  (normal noise of 10/25/50 % of the spacing; 1 % far outliers; one half of the part 4x
  denser, scored with each side's spacing), or pymeshlab's isotropic remesh with n/2
  vertices (spacing = mean edge length).
- *cad*: the CSG kernel's own triangulation of each part, not remeshed: long thin
  triangles, vertices only where faces meet (and at the centre of fanned caps).
  *cad_coarse*: the parts with round surfaces rebuilt with 24 segments per turn
  (facets turn by 15 degrees, still below the crease angle; the truth is recomputed
  from the coarse solid). *openscad*: five models (`evaluation/data/openscad/*.scad`:
  a bracket with a gusset and bolt holes, a plate with a pocket, chamfers and
  counterbores, a flanged pipe, a grooved knob, a turned handle whose fillet, shaft
  and dome are smooth) exported to STL by OpenSCAD 2021.01 and welded (identical
  vertices merged, as MeshLab does on load). Their round surfaces have `$fn` 24 to 48
  (facets turn by 15 degrees or less) and every designed edge turns by 45 degrees or
  more; the tests check that no edge turns by between 16 and 40 degrees, so the edges
  over 20 degrees are exactly the designed ones. On the prismatic parts every vertex
  lies on an edge (a detector that flags every vertex scores 1 there); the handle and
  the smooth controls' tessellations in *cad* (sphere, torus, rounded box: share of
  vertices flagged) are the checks against that.
  **Scored per vertex**: a vertex is a true feature when it lies on an exact edge;
  precision = true features detected / detected, coverage = recall. (With vertices far
  apart along the edges and nearly all of them on edges, a spacing-based score means
  nothing.)
- *thin1/2/3* (clouds) and *thin1/2/3_mesh*: a sheet-metal angle bracket (sharp 90
  degree bend, holes), an open ribbed housing (walls, floor and three ribs), a rotor
  (hub and six 30-degree pitched blades) and a tube, with every wall t = 1, 2 or 3
  spacings thick. The part is built for the sampling: the wall is
  `t * expected_spacing(A, n)`, where the spacing of n Poisson-disk points on area A
  is `0.78 sqrt(A / n)` (measured) and a mesh's is the remesher's target edge
  `sqrt(2 A / (sqrt(3) n))`; A depends on the wall, A(w) is fitted linearly through
  the parts built with w = 1 and 3 and the equation solved exactly
  (`groundtruth.thin_wall`). Measured at 6,000 points: walls of t spacings within 2 %
  (clouds) and 3 % (meshes).
- *acute*, *acute_mesh*: wedges whose apex edge has a dihedral angle of 30, 45 and 60
  degrees, and the star prism (45-degree tips).
- *scan* (`evaluation/scan.py`): one depth camera (pinhole, square pixel grid, the
  same angular step in every view) at four positions around and above the part (2.2 to
  3.4 bounding radii away; the underside is never seen); each pixel's ray gives its
  first hit on the mesh (exact ray-triangle intersection: occlusion is exact); hits
  more than 75 degrees from head-on are lost; range noise along the ray with sigma =
  0.1 pixel footprints at the mean distance, growing with range squared; the views are
  merged without resampling (about n points). Density therefore falls with range and
  incidence, and overlaps are denser. Spacing: from the local density
  (`evaluation.scoring.density_spacing`, 16 neighbours), since nearest-neighbour distances
  collapse where views interleave. **Coverage is measured only on the edges the scan
  saw**: a piece of an edge counts when each of its two faces has a scan point within
  2 of that point's spacings of it (an edge never seen, or seen from one side, cannot
  be found as a crease); precision counts detections near any true edge.
- *smooth*, *smooth_mesh* (and the rounded box in *scan*): sphere, torus, rounded box;
  no edges; the score is the share of points flagged.

**Scores** (`evaluation/scoring.py`): precision = detections within 1 spacing of
an edge / detections; coverage = edge length with a detection within 1.5 spacings;
F1; thickness = detections within 2 spacings per spacing of covered edge (1.0: one
row of points along the edge). Means are over the sharp parts of a condition.
"""


def markdown(rows: list[dict], summary: dict, checks: list[dict], worse: dict, meta: dict) -> str:
    """The evaluation as a markdown page."""
    modes = meta["modes"]
    lines = [
        f"# Evaluation: {', '.join(modes)} on parts with known sharp edges",
        "",
        f"Written by `scripts/evaluate.py` (`{meta['command']}`): {meta['n_points']} points "
        f"per cloud, seed {meta['seed']}, {meta['seconds']:.0f} s on {meta['machine']}. "
        "How the inputs are made and scored: at the end of this page.",
        "",
        "## Targets",
        "",
        "| target | required | " + " | ".join(modes) + " |",
        "|---|---|" + "---|" * len(modes),
    ]
    for t in checks:
        cells = [f"{_target_value(t[m])} {'yes' if t[m]['met'] else '**no**'}" for m in modes]
        lines.append(f"| {t['target']} | {t['required']} | " + " | ".join(cells) + " |")
    for m, w in worse.items():
        lines.append("")
        lines.append(f"{m} worse than paper by more than 0.01 F1 on: {', '.join(w) or 'none'}.")
    lines += [
        "",
        "## Means per condition",
        "",
        "F1, precision (P), coverage (C; recall for per-vertex scores), thickness: means "
        "over the sharp parts; flagged: the largest share of points flagged on a smooth "
        "part (all false positives).",
        "",
        "| condition | what | parts | n | "
        + " | ".join(
            f"{m} F1 | {m} min F1 | {m} P | {m} C | {m} thick. | {m} flagged" for m in modes
        )
        + " |",
        "|---|---|---|---|" + "---|---|---|---|---|---|" * len(modes),
    ]
    for c, s in summary.items():
        cells = []
        for m in modes:
            e = s[m]
            fl = e["smooth_flagged_max"]
            cells += [
                f"**{_f(e['f1'])}**",
                _f(e["min_f1"]),
                _f(e["precision"]),
                _f(e["coverage"]),
                _f(e["thickness"], 2),
                "-" if math.isnan(fl) else f"{100 * fl:.2f} %",
            ]
        desc = gt.CONDITIONS[c].description
        lines.append(f"| {c} | {desc} | {s['parts']} | {s['points']} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Every part and condition",
        "",
        "| condition | part | n | "
        + " | ".join(f"{m} P | {m} C | {m} F1 | {m} thick. | {m} flagged %" for m in modes)
        + " |",
        "|---|---|---|" + "---|---|---|---|---|" * len(modes),
    ]
    for row in rows:
        cells = []
        for m in modes:
            s = row[m]
            cells += [
                _f(s["precision"]),
                _f(s["coverage"]),
                _f(s["f1"]),
                _f(s["thickness"], 2),
                f"{100 * s['fp_rate']:.2f}",
            ]
        lines.append(
            f"| {row['condition']} | {row['part']} | {row['n']} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines) + "\n\n" + METHOD


#: The page's last section, written by ``scripts/evaluate_cad.py``.
CAD_SECTION = "## CAD parts with exact truth"


def main(argv: list[str] | None = None) -> int:
    """Command line."""
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument(
        "--quick", action="store_true", help="6,000 points, each condition's quick parts"
    )
    ap.add_argument("--points", type=int, help="points per cloud (default 20000; quick 6000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", default="paper,robust", help="comma-separated detect modes")
    ap.add_argument("--conditions", help="comma-separated conditions (default: all)")
    ap.add_argument("--parts", help="comma-separated part names (default: all)")
    ap.add_argument("--json", help="also write the raw results to this JSON file")
    ap.add_argument("--no-write", action="store_true", help="leave docs/ alone")
    ap.add_argument(
        "--cache",
        default=str(ROOT / "build" / "evaluation-cache"),
        help="cache of generated inputs (default build/evaluation-cache)",
    )
    ap.add_argument("--no-cache", action="store_true", help="generate everything afresh")
    ap.add_argument("--list", action="store_true", help="list the conditions and their parts")
    args = ap.parse_args(argv)
    if args.list:
        for c in gt.CONDITIONS.values():
            print(f"{c.name:12s} [{c.group}] {c.description}")
            print(f"{'':12s} parts: {', '.join(c.parts)}; quick: {', '.join(c.quick_parts) or '-'}")
        return 0
    n = args.points or (6000 if args.quick else 20000)
    modes = args.modes.split(",")
    pairs = gt.suite(
        quick=args.quick,
        conditions=args.conditions.split(",") if args.conditions else None,
        parts=args.parts.split(",") if args.parts else None,
    )
    if not pairs:
        ap.error("no (part, condition) pair selected")
    cache = None if args.no_cache else Path(args.cache) / _generator_hash()
    t = time.perf_counter()
    rows = run(pairs, modes, n, args.seed, cache)
    seconds = time.perf_counter() - t
    summary = summarise(rows, modes)
    checks = targets(rows, summary, modes)
    worse = no_worse_than_paper(summary, modes)
    meta = {
        "command": "python3 scripts/evaluate.py" + (" " + " ".join(argv or sys.argv[1:])).rstrip(),
        "modes": modes,
        "n_points": n,
        "seed": args.seed,
        "seconds": seconds,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    print(f"\n{len(rows)} cases in {seconds:.1f} s")
    print_summary(summary, checks, worse, modes)
    payload = {
        "meta": meta,
        "summary": summary,
        "targets": checks,
        "worse_than_paper": worse,
        "rows": rows,
    }
    text = json.dumps(payload, indent=1, default=float) + "\n"
    if args.json:
        Path(args.json).write_text(text)
        print(f"wrote {args.json}")
    if not args.no_write:
        md = ROOT / "docs" / "evaluation.md"
        old = md.read_text() if md.is_file() else ""
        cad = old.find(CAD_SECTION)  # evaluate_cad.py's section stays as it is
        page = markdown(rows, summary, checks, worse, meta)
        page = page if cad < 0 else page.rstrip("\n") + "\n\n" + old[cad:]
        atomic_write(md, lambda tmp: Path(tmp).write_text(page))
        atomic_write(ROOT / "docs" / "evaluation.json", lambda tmp: Path(tmp).write_text(text))
        print(f"wrote {md} and docs/evaluation.json")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
