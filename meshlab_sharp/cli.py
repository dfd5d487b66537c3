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
from .plugin import add_plugin_command
from .preprocessing import Preprocessing
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
    det.add_argument(
        "--mode",
        choices=("paper", "robust"),
        default="paper",
        help="paper: the paper's method as ALGORITHM.md reads it (default); robust: "
        "ignores outliers, density-independent, no features on smooth objects, thin "
        "lines (docs/robust-mode.md)",
    )
    det.add_argument("--ascii", action="store_true", help="write an ASCII PLY (default binary)")
    det.add_argument("--force", action="store_true", help="overwrite existing outputs")
    det.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no summary")
    _add_preprocessing_arguments(det)
    det.set_defaults(func=run_detect)

    add_plugin_command(sub)
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
    extra = (args.save_processed, args.plot)
    outputs = [p for p in (output, args.indices, args.report, *extra) if p is not None]
    _check_outputs(source, [Path(p) for p in outputs], force=args.force)
    if output.suffix.lower() != ".ply":
        raise MeshlabSharpError(f"{output}: the output must be a .ply file")
    steps = _preprocessing_from_args(args)

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
        mode=args.mode,
        as_points=args.as_points,
        progress=progress,
        preprocessing=steps,
        return_details=args.plot is not None,
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
    if args.save_processed and result.preprocessing is not None:
        done = result.preprocessing
        assert done.result is not None
        save_features_ply(
            args.save_processed,
            done.geometry.vertices,
            done.geometry.faces,
            done.result.strength,
            done.result.mask,
            binary=not args.ascii,
        )
    result.timings["save"] = time.perf_counter() - t
    result.timings["total"] = time.perf_counter() - start
    progress.step("saved")
    progress.close()
    if args.plot:
        from .plot import save_report

        save_report(args.plot, result, geometry)
    if args.report:
        report = result.summary()
        report["input"] = geometry.source
        report["outputs"] = {"ply": str(output), "indices": args.indices}
        save_json(args.report, report)
    if show:
        if result.preprocessing is not None:
            _print_preprocessing(result)
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


def _add_preprocessing_arguments(det: argparse.ArgumentParser) -> None:
    """Preprocessing flags (pymeshlab filters, applied in a fixed order) and the picture."""
    from .preprocessing import DENOISE_METHODS

    pre = det.add_argument_group(
        "preprocessing",
        "pymeshlab filters run before detection, always in this order: remove outliers, "
        "denoise, fill holes, simplify. Results stay in the input's order: removed points "
        "are not features; vertices added by hole filling are only in --save-processed.",
    )
    pre.add_argument(
        "--remove-outliers",
        action="store_true",
        help="point clouds: remove points of high local outlier probability",
    )
    pre.add_argument(
        "--outlier-probability",
        type=float,
        default=0.8,
        metavar="P",
        help="outlier probability threshold in (0, 1) (default 0.8)",
    )
    pre.add_argument(
        "--outlier-neighbours",
        type=int,
        default=32,
        metavar="K",
        help="neighbours of the outlier probability (default 32)",
    )
    pre.add_argument(
        "--denoise",
        nargs="?",
        const="auto",
        choices=DENOISE_METHODS,
        metavar="METHOD",
        help="smooth before detection: meshes taubin (default) or two_steps; point clouds "
        "rimls (default) or apss MLS projection",
    )
    pre.add_argument(
        "--smoothing-steps",
        type=int,
        metavar="N",
        help="mesh smoothing iterations (default 10 Taubin, 3 two-step)",
    )
    pre.add_argument("--fill-holes", action="store_true", help="meshes: close holes")
    pre.add_argument(
        "--max-hole-size",
        type=int,
        metavar="EDGES",
        help="largest hole closed, in boundary edges (default: bounding-box diagonal / "
        "mean edge length)",
    )
    pre.add_argument(
        "--simplify",
        type=float,
        metavar="FRACTION",
        help="keep about this fraction of the vertices, in (0, 1]",
    )
    pre.add_argument(
        "--save-processed",
        metavar="FILE.ply",
        help="write the processed geometry (quality = strength, features selected)",
    )
    det.add_argument(
        "--plot",
        metavar="FILE.png",
        help="write the report picture: histograms with thresholds, views with the "
        "features (needs matplotlib: pip install 'meshlab-sharp[plot]')",
    )


def _preprocessing_from_args(args: argparse.Namespace) -> Preprocessing | None:
    """The Preprocessing the flags ask for (None when none); checks the extra outputs."""
    steps = Preprocessing(
        remove_outliers=args.remove_outliers,
        outlier_probability=args.outlier_probability,
        outlier_neighbours=args.outlier_neighbours,
        denoise=args.denoise is not None,
        denoise_method=args.denoise or "auto",
        smoothing_steps=args.smoothing_steps,
        fill_holes=args.fill_holes,
        max_hole_size=args.max_hole_size,
        simplify=args.simplify,
    )
    if args.save_processed is not None:
        if not steps.active:
            raise MeshlabSharpError(
                "--save-processed needs a preprocessing step (--remove-outliers, --denoise, "
                "--fill-holes or --simplify)"
            )
        if Path(args.save_processed).suffix.lower() != ".ply":
            raise MeshlabSharpError(f"{args.save_processed}: --save-processed must be a .ply file")
    if args.plot is not None:
        if Path(args.plot).suffix.lower() != ".png":
            raise MeshlabSharpError(f"{args.plot}: --plot must be a .png file")
        from .plot import require_matplotlib

        require_matplotlib()
    return steps if steps.active else None


def _print_preprocessing(result: DetectionResult) -> None:
    """One line per preprocessing step, on stdout."""
    assert result.preprocessing is not None
    for step in result.preprocessing.steps:
        name = step["step"].replace("_", " ")
        if "skipped" in step:
            print(f"  {name}: skipped ({step['skipped']})")
        else:
            print(
                f"  {name}: {step['vertices_before']} -> {step['vertices_after']} vertices "
                f"[{step['seconds']:.2f} s]"
            )
