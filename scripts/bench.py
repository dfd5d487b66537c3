#!/usr/bin/env python3
"""Benchmark meshlab_sharp.detect stage by stage on CAD-like inputs it builds itself.

Inputs (seeded): a point cloud sampled uniformly on the surface of a union of boxes and
cylinders (a machined part: planes, cylinders, convex and concave edges), and a mesh,
a box whose faces are regular grids (welded by cleaning) with a few steps on top.
Each size runs in a fresh subprocess, so that its peak resident memory
(``VmHWM``, which sees C allocations, unlike tracemalloc, and unlike ``ru_maxrss`` is
not inherited from the parent: ``meshlab_sharp.tiles.run.peak_rss``) is its own; the baseline
(interpreter, imports, the input arrays) is measured in the same process before
detection and subtracted.

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
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

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


def _cpu_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


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
        vertices, faces = cad_mesh(n)
        scales = DEFAULT_RING_SCALES
    n_in = len(vertices)
    baseline = _rss_bytes()
    out: dict = {"kind": kind, "n": n_in, "backend": backend, "workers": _kernels._workers(-1)}

    with _kernels.use_backend(backend):
        # End to end on in-memory arrays, the modes back to back in each repeat: the
        # first call is cold (page faults, thread pool, first use of the library).
        walls: dict[str, list[float]] = {m: [] for m in modes}
        cpus: dict[str, list[float]] = {m: [] for m in modes}
        peak_detect = 0
        out["detect"] = {}
        for _ in range(repeat):
            for mode in modes:
                t, c = time.perf_counter(), _cpu_seconds()
                result = detect(vertices, faces, mode=mode)
                walls[mode].append(time.perf_counter() - t)
                cpus[mode].append(_cpu_seconds() - c)
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
                cold_s=totals[0], warm_s=warm, cpu_s=min(cpus[mode]), points_per_s=n_in / warm
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
            cleaned = timed("clean", lambda g=g: clean(g))
            pts = cleaned.vertices

            def neighbourhoods(pts=pts, cleaned=cleaned):
                nb = build_neighbourhoods(pts, cleaned.faces, scales)
                nrm = None if cleaned.faces is None else face_average_normals(pts, cleaned.faces)
                return nb, nrm

            nb, nrm = timed("neighbourhoods", neighbourhoods)

            pdis = timed(
                "normals_projected_distance",
                lambda pts=pts, nb=nb, nrm=nrm: projected_distances_all(
                    pts, nb, scales, normals=nrm
                ),
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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="100k,1M", help="comma-separated, e.g. 100k,1M,5M,20M")
    ap.add_argument("--kind", choices=["points", "mesh", "both"], default="both")
    ap.add_argument("--backend", choices=["compiled", "numpy"], default="compiled")
    ap.add_argument("--mode", choices=["paper", "robust", "both"], default="both")
    ap.add_argument("--repeat", type=int, default=3, help="runs per size (best is reported)")
    ap.add_argument("--json", default="bench.json", help="where to write the results")
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
    args = ap.parse_args(argv)

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
    if len(r["detect"]) == 2:
        p, q = r["detect"]["paper"], r["detect"]["robust"]
        print(
            f"   robust / paper: warm {q['warm_s'] / p['warm_s']:.2f}, "
            f"cpu {q['cpu_s'] / p['cpu_s']:.2f}"
        )
    print("   paper stages " + ", ".join(f"{k} {v / 1e3:,.0f}k/s" for k, v in rate.items()))


if __name__ == "__main__":
    raise SystemExit(main())
