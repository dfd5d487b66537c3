#!/usr/bin/env python3
"""Benchmark meshlab_sharp.detect stage by stage on CAD-like inputs it builds itself.

Inputs (seeded): a point cloud sampled uniformly on the surface of a union of boxes and
cylinders (a machined part: planes, cylinders, convex and concave edges), and a mesh,
a box whose faces are regular grids (welded by cleaning) with a few steps on top.
Each size runs in a fresh subprocess, so that its peak resident memory
(``VmHWM``, which sees C allocations, unlike tracemalloc, and unlike ``ru_maxrss`` is
not inherited from the parent: ``meshlab_sharp.tiles.run.peak_rss``) is its own; the baseline
(interpreter, imports, the input arrays) is measured in the same process before
detection, the high-water mark reset there to the resident memory, and subtracted.

Stages, timed separately: load (a binary PLY written beforehand, read with
meshlab_sharp.io.load), clean, neighbourhoods, normals + projected distance, threshold
(normalisation, Otsu, candidates, decision), save (a PLY with the mask and strength).
``detect`` end to end is timed too, on the in-memory arrays, in each ``--mode`` (paper,
robust or both, run back to back in each repeat): "cold" is the first call in the
process, "warm" the best of the repeats, "cpu" the best process CPU time (user + system,
every thread: steadier than wall time on a shared machine). The stages are paper mode's.

    python3 scripts/bench.py --sizes 100k,1M --repeat 3 --json out/bench.json
    python3 scripts/bench.py --sizes 1M --kind mesh --backend numpy
    python3 scripts/bench.py --sizes 1M --kind points --mode both --repeat 2
    python3 scripts/bench.py --sizes 1M --kind shuffled --mode both --repeat 4

``--compare`` runs one size side by side instead: the CLI and the MeshLab
plugin under meshlabserver on the same float PLY, in both modes, with the plugin/CLI
ratio; ``detect`` on the same points in memory against pgeof's kNN (k = 40) plus its
multiscale features at the same 8 scales (``pip install 'meshlab-sharp[bench]'``),
with the ratio; and the compiled kernels' pieces of the cloud path timed alone:

    python3 scripts/bench.py --compare --sizes 1M --repeat 2 --json out/compare.json
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import _venv  # scripts/, the script's own folder, is on sys.path

_venv.enter()

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# ----------------------------------------------------------------------------- inputs

#: Boxes (lo, hi) and z-axis cylinders (cx, cy, r, z0, z1) of the part, in mm.
BOXES = [
    ((0.0, 0.0, 0.0), (100.0, 60.0, 20.0)),
    ((10.0, 10.0, 20.0), (45.0, 50.0, 35.0)),
    ((60.0, -10.0, 5.0), (90.0, 5.0, 15.0)),
]
CYLINDERS = [
    (72.0, 30.0, 14.0, 20.0, 45.0),
    (27.5, 30.0, 8.0, 35.0, 50.0),
]


def _inside(p: np.ndarray, skip: int) -> np.ndarray:
    """True for points strictly inside a primitive other than number ``skip``."""
    out = np.zeros(len(p), dtype=bool)
    for i, (lo, hi) in enumerate(BOXES):
        if i != skip:
            out |= np.all((p > np.array(lo)) & (p < np.array(hi)), axis=1)
    for j, (cx, cy, r, z0, z1) in enumerate(CYLINDERS):
        if len(BOXES) + j != skip:
            d2 = (p[:, 0] - cx) ** 2 + (p[:, 1] - cy) ** 2
            out |= (d2 < r * r) & (p[:, 2] > z0) & (p[:, 2] < z1)
    return out


def _sample_box(rng: np.random.Generator, lo, hi, m: int) -> np.ndarray:
    lo, hi = np.array(lo), np.array(hi)
    size = hi - lo
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    face = rng.choice(6, size=m, p=areas / areas.sum())
    p = lo + rng.random((m, 3)) * size
    axis, side = face // 2, face % 2
    p[np.arange(m), axis] = np.where(side == 1, hi[axis], lo[axis])
    return p


def _sample_cylinder(rng: np.random.Generator, cx, cy, r, z0, z1, m: int) -> np.ndarray:
    side, cap = 2 * np.pi * r * (z1 - z0), np.pi * r * r
    kind = rng.choice(3, size=m, p=np.array([side, cap, cap]) / (side + 2 * cap))
    t = rng.random(m) * 2 * np.pi
    rad = np.where(kind == 0, r, r * np.sqrt(rng.random(m)))
    z = np.where(kind == 0, z0 + rng.random(m) * (z1 - z0), np.where(kind == 1, z0, z1))
    return np.column_stack([cx + rad * np.cos(t), cy + rad * np.sin(t), z])


def cad_cloud(n: int, seed: int = 0) -> np.ndarray:
    """``n`` points sampled uniformly on the surface of the union of BOXES and CYLINDERS
    (samples of one primitive inside another are dropped). (n, 3) float64."""
    rng = np.random.default_rng(seed)
    areas = []
    for lo, hi in BOXES:
        s = np.array(hi) - np.array(lo)
        areas.append(2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]))
    for _, _, r, z0, z1 in CYLINDERS:
        areas.append(2 * np.pi * r * (z1 - z0) + 2 * np.pi * r * r)
    areas = np.array(areas)
    chunks, total, want = [], 0, n
    while total < n:
        m = int(want * 1.6) + 1000
        per = rng.multinomial(m, areas / areas.sum())
        for i, k in enumerate(per):
            if i < len(BOXES):
                p = _sample_box(rng, *BOXES[i], k)
            else:
                p = _sample_cylinder(rng, *CYLINDERS[i - len(BOXES)], k)
            chunks.append(p[~_inside(p, i)])
        total = sum(len(c) for c in chunks)
        want = n - total
    cloud = np.concatenate(chunks)
    return cloud[rng.permutation(len(cloud))[:n]]


def shuffled_mesh(n: int, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """:func:`cad_mesh` with its vertices in a random order (faces kept in order, their
    corners renumbered): a vertex order without locality, as a scan's or a remesher's,
    where the grid-numbered bench mesh reads memory in order."""
    vertices, faces = cad_mesh(n)
    perm = np.random.default_rng(seed).permutation(len(vertices))
    rank = np.empty_like(perm)
    rank[perm] = np.arange(len(vertices))
    return vertices[perm], rank[faces]


def cad_mesh(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed box mesh of about ``n`` vertices: each face a regular m x m grid of
    triangles, faces stored separately (their shared edges are merged by cleaning), and
    the top face carved into steps (height field). (v, 3) float64, (f, 3) int64."""
    m = max(3, round(float(np.sqrt(n / 6.0))))
    g = np.linspace(0.0, 1.0, m)
    verts, faces, base = [], [], 0
    a, b = np.meshgrid(g, g, indexing="ij")
    quad = np.arange(m * m).reshape(m, m)
    q00, q10, q01, q11 = quad[:-1, :-1], quad[1:, :-1], quad[:-1, 1:], quad[1:, 1:]
    tri = np.concatenate(
        [np.stack([q00, q10, q11], -1).reshape(-1, 3), np.stack([q00, q11, q01], -1).reshape(-1, 3)]
    )
    for axis in range(3):
        others = [i for i in range(3) if i != axis]
        for side in (0.0, 1.0):
            p = np.empty((m * m, 3))
            p[:, axis] = side
            p[:, others[0]] = a.ravel()
            p[:, others[1]] = b.ravel()
            t = tri if side == 1.0 else tri[:, ::-1]
            verts.append(p)
            faces.append(t + base)
            base += m * m
    v = np.concatenate(verts)
    top = v[:, 2] == 1.0
    inner = top & (v[:, 0] > 0) & (v[:, 0] < 1) & (v[:, 1] > 0) & (v[:, 1] < 1)
    steps = np.floor(v[:, 0] * 4) / 4 * 0.2 + (v[:, 1] > 0.5) * 0.1
    v[inner, 2] = 1.0 + steps[inner]
    return v, np.concatenate(faces)


