"""The ``meshlab-sharp`` command line.

``meshlab-sharp detect INPUT`` writes ``INPUT_sharp.ply`` (every input vertex in input
order, faces kept, vertex quality = strength, features selected and red), and on
request the feature indices and a JSON report. ``meshlab-sharp detect`` with no input
runs on the built-in sample part.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from . import __version__
from .errors import MeshlabSharpError
from .io import Geometry, load, save_features_ply, save_indices, save_json
from .multiscale import DEFAULT_KNN_SCALES, DEFAULT_RING_SCALES
from .normals import WEIGHTINGS
from .pipeline import DetectionResult, detect
from .progress import Progress


def parse_scales(text: str) -> list[int]:
    """Parse ``"12,16,20"`` or an inclusive range ``"12:40:4"`` (``"1:4"`` steps by 1)."""
    try:
        if ":" in text:
            parts = [int(p) for p in text.split(":")]
            if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] <= 0):
                raise ValueError
            step = parts[2] if len(parts) == 3 else 1
            return list(range(parts[0], parts[1] + 1, step))
        return [int(p) for p in text.replace(" ", "").split(",") if p]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"invalid scales {text!r}: use a list like 12,16,20 or a range like 12:40:4"
        ) from None


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = argparse.ArgumentParser(
        prog="meshlab-sharp",
        description="Find sharp features (creases, corners) of point clouds and meshes "
        "automatically, with the projected-distance method of Tran et al.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    det = sub.add_parser(
        "detect",
        help="detect sharp features and write a PLY MeshLab shows",
        description="Detect sharp features. Output: a PLY with every input vertex in "
        "input order (faces kept), vertex quality = feature strength (fraction of "
        "scales), features selected (PLY flags bit 0x20) and coloured red.",
    )
    det.add_argument("input", nargs="?", help="mesh or point cloud (PLY, OBJ, OFF, STL, XYZ...)")
    det.add_argument(
        "--sample",
        nargs="?",
        const="points",
        choices=("points", "mesh"),
        help="run on the built-in sample part (the default when no INPUT is given)",
    )
    det.add_argument("-o", "--output", help="output PLY (default: INPUT_sharp.ply)")
    det.add_argument("--indices", metavar="FILE", help="write 0-based feature indices, one a line")
    det.add_argument("--report", metavar="FILE", help="write counts, thresholds, timings as JSON")
    det.add_argument("--as-points", action="store_true", help="treat a mesh as a point cloud")
    det.add_argument(
        "--scales",
        type=parse_scales,
        help="kNN sizes for clouds (default "
        f"{','.join(map(str, DEFAULT_KNN_SCALES))}) or rings for meshes (default "
        f"{','.join(map(str, DEFAULT_RING_SCALES))}); a list or a range start:stop:step",
    )
    det.add_argument(
        "--weighting",
        choices=WEIGHTINGS,
        default="gaussian",
        help="weights of the PCA normals (default: gaussian)",
    )
    det.add_argument("--ascii", action="store_true", help="write an ASCII PLY (default binary)")
    det.add_argument("--force", action="store_true", help="overwrite existing outputs")
    det.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no summary")
    det.set_defaults(func=run_detect)

    try:  # TEMPORARY until plugin.py lands
        from .plugin import add_plugin_command

        add_plugin_command(sub)
    except ImportError:
        pass
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``meshlab-sharp`` script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MeshlabSharpError as exc:
        print(f"meshlab-sharp: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"meshlab-sharp: error: {exc.strerror or exc}: {exc.filename or ''}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("meshlab-sharp: interrupted; no partial output was left", file=sys.stderr)
        return 130


def run_detect(args: argparse.Namespace) -> int:
    """``meshlab-sharp detect``."""
    if args.input is not None and args.sample is not None:
        raise MeshlabSharpError("give either INPUT or --sample, not both")
    if args.input is None:
        source, stem, folder = _sample_geometry(args.sample or "points"), "sample_part", Path(".")
    else:
        source = Path(args.input)
        stem, folder = source.stem, source.parent
    output = Path(args.output) if args.output else folder / f"{stem}_sharp.ply"
    outputs = [p for p in (output, args.indices, args.report) if p is not None]
    _check_outputs(source, [Path(p) for p in outputs], force=args.force)
    if output.suffix.lower() != ".ply":
        raise MeshlabSharpError(f"{output}: the output must be a .ply file")

    show = not args.quiet
    progress = Progress(
        len(args.scales or DEFAULT_KNN_SCALES) + 4, enabled=show and sys.stderr.isatty()
    )
    start = time.perf_counter()
    geometry = source if isinstance(source, Geometry) else load(source)
    load_time = time.perf_counter() - start
    result = detect(
        geometry,
        scales=args.scales,
        weighting=args.weighting,
        as_points=args.as_points,
        progress=progress,
    )
    result.timings["load"] = load_time
    t = time.perf_counter()
    save_features_ply(
        output,
        geometry.vertices,
        geometry.faces,
        result.strength,
        result.mask,
        binary=not args.ascii,
    )
    if args.indices:
        save_indices(args.indices, result.mask)
    result.timings["save"] = time.perf_counter() - t
    result.timings["total"] = time.perf_counter() - start
    progress.step("saved")
    progress.close()
    if args.report:
        report = result.summary()
        report["input"] = geometry.source
        report["outputs"] = {"ply": str(output), "indices": args.indices}
        save_json(args.report, report)
    if show:
        _print_summary(geometry.source, output, result)
    return 0


def _sample_geometry(kind: str) -> Geometry:
    """The built-in sample part as a Geometry."""
    from .sample import sample_part

    part = sample_part(kind)
    return Geometry(vertices=part.vertices, faces=part.faces, source=f"sample part ({kind})")


def _check_outputs(source: Geometry | Path, outputs: list[Path], *, force: bool) -> None:
    """Refuse to overwrite the input, or an existing output without ``--force``."""
    resolved = [p.resolve() for p in outputs]
    if len(set(resolved)) != len(resolved):
        raise MeshlabSharpError("two outputs have the same path")
    if isinstance(source, Path) and source.exists() and source.resolve() in resolved:
        raise MeshlabSharpError(f"{source}: an output would overwrite the input")
    for p in outputs:
        if p.exists() and not force:
            raise MeshlabSharpError(f"{p} exists; use --force to overwrite it")


def _print_summary(source: str, output: Path, result: DetectionResult) -> None:
    """One line per scale and a closing line, on stdout."""
    unit = "k" if result.kind == "points" else "ring"
    for s, t, c in zip(result.scales, result.thresholds, result.candidate_counts, strict=True):
        print(f"  {unit} = {s:3d}: threshold {t:.4f}, {c} candidates")
    n = len(result.mask)
    print(
        f"{source}: {n} {'vertices' if result.kind == 'mesh' else 'points'}, "
        f"{result.n_features} sharp features ({100.0 * result.n_features / n:.1f}%) "
        f"-> {output} [{result.timings.get('total', 0.0):.2f} s]"
    )
