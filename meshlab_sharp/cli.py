"""The ``meshlab-sharp`` command line.

``meshlab-sharp detect INPUT`` writes ``INPUT_sharp.ply`` (every input vertex in input
order with the input's own vertex properties, faces kept, vertex quality = strength,
features selected and red unless ``--no-colour``) or a LAS/LAZ file, and on request the
feature indices and a JSON report. ``meshlab-sharp detect`` with no input runs on the
built-in sample part, whose outputs in ``out/`` each run replaces.
"""

from __future__ import annotations

import argparse
import errno
import logging
import os
import re
import signal
import sys
import threading
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any, NamedTuple, NoReturn, TextIO

from . import __version__
from .address_space import check_address_space
from .defaults import (
    DEFAULT_KNN_SCALES,
    DEFAULT_MODE,
    DEFAULT_RING_SCALES,
    DEFAULT_WEIGHTING,
    DENOISE_METHODS,
    HELD_SIGNALS,
    MAX_SCALES,
    MODES,
    WEIGHTINGS,
)
from .errors import InputError, InputWarning, Interrupted, MeshlabSharpError, OutOfMemory
from .outputs import OutputSet
from .plugin import add_plugin_command
from .progress import TICK, Progress

if TYPE_CHECKING:  # the heavy modules are imported when work starts
    from .io.geometry import Geometry
    from .preprocessing import Preprocessing
    from .result import DetectionResult

#: ASCII white space, the only separator of a space-separated list (the plugin's too).
_SPACE = " \t\n\r\f\v"
#: One number of a scale list: an optional sign and digits, white space around it.
_NUMBER = re.compile(rf"[{_SPACE}]*([+-]?[0-9]+)[{_SPACE}]*")


def _scale_number(token: str) -> int:
    """One number of :func:`parse_scales`' grammar, at most 2**31 - 1 in magnitude."""
    match = _NUMBER.fullmatch(token)
    if match is None or abs(int(match.group(1))) > 2**31 - 1:
        raise ValueError(token)
    return int(match.group(1))


def parse_scales(text: str) -> list[int]:
    """Parse a list ``"12,16,20"`` or ``"12 16 20"`` (the plugin's format), or an
    inclusive range ``"12:40:4"`` (``"1:4"`` steps by 1).

    A list is comma-separated (white space around the commas allowed) or separated by
    ASCII white space, never both; each number is an optional sign and digits. A range
    is checked before it is built: at most :data:`MAX_SCALES` values. The native
    library's ``ms_parse_scales``, which the MeshLab plugin calls, reads the same grammar
    with the same messages (``tests/test_detect_native.py`` checks both on one table).
    """
    hint = "use a list like 12,16,20 or 12 16 20, or a range like 12:40:4"
    values: Sequence[int]
    try:
        if ":" in text:
            parts = [_scale_number(p) for p in text.split(":")]
            if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] <= 0):
                raise ValueError
            values = range(parts[0], parts[1] + 1, parts[2] if len(parts) == 3 else 1)
        else:
            items = text.split(",") if "," in text else re.split(f"[{_SPACE}]+", text.strip(_SPACE))
            values = [_scale_number(p) for p in items]
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid scales '{text}': {hint}") from None
    if len(values) == 0:
        raise argparse.ArgumentTypeError(f"invalid scales '{text}': the range is empty")
    if len(values) > MAX_SCALES:
        raise argparse.ArgumentTypeError(
            f"invalid scales '{text}': {len(values)} scales, more than {MAX_SCALES}"
        )
    return list(values)


def _seconds(text: str) -> float:
    """A positive, finite number of seconds."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 < value < float("inf"):
        raise argparse.ArgumentTypeError(
            f"invalid time {text!r}: give a positive number of seconds"
        )
    return value


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line, ``meshlab-sharp: error: ...``,
    with exit status 1 like every other error."""

    def error(self, message: str) -> NoReturn:
        self.exit(1, f"meshlab-sharp: error: {message} (see {self.prog} --help)\n")


