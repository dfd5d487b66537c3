#!/usr/bin/env python3
"""Evaluate the default mode on real CAD parts against their exact B-rep sharp edges.

Installs what it needs when missing (the ``gmsh`` wheel, the Debian package
``freecad-common``), builds each part's truth through gmsh/OpenCASCADE
(:mod:`evaluation.cad.truth`), makes its inputs (:mod:`evaluation.cad.inputs`: a fine
mesh, an STL-like tessellation, blue-noise clouds without and with noise of 25 % of
the spacing, an iid cloud, a simulated scan), runs ``detect(..., curves=True)`` in the
default mode and scores it (:mod:`evaluation.cad.run`). Writes the results as JSON and
prints the table.

    python3 scripts/evaluate_cad.py                      # all parts -> docs/evaluation-cad.json
    python3 scripts/evaluate_cad.py --quick --json out/cad.json
    python3 scripts/evaluate_cad.py --figure docs/evaluation-cad.png --markdown docs/evaluation.md
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import _venv  # scripts/, the script's own folder, is on sys.path

_venv.enter()

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from meshlab_sharp.io import atomic_write  # noqa: E402

TARGETS = {
    ("clear", "fine_mesh", "f1"): 0.99,
    ("clear", "blue_noise", "f1"): 0.975,
    ("clear", "noise25", "f1"): 0.93,
    ("clear", "iid", "f1"): 0.95,
    ("ambiguous", "blue_noise", "f1"): 0.85,
    ("ambiguous", "iid", "f1"): 0.80,
}
CURVE_TARGETS = {"curve_precision": 0.95, "curve_coverage": 0.95, "corners_found": 0.9}
FILLETED_MAX = 0.005


def fail(message: str) -> None:
    """One-line error, exit status 1."""
    print(f"meshlab-sharp: error: {message}", file=sys.stderr)
    raise SystemExit(1)


GMSH_LIBS = ["libglu1-mesa", "libxcursor1", "libxft2", "libxinerama1"]


def apt_install(packages: list[str]) -> None:
    """``apt-get update`` and install Debian packages (with sudo unless root)."""
    print(f"evaluate_cad: installing Debian packages: {' '.join(packages)}", file=sys.stderr)
    sudo = [] if os.geteuid() == 0 else ["sudo"]
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", *packages]):
        if subprocess.run(sudo + cmd, check=False, env=env, stdout=subprocess.DEVNULL).returncode:
            fail(f"could not run {' '.join(cmd)}")


def ensure_packages() -> None:
    """Install the gmsh wheel (and the libraries it loads) and the Debian package
    freecad-common when missing."""
    try:
        import gmsh  # noqa: F401
    except ImportError:
        print("evaluate_cad: installing the gmsh wheel", file=sys.stderr)
        cmd = [sys.executable, "-m", "pip", "install", "-q", "gmsh>=4.11"]
        if subprocess.run(cmd, check=False).returncode != 0:
            fail("could not install gmsh (pip install 'gmsh>=4.11')")
        importlib.invalidate_caches()
    except OSError:  # the wheel's libgmsh needs X and GLU libraries
        apt_install(GMSH_LIBS)
    from evaluation.cad.sources import FREECAD_DIR

    if not (FREECAD_DIR / "Idf").is_dir():
        apt_install(["freecad-common"])


def fmt(value: float, target: float | None = None, below: bool = False) -> str:
    """A table cell, with a mark where a target is missed."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    cell = f"{value:.3f}"
    if target is not None and (value > target if below else value < target):
        cell += " ✗"
    return cell