def parse_size(text: str) -> int:
    text = text.strip().lower()
    mult = {"k": 1_000, "m": 1_000_000}.get(text[-1:], 1)
    return int(float(text[:-1] if text[-1:] in "km" else text) * mult)


# ----------------------------------------------------------------------------- one size


def _rss_bytes() -> int:
    from meshlab_sharp.tiles.run import peak_rss

    return peak_rss()


def _reset_peak() -> None:
    """Start the high-water mark (``VmHWM``) afresh at the current resident memory
    (Linux: ``/proc/self/clear_refs``), so that a peak measured from here is not hidden
    under an earlier one: building the inputs peaks above what stays once their
    temporaries are freed, and a baseline taken as that earlier peak makes detect's
    peak look smaller by the difference (on the 1M cloud in the default mode: 69 B a
    point without the reset, 165 with it, for the same code). Where it cannot (another
    system), the earlier peak stays in."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:
        pass


def _cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _system_seconds() -> float:
    """Kernel time of this process: mostly first touches of fresh pages (zeroing, and on
    a virtual machine that hands freed memory back to its host, the host's faults)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_stime


def run_one(
    n: int, kind: str, backend: str, repeat: int, workdir: Path, modes: tuple[str, ...]
) -> dict:
    """All stages on one input, in this process (call in a fresh subprocess)."""
    from meshlab_sharp import _kernels
    from meshlab_sharp.cleaning import clean
    from meshlab_sharp.io import Geometry, load, save_features_ply
    from meshlab_sharp.multiscale import (
        DEFAULT_KNN_SCALES,
        DEFAULT_RING_SCALES,
        decide,
        projected_distances_all,
    )
    from meshlab_sharp.neighbourhoods import build_neighbourhoods
    from meshlab_sharp.normals import face_average_normals
    from meshlab_sharp.pipeline import detect
    from meshlab_sharp.threshold import FLAT_TOLERANCE, normalise, otsu_threshold

    if kind == "points":
        vertices, faces = cad_cloud(n), None
        scales = DEFAULT_KNN_SCALES
    else:
        vertices, faces = cad_mesh(n) if kind == "mesh" else shuffled_mesh(n)
        scales = DEFAULT_RING_SCALES
    n_in = len(vertices)
    _reset_peak()
    baseline = _rss_bytes()
    out: dict = {"kind": kind, "n": n_in, "backend": backend, "workers": _kernels._workers(-1)}

    # End to end on in-memory arrays, the modes back to back in each repeat: the
    # first call is cold (page faults, thread pool, first use of the library).
    walls: dict[str, list[float]] = {m: [] for m in modes}
    cpus: dict[str, list[float]] = {m: [] for m in modes}
    systems: dict[str, list[float]] = {m: [] for m in modes}
    peak_detect = 0
    out["detect"] = {}
    for _ in range(repeat):
        for mode in modes:
            t, c, k = time.perf_counter(), _cpu_seconds(), _system_seconds()
            result = detect(vertices, faces, mode=mode, backend=backend)
            walls[mode].append(time.perf_counter() - t)
            cpus[mode].append(_cpu_seconds() - c)
            systems[mode].append(_system_seconds() - k)
            peak_detect = max(peak_detect, _rss_bytes())
            out["detect"][mode] = {
                "n_features": int(result.n_features),
                "scales": list(result.scales),
                "thresholds": [float(t) for t in result.thresholds],
            }
            del result
    for mode in modes:
        totals = walls[mode]
        warm = min(totals[1:]) if len(totals) > 1 else totals[0]
        out["detect"][mode].update(
            cold_s=totals[0],
            warm_s=warm,
            cpu_s=min(cpus[mode]),
            points_per_s=n_in / warm,
            walls_s=totals,
            system_s=systems[mode],
        )
    out["peak_bytes_above_input"] = peak_detect - baseline
    out["peak_bytes_per_point"] = (peak_detect - baseline) / n_in

    # Stage by stage (best of the repeats).
    import pymeshlab

    path = workdir / f"in_{kind}_{n_in}.ply"
    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(vertex_matrix=vertices)
        if faces is None
        else pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces.astype(np.int32))
    )
    ms.save_current_mesh(str(path), binary=True)
    del ms
    stages: dict[str, list[float]] = {}

    def timed(name, fn):
        t = time.perf_counter()
        value = fn()
        stages.setdefault(name, []).append(time.perf_counter() - t)
        return value

    for _ in range(repeat):
        geometry = timed("load", lambda: load(path))
        g = geometry if faces is not None else Geometry(geometry.vertices, None, "bench")
        cleaned = timed("clean", lambda g=g: clean(g, backend=backend))
        pts = cleaned.vertices

        def neighbourhoods(pts=pts, cleaned=cleaned):
            nb = build_neighbourhoods(pts, cleaned.faces, scales, backend=backend)
            tri = cleaned.faces
            nrm = None if tri is None else face_average_normals(pts, tri, backend=backend)
            return nb, nrm

        nb, nrm = timed("neighbourhoods", neighbourhoods)

        pdis = timed(
            "normals_projected_distance",
            lambda pts=pts, nb=nb, nrm=nrm: projected_distances_all(pts, nb, scales, normals=nrm),
        )
        flat = FLAT_TOLERANCE * float(np.linalg.norm(np.ptp(pts, axis=0)))

        def threshold(pdis=pdis, flat=flat, m=pts.shape[0]):
            votes = np.zeros(m, dtype=np.int64)
            for raw in pdis:
                v = normalise(raw, flat_span=flat)
                votes += v >= otsu_threshold(v)
            return decide(votes, len(scales))

        mask, strength = timed("threshold", threshold)
        result_mask = cleaned.to_input_order(mask, False)
        result_strength = cleaned.to_input_order(strength, 0.0)

        timed(
            "save",
            lambda geometry=geometry, m=result_mask, s=result_strength: save_features_ply(
                workdir / "out.ply", geometry.vertices, geometry.faces, s, m
            ),
        )
        del nb, pdis
    out["stages_s"] = {k: min(v) for k, v in stages.items()}
    out["stages_points_per_s"] = {k: n_in / max(v, 1e-9) for k, v in out["stages_s"].items()}
    out["peak_bytes_per_point_all_stages"] = (_rss_bytes() - baseline) / n_in
    return out