class _Once(argparse.Action):
    """An option naming an output, which may be given only once (given twice, which
    one was meant is unknown: an error, not the last one silently)."""

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        if getattr(namespace, self.dest) is not None:
            parser.error(f"{'/'.join(self.option_strings)} given twice")
        setattr(namespace, self.dest, values)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    parser = _Parser(
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
        "input order (faces kept, a PLY input's vertex properties kept), vertex quality = "
        "feature strength (fraction of scales), features selected (PLY flags bit 0x20) "
        "and coloured red (not with --no-colour); or LAS/LAZ (-o OUT.las).",
    )
    det.add_argument("input", nargs="?", help="mesh or point cloud (PLY, OBJ, OFF, STL, XYZ...)")
    det.add_argument(
        "--sample",
        nargs="?",
        const="points",
        choices=("points", "mesh"),
        help="run on the built-in sample part (the default when no INPUT is given)",
    )
    det.add_argument(
        "-o",
        "--output",
        action=_Once,
        help=f"output .ply, or .las/.laz (needs laspy: pip install 'meshlab-sharp[las]'; "
        "features class 64, strength in the extra dimension sharp_strength; a LAS input's "
        f"attributes kept) (default: INPUT_sharp.ply; {SAMPLE_FOLDER}/sample_part_sharp.ply "
        f"and {SAMPLE_FOLDER}/sample_part_mesh_sharp.ply for the sample part; the sample's "
        f"outputs in {SAMPLE_FOLDER}/ are replaced on each run)",
    )
    det.add_argument(
        "--indices", action=_Once, metavar="FILE", help="write 0-based feature indices, one a line"
    )
    det.add_argument(
        "--report", action=_Once, metavar="FILE", help="write counts, thresholds, timings as JSON"
    )
    det.add_argument(
        "--curves",
        action=_Once,
        metavar="FILE",
        help="write the feature curves: .ply (edge mesh MeshLab opens), .obj (l lines) or "
        ".dxf (3D polylines; needs ezdxf: pip install 'meshlab-sharp[dxf]')",
    )
    det.add_argument("--as-points", action="store_true", help="treat a mesh as a point cloud")
    det.add_argument(
        "--scales",
        type=parse_scales,
        help="kNN sizes for clouds (default "
        f"{','.join(map(str, DEFAULT_KNN_SCALES))}) or rings for meshes (default "
        f"{','.join(map(str, DEFAULT_RING_SCALES))}); a list, comma- or space-separated "
        "('8,12,16' or '8 12 16'), or a range start:stop:step",
    )
    det.add_argument(
        "--weighting",
        choices=WEIGHTINGS,
        default=DEFAULT_WEIGHTING,
        help=f"weights of the PCA normals (default: {DEFAULT_WEIGHTING})",
    )
    det.add_argument(
        "--mode",
        choices=MODES,
        default=DEFAULT_MODE,
        help=f"robust (default: {DEFAULT_MODE}): ignores outliers, copes with noise, "
        "uneven density and CAD tessellations, no features on smooth objects, lines one "
        "point wide; paper: the paper's method exactly as "
        "ALGORITHM.md reads it",
    )
    det.add_argument(
        "--max-memory",
        metavar="SIZE",
        help="point clouds out of core: spatial tiles with halos, peak memory under SIZE "
        "(e.g. 1GB); the same result as in memory (binary PLY, LAS/LAZ, E57 streamed)",
    )
    det.add_argument(
        "--dask",
        metavar="CLUSTER",
        help="run the tiles on Dask: local:N (N local workers) or tcp://HOST:PORT",
    )
    det.add_argument(
        "--dask-timeout",
        type=_seconds,
        metavar="SECONDS",
        help="--dask tcp://...: seconds to reach the scheduler, and then to wait for its "
        "first worker (default 30)",
    )
    det.add_argument(
        "--verbose",
        action="store_true",
        help="--dask: show the scheduler's and workers' log messages",
    )
    det.add_argument(
        "--scratch",
        metavar="DIR",
        help="folder for the tiles' arrays (with --dask on several machines: shared)",
    )
    det.add_argument("--ascii", action="store_true", help="write an ASCII PLY (default binary)")
    det.add_argument(
        "--no-colour",
        dest="colour",
        action="store_false",
        help="do not colour the features red and the rest grey: keep the input's own "
        "colours (the selection and the quality still mark the features)",
    )
    det.add_argument("--force", action="store_true", help="overwrite existing outputs")
    det.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no summary")
    _add_preprocessing_arguments(det)
    det.set_defaults(func=run_detect)

    add_plugin_command(sub)
    return parser