def table(summary: dict) -> str:
    """The results as Markdown tables (detection, then curves)."""
    from evaluation.cad.inputs import INPUTS

    lines = [
        "| class | input | parts | detection F1 | precision | coverage | flagged (%) |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for cls, per in summary.items():
        for name in INPUTS:
            if name not in per or (name == "stl_like" and cls != "filleted"):
                continue
            s = per[name]
            target = TARGETS.get((cls, name, "f1"))
            flagged = (
                fmt(s["flagged"] * 100, FILLETED_MAX * 100, below=True)
                if cls == "filleted"
                else fmt(s["flagged"] * 100)
            )
            lines.append(
                f"| {cls} | {name} | {s['parts']} | {fmt(s.get('f1', math.nan), target)} | "
                f"{fmt(s.get('precision', math.nan))} | {fmt(s.get('coverage', math.nan))} | "
                f"{flagged} |"
            )
    lines += [
        "",
        "| class | input | curve precision | curve coverage | count ratio (median) "
        "| corners found |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for cls, per in summary.items():
        if cls == "filleted":
            continue
        for name in INPUTS:
            if name not in per:
                continue
            s = per[name]
            meshes = cls == "clear" and name in ("fine_mesh", "stl_like")
            cov_target = 0.95 if meshes else 0.90 if cls == "clear" and name == "iid" else None
            ratio = s["count_ratio_median"]
            mark = " ✗" if cls == "clear" and not 0.8 <= ratio <= 1.25 else ""
            lines.append(
                f"| {cls} | {name} | {fmt(s['curve_precision'], 0.95 if meshes else None)} | "
                f"{fmt(s['curve_coverage'], cov_target)} | {ratio:.2f}{mark} | "
                f"{fmt(s['corners_found'], 0.9 if cls == 'clear' else None)} |"
            )
    return "\n".join(lines)


SECTION = "## CAD parts with exact truth"


def part_table(rows: list[dict]) -> str:
    """One line per part: its class, truth, detection F1 per input and curve coverage."""
    from evaluation.cad.inputs import INPUTS

    head = [i for i in INPUTS if i != "stl_like"]
    lines = [
        "| part | package | class | sharp curves | corners | "
        + " | ".join(f"F1 {i}" for i in head)
        + " | curve coverage stl_like / fine_mesh / iid |",
        "| --- " * (5 + len(head) + 1) + "|",
    ]
    for r in rows:
        inp = r["inputs"]
        if r["class"] == "filleted":
            cells = [f"{100 * inp[i]['flagged']:.2f} % flagged" for i in head]
            cov = "-"
        else:
            cells = [fmt(inp[i]["detection"]["f1"]) for i in head]
            cov = " / ".join(
                fmt(inp[i]["curves"]["coverage"]) for i in ("stl_like", "fine_mesh", "iid")
            )
        reasons = f" ({'; '.join(r['reasons'])})" if r["reasons"] else ""
        lines.append(
            f"| {r['name']} | {r['package']} | {r['class']}{reasons} | {r['sharp_curves']} | "
            f"{r['corners']} | " + " | ".join(cells) + f" | {cov} |"
        )
    return "\n".join(lines)


def markdown(out: dict, figure: str | None) -> str:
    """The section of docs/evaluation.md."""
    from evaluation.cad.sources import PARTS

    used = {r["name"] for r in out["parts"]}
    packages = sorted({p.package for p in PARTS if p.name in used})
    text = [
        SECTION,
        "",
        f"Written by `scripts/evaluate_cad.py` (`{out['command']}`): {out['points']:,} points "
        f"per cloud, seed {out['seed']}, {len(out['parts'])} parts in {out['seconds']:.0f} s on "
        f"{out['machine']}, gmsh {out['gmsh']}; every figure in `docs/evaluation-cad.json`. "
        "The script installs what it needs (the `gmsh` wheel, the `cad` extra; the Debian "
        f"package `freecad-common`). Parts from: {', '.join(packages)}.",
        "",
        "**Truth** (`evaluation/cad/truth.py`): the B-rep, read by gmsh's OpenCASCADE "
        "kernel. A curve between two faces is sharp where the faces' normals "
        "(`gmsh.model.getNormal` at the curve's samples, projected on each face) differ by 20 "
        "degrees or more; a curve with one face (a seam) never is; a corner is a vertex of 3 "
        "or more sharp curves. A mesh's own dihedral angles are never used. **Ambiguous** "
        "parts have an angle between 15 and 30 degrees on a curve, or two separate sharp "
        "features closer than 3 blue-noise spacings: two corners, or two points of the "
        "sharp curves whose way along the sharp curves is more than twice their distance "
        "(curves that do not meet or meet only far away, or meet at a sharp angle; a curve "
        "that comes back near itself). **Filleted** parts have no sharp curve (their score "
        "is the share of points flagged). They are reported apart, never dropped.",
        "",
        "**Inputs** (`evaluation/cad/inputs.py`): *fine_mesh*: gmsh's Frontal-Delaunay mesh "
        "of about n vertices, refined to 48 elements per turn on curved surfaces (B-rep "
        "curves are mesh edges); *stl_like*: 24 segments per turn and no other size limit "
        "(long thin triangles); *blue_noise*: Poisson-disk points on the fine mesh; "
        "*noise25*: the same with normal noise of 25 % of the spacing; *iid*: independent "
        "uniform points; *scan*: the simulated scanner of `evaluation/scan.py` around the "
        "fine mesh. **Scores**: detection per point (`evaluation.scoring.score_part`: "
        "precision within 1 spacing, coverage within 1.5); curves by "
        "`evaluation.scoring.evaluate_curves` (the STL-like tessellation at the blue-noise "
        "spacing), corners within 2 spacings of the B-rep corners. On the scan, coverage, "
        "count ratio and corners are measured on the truth the scanner saw, as detection "
        "coverage is: a piece of an exact edge is seen when a piece of the mesh's creases "
        "on the same curve with scan points on both sides lies within half a spacing of "
        "it, a corner when the seen pieces of 3 or more of its sharp curves end at it; "
        "precision against all the edges. Means over the parts of a class; count ratio: "
        "median; corners: pooled. ✗: a target missed.",
        "",
        table(out["summary"]),
        "",
        part_table(out["parts"]),
    ]
    if figure:
        text += [
            "",
            f"![B-rep truth, features and curves of one CAD part]({figure})",
            "",
            "*A part of `freecad-common` (an electronic package's STEP model) as a blue-noise "
            "cloud: left, its B-rep sharp curves (hidden ones drawn too) and corners; middle, "
            "the features of the default mode, coloured by strength; right, the feature "
            "curves by kind and their corners.*",
        ]
    wrapped = [t if t.startswith(("|", "!", "#")) else textwrap.fill(t, 88) for t in text]
    return "\n".join(wrapped) + "\n"


def write_section(path: Path, section: str) -> None:
    """Replace (or append) the CAD section of a Markdown page, atomically."""
    old = path.read_text() if path.is_file() else ""
    start = old.find(SECTION)
    if start < 0:
        new = old.rstrip("\n") + "\n\n" + section
    else:
        end = old.find("\n## ", start + len(SECTION))
        new = old[:start] + section + ("" if end < 0 else old[end:])
    atomic_write(path, lambda tmp: Path(tmp).write_text(new))


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Command-line options."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="a few parts only")
    ap.add_argument("--parts", nargs="+", metavar="NAME", help="these parts only")
    ap.add_argument("--points", type=int, default=50_000, help="points per cloud (default 50,000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=ROOT / "docs" / "evaluation-cad.json")
    ap.add_argument("--figure", type=Path, help="also draw the figure part as this PNG")
    ap.add_argument(
        "--markdown",
        type=Path,
        help="write the section into this page (e.g. docs/evaluation.md)",
    )
    ap.add_argument("--figure-part", default="SOT428_DPAK")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Run the evaluation, write the JSON, print the table."""
    args = parse_args(argv)
    if args.points < 1000:
        fail("--points must be at least 1000")
    for out_path in (args.json, args.figure, args.markdown):
        if out_path is None:
            continue
        if out_path.resolve().parent == (ROOT / "out").resolve():
            out_path.resolve().parent.mkdir(exist_ok=True)  # out/, git-ignored, as the CLI's
        if not out_path.resolve().parent.is_dir():
            fail(f"{out_path.parent}: no such folder")
    from evaluation.cad.sources import PARTS, QUICK_PARTS, missing_sources

    names = args.parts or (QUICK_PARTS if args.quick else [p.name for p in PARTS])
    unknown = sorted(set(names) - {p.name for p in PARTS})
    if unknown:
        fail(f"unknown part {unknown[0]!r} (parts: {', '.join(p.name for p in PARTS)})")
    chosen = tuple(p for p in PARTS if p.name in names)
    ensure_packages()
    import gmsh

    from evaluation.cad.run import evaluate_part, summarise

    missing = missing_sources(chosen)
    if missing:
        fail(f"{missing[0].path}: not installed ({missing[0].package})")
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    rows = []
    t0 = time.perf_counter()
    workdir = Path(tempfile.mkdtemp(prefix="evaluate-cad-"))
    try:
        for source in chosen:
            try:
                row = evaluate_part(source, args.points, workdir, seed=args.seed)
            except Exception as e:  # gmsh raises plain Exceptions on unreadable CAD files
                fail(f"{source.path}: {e}")
            print(f"evaluate_cad: {source.name}: {row['class']}", file=sys.stderr)
            rows.append(row)
        if args.figure is not None:
            draw(args.figure, args.figure_part, args.points, args.seed, workdir)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
        gmsh.finalize()
    summary = summarise(rows)
    out = {
        "command": "python3 scripts/evaluate_cad.py"
        + (" " + " ".join(argv or sys.argv[1:])).rstrip(),
        "points": args.points,
        "seed": args.seed,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}",
        "gmsh": gmsh.__version__,
        "seconds": time.perf_counter() - t0,
        "summary": summary,
        "parts": rows,
    }
    text = json.dumps(out, indent=1, default=float) + "\n"
    atomic_write(args.json, lambda tmp: Path(tmp).write_text(text))
    if args.markdown is not None:
        figure = None
        if args.figure is not None:
            figure = os.path.relpath(args.figure.resolve(), args.markdown.resolve().parent)
        write_section(args.markdown, markdown(out, figure))
    print(table(summary))
    print(f"\n{len(rows)} parts in {out['seconds']:.0f} s; wrote {args.json}")
    return 0


def draw(path: Path, name: str, n: int, seed: int, workdir: Path) -> None:
    """The figure of one part's blue-noise cloud."""
    from evaluation.cad.figure import save_figure
    from evaluation.cad.inputs import make_inputs
    from evaluation.cad.sources import PARTS, load
    from evaluation.cad.truth import brep_truth
    from meshlab_sharp import detect

    source = next((p for p in PARTS if p.name == name), None)
    if source is None:
        fail(f"unknown part {name!r}")
    load(source, workdir)
    truth = brep_truth()
    part = make_inputs(name, truth.segments, n, seed=seed, which=("blue_noise",))["blue_noise"]
    result = detect(part.vertices, curves=True)
    save_figure(
        path,
        part,
        truth,
        result,
        f"{name} ({source.package}), {n:,}-point blue-noise cloud, default mode",
    )


if __name__ == "__main__":
    raise SystemExit(main())