# ----------------------------------------------------------------------------- driver


# ----------------------------------------------------------------- out of core, Dask


#: Points per block of the benchmark clouds above this size (each block a seeded
#: cad_cloud of its own), so that a 100M-point cloud is never whole in memory.
BLOCK = 10_000_000


def cloud_blocks(n: int) -> Iterator[np.ndarray]:
    """The benchmark cloud of ``n`` points: cad_cloud(n) up to BLOCK points, above
    that cad_cloud(BLOCK, seed=i) blocks (the last one shorter), (c, 3) float64."""
    for i, start in enumerate(range(0, n, BLOCK)):
        yield cad_cloud(min(BLOCK, n - start), seed=i)


def write_cloud_ply(path: Path, n: int) -> None:
    """A binary PLY of double x, y, z of the benchmark cloud of ``n`` points (what the
    tiled runs memory-map), written block by block."""
    header = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\n"
        "property double x\nproperty double y\nproperty double z\nend_header\n"
    )
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        for points in cloud_blocks(n):
            for s in range(0, len(points), 1 << 20):
                fh.write(np.ascontiguousarray(points[s : s + (1 << 20)], "<f8").tobytes())
            del points


def run_tiled_one(path: Path, mode: str, how: str, out: Path, tile_points: int) -> dict:
    """One detection of the cloud at ``path`` in this process (call in a fresh
    subprocess): ``how`` is "memory", "tiled:SIZE", "dask:SIZE:CLUSTER" or
    "dask-same:CLUSTER" (Dask with ``tile_points`` per tile: the tiles of the previous
    out-of-core run, for a fair comparison). The mask, strength and thresholds go to
    ``out`` (.npz) for the comparison."""
    import meshlab_sharp
    from meshlab_sharp.io.stream import open_points
    from meshlab_sharp.multiscale import DEFAULT_KNN_SCALES
    from meshlab_sharp.tiles import detect_tiled

    kwargs: dict = {}
    if how.startswith("tiled:"):
        kwargs["max_memory"] = how.split(":", 1)[1]
    elif how.startswith("dask:"):
        _, size, cluster = how.split(":", 2)
        kwargs.update(max_memory=size, dask=cluster)
    t, cpu = time.perf_counter(), _cpu_seconds()
    if how.startswith("dask-same:"):
        got = detect_tiled(
            open_points(path),
            scales=DEFAULT_KNN_SCALES,
            mode=mode,
            tile_points=tile_points,
            dask=how.split(":", 1)[1],
        )
        mask, strength, thresholds = got["mask"], got["strength"], got["thresholds"]
        tiling, timings = got["tiling"], got["timings"]
    else:
        result = meshlab_sharp.detect(str(path), mode=mode, **kwargs)
        mask, strength, thresholds = result.mask, result.strength, result.thresholds
        tiling, timings = result.tiling or {}, result.timings
    seconds = time.perf_counter() - t
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    np.savez(out, mask=mask, strength=strength, thresholds=thresholds)
    return {
        "n": len(mask),
        "mode": mode,
        "how": how,
        "seconds": seconds,
        "cpu_s": _cpu_seconds() - cpu,
        "children_cpu_s": children.ru_utime + children.ru_stime,
        "points_per_s": len(mask) / seconds,
        "peak_bytes": _rss_bytes(),
        "worker_peak_bytes": int(tiling.get("worker_peak_bytes", 0)),
        "tiles": tiling.get("tiles"),
        "tile_points": tiling.get("tile_points"),
        "features": int(mask.sum()),
        "timings": {k: float(v) for k, v in timings.items()},
    }