@contextmanager
def _signals_interrupt() -> Iterator[None]:
    """Turn SIGINT, SIGTERM and SIGHUP into :class:`Interrupted` while the block runs.

    Only the first signal interrupts; later ones are ignored, so that the clean-up
    (removing temporary files) runs to its end. Outside the main thread, where Python
    cannot set handlers, nothing changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []

    def interrupt(signum: int, frame: FrameType | None) -> None:
        if not arrived:
            arrived.append(signum)
            raise Interrupted(signum)

    previous = {s: signal.signal(s, interrupt) for s in HELD_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


@contextmanager
def _warnings_as_lines() -> Iterator[None]:
    """Print each :class:`InputWarning` as one ``meshlab-sharp: warning: ...`` line while
    the block runs (other warnings as Python prints them)."""
    with warnings.catch_warnings():
        python_way = warnings.showwarning

        def show(
            message: Warning | str,
            category: type[Warning],
            filename: str,
            lineno: int,
            file: TextIO | None = None,
            line: str | None = None,
        ) -> None:
            if issubclass(category, InputWarning):
                print(f"meshlab-sharp: warning: {message}", file=sys.stderr)
            else:
                python_way(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        yield


def main(argv: Sequence[str] | None = None, *, end_after_out_of_memory: bool = False) -> int:
    """Entry point of the ``meshlab-sharp`` script; returns the exit status.

    Every failure is one line on stderr, ``meshlab-sharp: error: ...``, and status 1;
    SIGINT, SIGTERM and SIGHUP end the command with one line saying what was written,
    and status 128 + the signal's number. With ``end_after_out_of_memory`` (the
    script), the process ends right after an out-of-memory line (``os._exit``): a
    library whose threads could not start may crash while the interpreter shuts down.
    """
    with _signals_interrupt(), _warnings_as_lines():
        try:
            args = build_parser().parse_args(argv)
            return int(args.func(args) or 0)
        except MeshlabSharpError as exc:
            print(f"meshlab-sharp: error: {exc}", file=sys.stderr)
            if end_after_out_of_memory and isinstance(exc, OutOfMemory):
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(1)
            return 1
        except OSError as exc:
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"meshlab-sharp: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 1
        except Interrupted as exc:
            print(f"meshlab-sharp: {_interrupted_message(exc)}", file=sys.stderr)
            return 128 + exc.signum


def _interrupted_message(exc: Interrupted) -> str:
    """What an interruption left: nothing, or every output (after the renames)."""
    said = f"interrupted by {signal.Signals(exc.signum).name}"
    if exc.written is None:
        return said
    if not exc.written:
        return f"{said}; no output was written"
    return f"{said} after writing {', '.join(map(str, exc.written))}"


#: Folder of the sample part's default outputs (created when absent); git ignores it.
SAMPLE_FOLDER = "out"
#: Test hook: when set to a path, ``detect`` creates that file once every output is
#: staged and waits (at most a minute) until it is removed before renaming them.
PAUSE_ENV = "MESHLAB_SHARP_TEST_PAUSE"
#: Extensions of the main output: a PLY MeshLab shows, or LAS/LAZ (the ``las`` extra).
OUTPUT_FORMATS = (".ply", ".las", ".laz")
#: LAS/LAZ: an output in these formats keeps an input's per-point attributes.
_LAS_INPUTS = (".las", ".laz")


class _Plan(NamedTuple):
    """What ``detect`` reads and writes, checked before any heavy import."""

    source: Path | None  # the input file; None for the sample part
    sample: str | None  # the sample part's kind; None for an input file
    output: Path
    own: Path | None  # the sample's folder (out/) when an output is in it: made first
    paths: list[Path]  # every output


def run_detect(args: argparse.Namespace) -> int:
    """``meshlab-sharp detect``: every option and output is checked before numpy, scipy
    or pymeshlab is imported and before any computation, and the outputs are written
    all or nothing (:class:`meshlab_sharp.io.OutputSet`)."""
    progress = Progress(
        len(args.scales or DEFAULT_KNN_SCALES) + 4,
        enabled=not args.quiet and sys.stderr.isatty(),
        tick=TICK,
    )
    written: list[Path] = []
    check_address_space()  # before any library loads: a low ulimit -v would hang it
    try:
        plan = _plan(args)
        steps = _preprocessing_from_args(args)
        with OutputSet() as outputs:
            written = outputs.written
            mine = [p for p in plan.paths if plan.own is not None and _inside(p, plan.own)]
            outputs.claim([p for p in plan.paths if p not in mine], force=args.force)
            if plan.own is not None:
                plan.own.mkdir(exist_ok=True)
            outputs.claim(mine, force=True)  # the sample's own outputs: replaced
            return _detect_into(args, plan, steps, outputs, progress)
    except MemoryError:  # numpy's, the compiled kernels', pymeshlab's std::bad_alloc
        raise OutOfMemory(_out_of_memory(args)) from None
    except OSError as exc:  # a memory map, a thread or a process that cannot start
        if exc.errno == errno.ENOMEM:
            raise OutOfMemory(_out_of_memory(args)) from None
        raise
    except RuntimeError as exc:  # threading's, when a thread's stack cannot be mapped
        if "can't start new thread" in str(exc):
            raise OutOfMemory(_out_of_memory(args)) from None
        raise
    except ImportError as exc:  # a compiled module whose segments cannot be mapped
        if "failed to map segment" in str(exc):
            raise OutOfMemory(_out_of_memory(args)) from None
        raise
    except Interrupted as exc:
        exc.written = list(written)
        raise
    finally:
        progress.close()  # an error message starts on a line of its own


def _plan(args: argparse.Namespace) -> _Plan:
    """The input and the outputs, checked (:func:`_check_outputs`); no heavy import."""
    if args.input is not None and args.sample is not None:
        raise MeshlabSharpError("give either INPUT or --sample, not both")
    sample = (args.sample or "points") if args.input is None else None
    source: Path | None = None
    if sample is not None:
        # each kind its own file, so that --sample and --sample mesh do not collide
        stem = "sample_part" if sample == "points" else f"sample_part_{sample}"
        folder = Path(SAMPLE_FOLDER)
    else:
        source = Path(args.input)
        stem, folder = source.stem, source.parent
    output = Path(args.output) if args.output else folder / f"{stem}_sharp.ply"
    if output.suffix.lower() not in OUTPUT_FORMATS:
        raise MeshlabSharpError(
            f"{output}: the output must be a {', '.join(OUTPUT_FORMATS[:-1])} or "
            f"{OUTPUT_FORMATS[-1]} file"
        )
    if output.suffix.lower() in _LAS_INPUTS:
        from .io.las import check_las_output

        check_las_output(output)
    if args.curves is not None:
        from .io.curves import check_curves_path

        check_curves_path(args.curves)
    named = (args.indices, args.report, args.save_processed, args.plot, args.curves)
    extra = [Path(p) for p in named if p is not None]
    paths = [output, *extra]
    own = Path(SAMPLE_FOLDER) if sample is not None else None
    if own is not None and not any(_inside(p, own) for p in paths):
        own = None
    _check_outputs(source, paths, own=own)
    return _Plan(source, sample, output, own, paths)


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``path`` lies directly in ``folder`` (both may not exist yet)."""
    return path.parent.resolve() == folder.resolve()