def bench_tiled(sizes: list[int], modes: list[str], hows: list[str], out_json: str) -> int:
    """In-memory, tiled and Dask runs of each size and mode; checks they agree."""
    results = []
    with tempfile.TemporaryDirectory(prefix="meshlab_sharp_bench_") as tmp:
        for size in sizes:
            path = Path(tmp) / f"cloud_{size}.ply"
            write_cloud_ply(path, size)
            for mode in modes:
                first, tile_points = None, 0
                for how in hows:
                    npz = Path(tmp) / f"r_{size}_{mode}_{len(results)}.npz"
                    cmd = [sys.executable, __file__, "--tiled-one", str(path), mode, how, str(npz)]
                    cmd.append(str(tile_points))
                    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
                    if proc.returncode != 0:
                        print(proc.stderr, file=sys.stderr)
                        return proc.returncode
                    r = json.loads(proc.stdout.strip().splitlines()[-1])
                    tile_points = r["tile_points"] or tile_points
                    got = np.load(npz)
                    if first is None:
                        first = got
                    r["identical_to_first"] = all(
                        np.array_equal(got[k], first[k]) for k in ("mask", "strength", "thresholds")
                    )
                    r["load_average"] = os.getloadavg()[0]
                    results.append(r)
                    mb = (r["peak_bytes"] / 2**20, r["worker_peak_bytes"] / 2**20)
                    print(
                        f"{mode:6s} n={r['n']:>11,d} {how:24s} {r['seconds']:8.1f} s "
                        f"{r['points_per_s'] / 1e3:7.0f}k pts/s peak {mb[0]:6.0f} MB"
                        f" workers {mb[1]:6.0f} MB tiles {r['tiles']} "
                        f"identical {r['identical_to_first']} load {r['load_average']:.1f}",
                        flush=True,
                    )
                    steps = {k: round(v, 1) for k, v in r["timings"].items()}
                    print(f"       cpu {r['cpu_s']:.0f} s, timings {steps}", flush=True)
                    Path(out_json).parent.mkdir(parents=True, exist_ok=True)
                    Path(out_json).write_text(json.dumps({"results": results}, indent=1))
            path.unlink()
    Path(out_json).parent.mkdir(parents=True, exist_ok=True)
    Path(out_json).write_text(json.dumps({"results": results, "cpus": os.cpu_count()}, indent=1))
    print(f"wrote {out_json}")
    return 0