def _detect_into(
    args: argparse.Namespace,
    plan: _Plan,
    steps: Preprocessing | None,
    outputs: OutputSet,
    progress: Progress,
) -> int:
    """:func:`run_detect`'s work, staging every file in ``outputs`` and committing them."""
    from . import _kernels
    from .io import load, save_features_ply, save_indices

    try:
        _kernels.resolve(None)  # a bad MESHLAB_SHARP_BACKEND fails before any work
    except (ValueError, RuntimeError) as exc:
        raise MeshlabSharpError(str(exc)) from None
    _load_libraries()
    source, output = plan.source, plan.output
    start = time.perf_counter()
    if args.max_memory is not None or args.dask is not None:
        return _detect_tiled(args, plan, outputs, progress, steps)
    geometry = _sample_geometry(plan.sample) if source is None else load(source)
    args.input_points = len(geometry.vertices)
    attributes = _input_attributes(source) if output.suffix.lower() == ".ply" else None
    load_time = time.perf_counter() - start
    with _option_names():
        result = _detect(
            geometry,
            scales=args.scales,
            weighting=args.weighting,
            mode=args.mode,
            as_points=args.as_points,
            progress=progress,
            preprocessing=steps,
            return_details=args.plot is not None,
            curves=args.curves is not None,
        )
    result.timings["load"] = load_time
    t = time.perf_counter()
    binary = not args.ascii
    if output.suffix.lower() == ".ply":
        save_features_ply(
            output,
            geometry.vertices,
            geometry.faces,
            result.strength,
            result.mask,
            attributes=attributes,
            colour=args.colour,
            binary=binary,
            into=outputs,
        )
    else:
        _save_las(output, source, geometry.vertices, result, outputs)
    if args.indices:
        save_indices(args.indices, result.mask, into=outputs)
    if args.save_processed and result.preprocessing is not None:
        done = result.preprocessing
        assert done.result is not None
        save_features_ply(
            args.save_processed,
            done.geometry.vertices,
            done.geometry.faces,
            done.result.strength,
            done.result.mask,
            binary=binary,
            into=outputs,
        )
    _save_curves(args, result, outputs)
    if args.plot:
        from .plot import save_report

        save_report(args.plot, result, geometry, into=outputs)
    _commit(args, result, geometry.source, output, outputs, start=start, saving=t)
    progress.step("saved")
    progress.close()
    _print_warnings(result)
    if not args.quiet:
        if result.preprocessing is not None:
            _print_preprocessing(result)
        _print_summary(geometry.source, output, result)
    return 0