# ------------------------------------------- side by side: CLI, MeshLab plugin, pgeof


def write_float_ply(path: Path, points: np.ndarray) -> None:
    """A binary PLY of float x, y, z: what MeshLab and the CLI both read."""
    header = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(points)}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    )
    path.write_bytes(header.encode("ascii") + np.ascontiguousarray(points, "<f4").tobytes())


@contextmanager
def xvfb_display() -> Iterator[dict[str, str]]:
    """One Xvfb server for every meshlabserver run (which needs an X display even for a
    filter without GL), so that no run pays its start: the environment to run them in."""
    display = next(d for d in range(90, 400) if not Path(f"/tmp/.X{d}-lock").exists())
    command = ["Xvfb", f":{display}", "-screen", "0", "1280x1024x24", "-nolisten", "tcp"]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 20
        while not Path(f"/tmp/.X11-unix/X{display}").exists():
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("Xvfb did not start")
            time.sleep(0.1)
        yield dict(os.environ, DISPLAY=f":{display}")
    finally:
        proc.terminate()
        proc.wait()


def _timed_run(command: list[str], env: dict[str, str] | None = None) -> tuple[float, str]:
    """Wall seconds of a command and its output; raises when it fails."""
    t = time.perf_counter()
    proc = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    seconds = time.perf_counter() - t
    if proc.returncode != 0:
        raise RuntimeError(f"{command[0]} failed:\n{proc.stdout}\n{proc.stderr}")
    return seconds, proc.stdout + proc.stderr


def time_cli(path: Path, work: Path, mode: str, repeat: int) -> dict:
    """``meshlab-sharp detect`` on the PLY, end to end (interpreter start included); the
    stages of the best run from its --report."""
    best: dict = {"wall_s": float("inf")}
    for _ in range(repeat):
        report = work / "cli_report.json"
        command = [sys.executable, "-m", "meshlab_sharp", "detect", str(path), "-q", "--force"]
        command += ["-o", str(work / "cli_out.ply"), "--mode", mode, "--report", str(report)]
        seconds, _ = _timed_run(command, env=dict(os.environ, PYTHONPATH=str(ROOT)))
        if seconds < best["wall_s"]:
            summary = json.loads(report.read_text())
            best = {"wall_s": seconds, "stages_s": summary["timings_s"]}
            best["features"] = summary["n_features"]
    return best


def time_plugin(root: Path, path: Path, work: Path, mode: str, repeat: int, env: dict) -> dict:
    """The filter under the private MeshLab ``root``'s meshlabserver on the PLY, end to
    end (load, filter, save of quality, flags and colour), and meshlabserver loading and
    saving the same file without the filter; the filter's own time from its log."""
    script = (ROOT / "meshlab_plugin_cpp" / "examples" / "sharp_features_default.mlx").read_text()
    value = "0" if mode == "paper" else "1"
    script = re.sub(r'value="[^"]*" name="mode"', f'value="{value}" name="mode"', script)
    mlx = work / f"{mode}.mlx"
    mlx.write_text(script)

    def server(out: str, *script: str) -> list[str]:
        command = [str(root / "bin" / "meshlabserver"), "-i", str(path), "-o", str(work / out)]
        return [*command, "-m", "vq", "vf", "vc", *script]

    best: dict = {"wall_s": float("inf")}
    for _ in range(repeat):
        seconds, log = _timed_run(server("ml_out.ply", "-s", str(mlx)), env)
        if seconds < best["wall_s"]:
            took = re.search(r"detection took ([0-9.]+) s", log)
            count = re.search(r"(\d+) of \d+ vertices are features", log)
            best = {"wall_s": seconds, "filter_s": float(took.group(1)) if took else None}
            best["features"] = int(count.group(1)) if count else None
            stages = re.search(r"detection took [0-9.]+ s \(([^)]*)\)", log)
            best["stages_s"] = (
                {
                    name: float(seconds)
                    for name, seconds in re.findall(r"([a-z -]+) ([0-9.]+) s", stages.group(1))
                }
                if stages
                else {}
            )
            # meshlabserver prints each new progress message of the filter
            best["progress"] = [int(p) for p in re.findall(r"Sharp features: [a-z -]+ (\d+)%", log)]
    best["load_save_only_s"] = min(_timed_run(server("ml_io.ply"), env)[0] for _ in range(repeat))
    return best