def _detect(geometry: Any, **options: Any) -> DetectionResult:
    """:func:`meshlab_sharp.detect`, imported when the work starts."""
    from .pipeline import detect

    return detect(geometry, **options)


def _input_attributes(source: Path | None) -> dict[str, Any] | None:
    """The per-vertex properties of a PLY input (normals, colours, scalar fields) or the
    per-point attributes of a LAS/LAZ input, which the output PLY keeps; None for other
    inputs."""
    if source is None:
        return None
    if source.suffix.lower() in _LAS_INPUTS:
        from .io.las import las_attributes

        return las_attributes(source)
    if source.suffix.lower() != ".ply":
        return None
    from .io.ply import read_ply_properties

    return read_ply_properties(source, str(source)) or None


def _save_las(
    output: Path, source: Path | None, vertices: Any, result: DetectionResult, outputs: OutputSet
) -> None:
    """Stage the LAS/LAZ output: a LAS/LAZ input's points with all their attributes."""
    from .io.las import save_features_las

    keep = source if source is not None and source.suffix.lower() in _LAS_INPUTS else None
    save_features_las(output, vertices, result.strength, result.mask, source=keep, into=outputs)


def _save_curves(args: argparse.Namespace, result: DetectionResult, outputs: OutputSet) -> None:
    """Stage the ``--curves`` file when asked for."""
    if args.curves:
        from .io import save_curves

        assert result.curves is not None
        save_curves(args.curves, result.curves, into=outputs)