def time_pgeof(points: np.ndarray, scales: tuple[int, ...], repeat: int) -> dict | None:
    """pgeof (PyPI, the ``bench`` extra): its kNN at k = max(scales) and its multiscale
    features at every scale on the same points; None when it is not installed. Beside
    it, the same kNN by scipy's cKDTree on every core (``scipy_knn_s``): pgeof's own
    search runs on one thread, so its kNN plus features is a generous yardstick, and
    scipy's kNN plus pgeof's features a strict one."""
    try:
        import pgeof
    except ImportError:
        return None
    from scipy.spatial import cKDTree

    xyz = np.ascontiguousarray(points, np.float32)
    k = max(scales)
    best = {"knn_s": float("inf"), "features_s": float("inf"), "scipy_knn_s": float("inf")}
    for _ in range(repeat):
        t = time.perf_counter()
        cKDTree(xyz).query(xyz, k, workers=-1)
        best["scipy_knn_s"] = min(best["scipy_knn_s"], time.perf_counter() - t)
        t = time.perf_counter()
        nn, _ = pgeof.knn_search(xyz, xyz, k)
        knn_s = time.perf_counter() - t
        ptr = np.arange(len(xyz) + 1, dtype=np.uint32) * k
        t = time.perf_counter()
        pgeof.compute_features_multiscale(xyz, nn.reshape(-1), ptr, list(scales))
        best["knn_s"] = min(best["knn_s"], knn_s)
        best["features_s"] = min(best["features_s"], time.perf_counter() - t)
        del nn
    best["total_s"] = best["knn_s"] + best["features_s"]
    best["strict_total_s"] = best["scipy_knn_s"] + best["features_s"]
    return best


def profile_detect(points: np.ndarray, modes: tuple[str, ...], repeat: int) -> dict:
    """``detect`` on the in-memory points per mode (best of ``repeat`` after a warm-up),
    its stage timings, and the compiled kernels' pieces of the cloud path timed alone."""
    from meshlab_sharp import _kernels
    from meshlab_sharp.multiscale import DEFAULT_KNN_SCALES
    from meshlab_sharp.pipeline import detect
    from meshlab_sharp.robust import NOISE_KNN

    out: dict = {"detect": {}}
    detect(points[:20000])  # warm-up: library, thread pool
    for mode in modes:
        best: dict = {"wall_s": float("inf")}
        for _ in range(repeat):
            t = time.perf_counter()
            result = detect(points, mode=mode)
            seconds = time.perf_counter() - t
            if seconds < best["wall_s"]:
                best = {"wall_s": seconds, "stages_s": dict(result.timings)}
        out["detect"][mode] = best
    pieces: dict[str, list[float]] = {}

    def timed(name, fn):
        t = time.perf_counter()
        value = fn()
        pieces.setdefault(name, []).append(time.perf_counter() - t)
        return value

    for _ in range(repeat):
        tree = timed("kd-tree build", lambda: _kernels.build_tree(points))
        timed("kNN k=40 alone", lambda tree=tree: _kernels.cloud_knn(tree, 40))
        timed(
            "kNN + 8 scales PCA + pdis (paper pass)",
            lambda tree=tree: _kernels.cloud_projected_distances(tree, DEFAULT_KNN_SCALES),
        )
        timed(
            "same + local scales, noise, isolation stats (robust pass)",
            lambda tree=tree: _kernels.cloud_projected_distances(
                tree, DEFAULT_KNN_SCALES, relative=True, noise_k=NOISE_KNN
            ),
        )
    out["kernels_s"] = {k: min(v) for k, v in pieces.items()}
    return out