def _detect_tiled(
    args: argparse.Namespace,
    plan: _Plan,
    outputs: OutputSet,
    progress: Progress,
    steps: Preprocessing | None,
) -> int:
    """``detect --max-memory``/``--dask``: the input streamed, the output written in
    blocks (:mod:`meshlab_sharp.io.stream`)."""
    from .io import save_indices
    from .io.source import PointSource
    from .io.stream import mesh_error, open_points, write_features_ply

    source, output = plan.source, plan.output
    for flag, given in (
        ("--ascii", args.ascii),
        ("--plot", args.plot),
        ("--save-processed", args.save_processed),
        ("--no-colour", not args.colour),
        ("a LAS/LAZ output", output.suffix.lower() != ".ply"),
    ):
        if given:
            raise MeshlabSharpError(f"{flag} is not available with --max-memory/--dask")
    start = time.perf_counter()
    if args.dask is not None and not args.verbose:
        _quiet_dask()
    if source is None:
        assert plan.sample is not None
        if plan.sample == "mesh" and not args.as_points:
            raise mesh_error("sample part (mesh)")
        points = PointSource.from_array(_sample_geometry(plan.sample).vertices, "sample part")
    else:
        points = open_points(source, as_points=args.as_points)
    args.input_points = points.n
    with ExitStack() as stack:
        dask = args.dask
        if dask is not None and not dask.startswith("local:"):
            from .tiles.cluster import DEFAULT_CONNECT_TIMEOUT, connect

            timeout = args.dask_timeout or DEFAULT_CONNECT_TIMEOUT
            dask = stack.enter_context(connect(dask, timeout))
        result = _detect(
            points,
            scales=args.scales,
            weighting=args.weighting,
            mode=args.mode,
            progress=progress,
            preprocessing=steps,
            max_memory=args.max_memory,
            dask=dask,
            scratch=args.scratch,
            curves=args.curves is not None,
        )
    t = time.perf_counter()
    write_features_ply(output, points, result.strength, result.mask, into=outputs)
    if args.indices:
        save_indices(args.indices, result.mask, into=outputs)
    _save_curves(args, result, outputs)
    _commit(args, result, points.name, output, outputs, start=start, saving=t)
    progress.close()
    if not args.quiet:
        _print_summary(points.name, output, result)
    return 0


def _load_libraries() -> None:
    """Before the input is read, while memory is free: import the detection's libraries
    (numpy, scipy, pymeshlab, the compiled kernels) and have OpenBLAS map its threads'
    buffers, which it maps at its first matrix product and, when it cannot, ends the
    process with its own message instead of raising MemoryError."""
    import numpy as np

    from . import pipeline  # noqa: F401  (its imports load the libraries)

    block = np.ones((512, 512))
    block @ block


def _quiet_dask() -> None:
    """Keep distributed's log messages (this process's and its workers', which inherit
    the setting) out of the terminal: only critical ones are shown."""
    os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "critical")
    try:
        import distributed  # noqa: F401  (sets its loggers' levels from its config)
    except ImportError:  # the --dask check says which extra to install
        return
    for name in list(logging.root.manager.loggerDict):
        if name == "distributed" or name.startswith("distributed."):
            logging.getLogger(name).setLevel(logging.CRITICAL)


def _commit(
    args: argparse.Namespace,
    result: DetectionResult,
    source: str,
    output: Path,
    outputs: OutputSet,
    *,
    start: float,
    saving: float,
) -> None:
    """Close the timings (``start``: the run's, ``saving``: the writers'), stage the JSON
    report if asked for, then rename every staged output at once."""
    result.timings["save"] = time.perf_counter() - saving
    result.timings["total"] = time.perf_counter() - start
    if args.report:
        from .io import save_json

        report = {"version": __version__, **result.summary()}
        report["input"] = source
        report["outputs"] = {"ply": str(output), "indices": args.indices, "curves": args.curves}
        save_json(args.report, report, into=outputs)
    _pause_for_tests()
    outputs.commit()


def _pause_for_tests() -> None:
    """The :data:`PAUSE_ENV` test hook: hold between staging and renaming."""
    flag = os.environ.get(PAUSE_ENV)
    if not flag:
        return
    Path(flag).touch()
    end = time.monotonic() + 60.0
    while Path(flag).exists() and time.monotonic() < end:
        time.sleep(0.02)


#: Memory of an in-memory run per input point, bytes, for the out-of-memory message:
#: the detection's measured peak above the input (140-190 B/point, README), the input
#: and the output's copy, with a margin.
MEMORY_PER_POINT = 320
#: Memory of the interpreter and the libraries before the input is read, bytes.
MEMORY_BASELINE = 200 << 20


def _out_of_memory(args: argparse.Namespace) -> str:
    """The out-of-memory message: what the input needs (estimated from its points, or
    the file's size before they are counted) and the ``--max-memory`` hint."""
    name = "the sample part" if args.input is None else args.input
    name = name if name.isprintable() else ascii(name)
    n = getattr(args, "input_points", None)
    tiled = args.max_memory is not None or args.dask is not None
    if n is None:
        size = Path(args.input).stat().st_size if args.input else 0
        need = f"reading {name} ({size / 2**20:.0f} MB) did not fit in memory"
    elif tiled:
        need = f"{name} ({n} points) did not fit in the memory left beside its tiles"
    else:
        mb = (MEMORY_BASELINE + n * MEMORY_PER_POINT) / 2**20
        need = f"{name} ({n} points) needs about {mb:.0f} MB of memory"
    if tiled:
        return f"out of memory: {need}; give a smaller --max-memory, or free memory"
    return (
        f"out of memory: {need}; --max-memory SIZE (e.g. --max-memory 500MB) keeps a "
        "point cloud's peak under SIZE"
    )


def _sample_geometry(kind: str) -> Geometry:
    """The built-in sample part as a Geometry (built once, then read from the cache)."""
    from .io import Geometry
    from .sample import sample_part

    part = sample_part(kind, cache=True)
    return Geometry(vertices=part.vertices, faces=part.faces, source=f"sample part ({kind})")


def _check_outputs(source: Path | None, outputs: list[Path], *, own: Path | None = None) -> None:
    """Before any work and any heavy import: no output is the input or another output,
    and the sample part's folder (``out/``, ``own``), if it is missing, can be made.

    The rest is checked when the outputs are claimed (:meth:`OutputSet.claim`): every
    folder exists and is writable, no output is a folder or, without ``--force``, an
    existing file (the files in ``own`` are the tool's own: replaced without it)."""
    resolved = [p.resolve() for p in outputs]
    if len(set(resolved)) != len(resolved):
        raise MeshlabSharpError("two outputs have the same path")
    if source is not None and source.exists() and source.resolve() in resolved:
        raise MeshlabSharpError(f"{source}: an output would overwrite the input")
    for p in outputs:
        try:
            str(p).encode("utf-8")
        except UnicodeEncodeError:
            raise MeshlabSharpError(
                f"cannot write {str(p)!a}: the name is not valid UTF-8; choose another with -o"
            ) from None
    if own is not None and not own.exists():
        folder = own.resolve().parent
        if not os.access(folder, os.W_OK | os.X_OK):
            raise MeshlabSharpError(f"cannot make {own}: the folder {folder} is not writable")


def _print_summary(source: str, output: Path, result: DetectionResult) -> None:
    """One line per scale and a closing line, on stdout."""
    unit = "k" if result.kind == "points" else "ring"
    for s, t, c in zip(result.scales, result.thresholds, result.candidate_counts, strict=True):
        print(f"  {unit} = {s:3d}: threshold {t:.4f}, {c} candidates")
    if result.curves is not None:
        kinds = [c.kind for c in result.curves]
        counts = ", ".join(f"{kinds.count(k)} {k}" for k in sorted(set(kinds)))
        corners = 0 if result.corners is None else len(result.corners)
        print(f"  curves: {len(kinds)} ({counts or 'none'}), {corners} corners")
    n = len(result.mask)
    print(
        f"{source}: {n} {'vertices' if result.kind == 'mesh' else 'points'}, "
        f"{result.mode} mode, "
        f"{result.n_features} sharp features ({100.0 * result.n_features / n:.1f}%) "
        f"-> {output} [{result.timings.get('total', 0.0):.2f} s]"
    )
    if result.tiling is not None:
        tiling = result.tiling
        workers = tiling["worker_peak_bytes"]
        print(
            f"  out of core: {tiling['tiles']} tiles, {tiling['tasks']} tile tasks, peak "
            f"memory {tiling['peak_bytes'] / 2**20:.0f} MB"
            + (f" (workers {workers / 2**20:.0f} MB)" if workers else "")
        )