def bench_compare(n: int, repeat: int, meshlab_root: str | None, out_json: str) -> int:
    """One run, side by side on the same ``n``-point cloud: the CLI and the MeshLab plugin
    on one PLY (both modes), this package's detect and pgeof on the same points."""
    from meshlab_sharp.cli import main as cli_main
    from meshlab_sharp.multiscale import DEFAULT_KNN_SCALES

    modes = ("paper", "robust")
    points = cad_cloud(n).astype(np.float32).astype(np.float64)  # what the PLY holds
    result: dict = {"n": n, "cpus": os.cpu_count(), "load_before": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory(prefix="meshlab_sharp_compare_") as tmp:
        work = Path(tmp)
        path = work / "cloud.ply"
        write_float_ply(path, points)
        root = Path(meshlab_root) if meshlab_root else work / "meshlab"
        if not meshlab_root:
            code = cli_main(["plugin", "install", "--root", str(root / "root"), "--no-apt"]
                            + ["--build-dir", str(root / "build")])  # fmt: skip
            if code != 0:
                return code
            root = root / "root"
        result["cli"] = {m: time_cli(path, work, m, repeat) for m in modes}
        with xvfb_display() as env:
            result["plugin"] = {m: time_plugin(root, path, work, m, repeat, env) for m in modes}
    result["this"] = profile_detect(points, modes, repeat)
    result["pgeof"] = time_pgeof(points, DEFAULT_KNN_SCALES, repeat)
    result["load_after"] = os.getloadavg()[0]
    _print_compare(result)
    print(markdown_compare(result))
    Path(out_json).parent.mkdir(parents=True, exist_ok=True)
    Path(out_json).write_text(json.dumps(result, indent=1))
    print(f"wrote {out_json}")
    return 0


def _print_compare(r: dict) -> None:
    print(f"{r['n']:,d} points, {r['cpus']} CPUs, load {r['load_before']:.1f}")
    pg = r["pgeof"]
    for mode in ("paper", "robust"):
        cli, plug = r["cli"][mode], r["plugin"][mode]
        this = r["this"]["detect"][mode]["wall_s"]
        print(
            f"  {mode:6s} CLI {cli['wall_s']:.2f} s ({cli['features']} features), plugin "
            f"{plug['wall_s']:.2f} s (filter {plug['filter_s']:.2f} s, {plug['features']} "
            f"features; meshlabserver load + save alone {plug['load_save_only_s']:.2f} s): "
            f"plugin / CLI {plug['wall_s'] / cli['wall_s']:.2f}; "
            f"{len(plug['progress'])} progress updates"
        )
        line = f"         detect in memory {this:.2f} s"
        if pg is not None:
            line += (
                f", pgeof kNN + features {pg['total_s']:.2f} s: ratio {this / pg['total_s']:.2f}"
                f"; scipy's kNN + pgeof's features {pg['strict_total_s']:.2f} s: ratio "
                f"{this / pg['strict_total_s']:.2f}"
            )
        print(line)
    if pg is not None:
        print(
            f"  pgeof: kNN k=40 {pg['knn_s']:.2f} s, 8-scale features {pg['features_s']:.2f} s;"
            f" scipy cKDTree kNN k=40 on every core {pg['scipy_knn_s']:.2f} s"
        )
    for name, seconds in r["this"]["kernels_s"].items():
        print(f"  kernel: {name} {seconds:.2f} s")


def markdown_compare(r: dict) -> str:
    """The side-by-side run as the tables of docs/benchmark.md."""
    pg = r["pgeof"]
    rows = [
        ("CLI `meshlab-sharp detect` on the PLY, end to end", lambda m: r["cli"][m]["wall_s"]),
        ("plugin under meshlabserver on the PLY, end to end", lambda m: r["plugin"][m]["wall_s"]),
        ("**plugin / CLI**", lambda m: r["plugin"][m]["wall_s"] / r["cli"][m]["wall_s"]),
        ("  the filter alone (its log)", lambda m: r["plugin"][m]["filter_s"]),
        ("  meshlabserver load + save alone", lambda m: r["plugin"][m]["load_save_only_s"]),
        ("`detect` on the points in memory", lambda m: r["this"]["detect"][m]["wall_s"]),
    ]
    if pg is not None:
        rows.append(("pgeof kNN k=40 + 8-scale features", lambda m: pg["total_s"]))
        rows.append(
            ("**detect / pgeof**", lambda m: r["this"]["detect"][m]["wall_s"] / pg["total_s"])
        )
        rows.append(("scipy's kNN (every core) + pgeof's features", lambda m: pg["strict_total_s"]))
        rows.append(
            (
                "**detect / (scipy's kNN + pgeof's features)**",
                lambda m: r["this"]["detect"][m]["wall_s"] / pg["strict_total_s"],
            )
        )
    lines = ["| 1M-point cloud | paper | robust (default) |", "|---|---:|---:|"]
    for name, value in rows:
        ratio = name.startswith("**")
        cells = [f"{value(m):.2f}" if ratio else f"{value(m):.2f} s" for m in ("paper", "robust")]
        lines.append(f"| {name} | {cells[0]} | {cells[1]} |")
    features = [
        f"{r['cli'][m]['features']} / {r['plugin'][m]['features']}" for m in ("paper", "robust")
    ]
    lines.append(f"| features: CLI / plugin | {features[0]} | {features[1]} |")
    lines += ["", "| stage (`detect` in memory) | paper | robust |", "|---|---:|---:|"]
    stages = r["this"]["detect"]
    for stage in stages["paper"]["stages_s"]:
        cells = [f"{stages[m]['stages_s'].get(stage, 0.0):.2f} s" for m in ("paper", "robust")]
        lines.append(f"| {stage} | {cells[0]} | {cells[1]} |")
    lines += ["", "| stage (the plugin's filter, its log) | paper | robust |", "|---|---:|---:|"]
    plugin = {m: r["plugin"][m]["stages_s"] for m in ("paper", "robust")}
    for stage in dict.fromkeys([*plugin["paper"], *plugin["robust"]]):
        cells = [f"{plugin[m][stage]:.2f} s" if stage in plugin[m] else "" for m in plugin]
        lines.append(f"| {stage.strip()} | {cells[0]} | {cells[1]} |")
    lines += ["", "| compiled kernel, alone | time |", "|---|---:|"]
    lines += [f"| {name} | {seconds:.2f} s |" for name, seconds in r["this"]["kernels_s"].items()]
    if pg is not None:
        lines.append(f"| pgeof kNN k=40 | {pg['knn_s']:.2f} s |")
        lines.append(f"| pgeof 8-scale features | {pg['features_s']:.2f} s |")
        lines.append(f"| scipy cKDTree kNN k=40, every core | {pg['scipy_knn_s']:.2f} s |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="100k,1M", help="comma-separated, e.g. 100k,1M,5M,20M")
    ap.add_argument(
        "--kind",
        choices=["points", "mesh", "shuffled", "both"],
        default="both",
        help="shuffled: the bench mesh with its vertices in a random order (not in both)",
    )
    ap.add_argument("--backend", choices=["compiled", "numpy"], default="compiled")
    ap.add_argument("--mode", choices=["paper", "robust", "both"], default="both")
    ap.add_argument("--repeat", type=int, default=3, help="runs per size (best is reported)")
    ap.add_argument("--json", default="out/bench.json", help="where to write the results")
    ap.add_argument("--one", nargs=3, metavar=("N", "KIND", "WORKDIR"), help=argparse.SUPPRESS)
    ap.add_argument(
        "--tiled",
        metavar="RUNS",
        help="out-of-core benchmark instead: comma-separated runs among memory, "
        "tiled:SIZE, dask:SIZE:CLUSTER, dask-same:CLUSTER (the previous run's tiles) "
        "(e.g. memory,tiled:1GB,dask-same:local:2)",
    )
    ap.add_argument("--modes", default="paper,robust", help="modes of the --tiled runs")
    ap.add_argument("--tiled-one", nargs=5, help=argparse.SUPPRESS)
    ap.add_argument(
        "--compare",
        action="store_true",
        help="side by side on the first size instead: the CLI and the MeshLab plugin on one "
        "PLY, detect and pgeof (if installed) on the same points",
    )
    ap.add_argument(
        "--meshlab-root",
        help="private MeshLab root with the plugin (meshlab-sharp plugin install --root); "
        "default: build one for the run",
    )
    args = ap.parse_args(argv)

    if args.compare:
        size = parse_size(args.sizes.split(",")[0])
        return bench_compare(size, args.repeat, args.meshlab_root, args.json)

    if args.tiled_one:
        path, mode, how, out, tile_points = args.tiled_one
        print(json.dumps(run_tiled_one(Path(path), mode, how, Path(out), int(tile_points))))
        return 0
    if args.tiled:
        sizes = [parse_size(s) for s in args.sizes.split(",")]
        hows = _split_runs(args.tiled)
        return bench_tiled(sizes, args.modes.split(","), hows, args.json)

    if args.one:
        n, kind, workdir = int(args.one[0]), args.one[1], Path(args.one[2])
        modes = ("paper", "robust") if args.mode == "both" else (args.mode,)
        print(json.dumps(run_one(n, kind, args.backend, args.repeat, workdir, modes)))
        return 0

    kinds = ["points", "mesh"] if args.kind == "both" else [args.kind]
    results = []
    with tempfile.TemporaryDirectory(prefix="meshlab_sharp_bench_") as tmp:
        for size in [parse_size(s) for s in args.sizes.split(",")]:
            for kind in kinds:
                cmd = [
                    sys.executable, __file__, "--one", str(size), kind, tmp,
                    "--backend", args.backend, "--repeat", str(args.repeat),
                    "--mode", args.mode,
                ]  # fmt: skip
                proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
                if proc.returncode != 0:
                    print(proc.stderr, file=sys.stderr)
                    return proc.returncode
                r = json.loads(proc.stdout.strip().splitlines()[-1])
                results.append(r)
                _print(r)
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps({"results": results, "cpus": os.cpu_count()}, indent=1))
    print(f"wrote {args.json}")
    return 0


def _split_runs(text: str) -> list[str]:
    """ "memory,tiled:1GB,dask:1GB:local:2" -> its runs (a Dask cluster may hold a comma
    only in a tcp:// address, which has none)."""
    return [part.strip() for part in text.split(",") if part.strip()]


def _print(r: dict) -> None:
    rate = r["stages_points_per_s"]
    print(
        f"{r['kind']:6s} n={r['n']:>9,d} {r['backend']}, peak {r['peak_bytes_per_point']:.0f} B/pt"
    )
    for mode, d in r["detect"].items():
        print(
            f"   {mode:6s} detect cold {d['cold_s']:.2f} s, warm {d['warm_s']:.2f} s "
            f"({d['points_per_s'] / 1e3:,.0f}k pts/s), cpu {d['cpu_s']:.2f} s"
        )
        print(
            f"          each run: wall {' '.join(f'{x:.2f}' for x in d['walls_s'])} s, "
            f"system {' '.join(f'{x:.2f}' for x in d['system_s'])} s"
        )
    if len(r["detect"]) == 2:
        p, q = r["detect"]["paper"], r["detect"]["robust"]
        print(
            f"   robust / paper: warm {q['warm_s'] / p['warm_s']:.2f}, "
            f"cpu {q['cpu_s'] / p['cpu_s']:.2f}"
        )
    print("   paper stages " + ", ".join(f"{k} {v / 1e3:,.0f}k/s" for k, v in rate.items()))


if __name__ == "__main__":
    raise SystemExit(main())