def _add_preprocessing_arguments(det: argparse.ArgumentParser) -> None:
    """Preprocessing flags (pymeshlab filters, applied in a fixed order) and the picture."""
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
        type=_denoise_method,
        metavar="METHOD",
        help="smooth before detection, unless the input looks clean (skipped with a "
        "warning): meshes taubin (default) or two_steps; point clouds rimls (default) or "
        "apss MLS projection (a warning says when a method did not help in the measured "
        "cases: docs/preprocessing.md)",
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
        action=_Once,
        metavar="FILE.ply",
        help="write the processed geometry (quality = strength, features selected)",
    )
    det.add_argument(
        "--plot",
        action=_Once,
        metavar="FILE.png",
        help="write the report picture: histograms with thresholds, views with the "
        "features (needs matplotlib: pip install 'meshlab-sharp[plot]')",
    )


def _denoise_method(text: str) -> str:
    """``--denoise``'s optional METHOD; a file name there (``--denoise part.ply``, the
    input read as the method) gets a message saying how to write it."""
    if text in DENOISE_METHODS:
        return text
    if Path(text).suffix or os.sep in text:
        raise argparse.ArgumentTypeError(
            f"'{text}' is not a denoising method but looks like a file: give the input "
            f"before --denoise (detect {text} --denoise), or a method: "
            f"{', '.join(DENOISE_METHODS)}"
        )
    raise argparse.ArgumentTypeError(
        f"unknown denoising method '{text}'; choose from {', '.join(DENOISE_METHODS)}"
    )


#: Preprocessing parameters and the options that set them, for messages.
_OPTION_NAMES = {
    "outlier_probability": "--outlier-probability",
    "outlier_neighbours": "--outlier-neighbours",
    "remove_outliers": "--remove-outliers",
    "smoothing_steps": "--smoothing-steps",
    "denoise_method": "--denoise",
    "max_hole_size": "--max-hole-size",
    "fill_holes": "--fill-holes",
    "simplify": "--simplify",
    "denoise": "--denoise",
}
_OPTION_NAME = re.compile(
    r"(?<![\w-])(" + "|".join(sorted(_OPTION_NAMES, key=len, reverse=True)) + r")(?![\w-])"
)


@contextmanager
def _option_names() -> Iterator[None]:
    """Errors of the preprocessing parameters, worded with the options that set them
    (``--denoise 'rimls' is for point clouds``, not ``denoise_method``)."""
    try:
        yield
    except InputError as exc:
        text = _OPTION_NAME.sub(lambda m: _OPTION_NAMES[m.group(1)], str(exc))
        raise InputError(text.removeprefix("preprocessing: ")) from None


def _preprocessing_from_args(args: argparse.Namespace) -> Preprocessing | None:
    """The Preprocessing the flags ask for (None when none); checks the extra outputs."""
    steps = None
    if args.remove_outliers or args.denoise or args.fill_holes or args.simplify is not None:
        from .preprocessing import Preprocessing

        with _option_names():
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
        if steps is None:
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
    return steps


def _print_warnings(result: DetectionResult) -> None:
    """The preprocessing steps' warnings, one line each on stderr."""
    if result.preprocessing is not None:
        for step in result.preprocessing.steps:
            if "warning" in step:
                print(f"meshlab-sharp: warning: {step['warning']}", file=sys.stderr)


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
