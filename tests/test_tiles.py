"""Out-of-core detection (meshlab_sharp.tiles): tiled and Dask runs equal the in-memory
run bit for bit, the halos are proven, the streaming readers and writers keep order."""

from __future__ import annotations

import os

import numpy as np
import pytest
from shapes import noisy_sphere_points, random_box_points

import meshlab_sharp
from meshlab_sharp import _kernels
from meshlab_sharp.errors import InputError
from meshlab_sharp.multiscale import DEFAULT_KNN_SCALES
from meshlab_sharp.neighbourhoods import KnnNeighbourhoods
from meshlab_sharp.tiles import detect_tiled, parse_memory
from meshlab_sharp.tiles.layout import build_layout
from meshlab_sharp.tiles.neighbours import Query, neighbours
from meshlab_sharp.tiles.run import machine_threads, task_threads, warm_up
from meshlab_sharp.tiles.store import Store

pytestmark = pytest.mark.skipif(not _kernels.available(), reason="needs the compiled kernels")

SCALES = (8, 12, 16)


def hostile_cloud(n: int = 4000, seed: int = 7) -> np.ndarray:
    """A sampled box (edges and corners everywhere, so tiles cut through them) with
    exact duplicates, a near outlier (isolated in robust mode), a lone far outlier, a
    far pair and a far cluster of 3, shuffled."""
    rng = np.random.default_rng(seed)
    pts = random_box_points(n, seed=seed)
    far = np.array(
        [[1.5, 0.1, 0.1], [25.0, 25.0, 25.0], [-20.0, 3.0, 1.0], [-20.0, 3.05, 1.0]]
        + [[0.5, 40.0, 0.2], [0.55, 40.0, 0.2], [0.5, 40.05, 0.25]]
    )
    pts = np.concatenate([pts, pts[rng.choice(n, 60)], far])
    return pts[rng.permutation(len(pts))]


def assert_same(tiled: dict, ref: meshlab_sharp.DetectionResult) -> None:
    assert np.array_equal(tiled["mask"], ref.mask)
    assert np.array_equal(tiled["strength"], ref.strength)
    assert np.array_equal(tiled["kept"], ref.kept)
    assert np.array_equal(tiled["thresholds"], ref.thresholds)
    assert np.array_equal(tiled["candidate_counts"], ref.candidate_counts)
    assert tiled["n_clean"] == ref.n_clean


@pytest.mark.parametrize("mode", ["paper", "robust"])
@pytest.mark.parametrize("tile_points", [300, 1200])
def test_tiled_equals_in_memory(mode: str, tile_points: int) -> None:
    pts = hostile_cloud()
    ref = meshlab_sharp.detect(pts, scales=SCALES, mode=mode)
    out = detect_tiled(pts, scales=SCALES, mode=mode, tile_points=tile_points)
    assert out["tiling"]["tiles"] >= 4
    assert out["tiling"]["streamed"] > 0  # the far points took the streaming route
    assert ref.n_features > 50
    assert_same(out, ref)


def test_robust_passes_as_in_memory() -> None:
    """Robust mode runs the in-memory run's compiled passes per tile: one over every
    point on a clean cloud (no isolated points, no noise to grow the scales for); with
    isolated points, a second one only over the kept points whose k nearest held one:
    here a point beside a tight clump on a face (isolated: its nearest is in the clump,
    whose lists are the clump) lies in the lists of the face's points beyond it."""
    clean = random_box_points(4000, seed=4)
    ref = meshlab_sharp.detect(clean, scales=SCALES, mode="robust")
    out = detect_tiled(clean, scales=SCALES, mode="robust", tile_points=600)
    assert ref.kept.all() and ref.scales == SCALES and ref.n_features > 50
    assert_same(out, ref)
    assert [k for k in out["timings"] if k.startswith("step_pass")] == ["step_pass"]
    c = clean[0]  # on the face z = 0.5
    clump = c + np.random.default_rng(2).normal(scale=3e-4, size=(30, 3)) * [1, 1, 0]
    pts = np.concatenate([clean, clump, [c + [0.01, 0.0, 0.0]]])
    ref = meshlab_sharp.detect(pts, scales=SCALES, mode="robust")
    assert not ref.kept[-1] and ref.scales == SCALES
    out = detect_tiled(pts, scales=SCALES, mode="robust", tile_points=600)
    passes = [k for k in out["timings"] if k.startswith("step_pass")]
    assert passes == ["step_pass", "step_pass kept"]
    assert 0 < out["tiling"]["redone"] < 100
    assert_same(out, ref)


def test_compiled_passes_of_some_rows_equal_the_whole_pass() -> None:
    """The compiled passes restricted to some points (``rows=``: a tile's own points,
    not its halo) give those points' values of the pass over every point, bit for bit."""
    from meshlab_sharp import robust

    pts = hostile_cloud(3000, seed=2)
    pts = pts[_kernels.merge_duplicates(pts)[0]]
    rows = np.flatnonzero(pts[:, 0] < 0.1)  # a slab: runs of the tree, and stray points
    rows = np.union1d(rows, [5, 17, len(pts) - 1])
    tree = _kernels.build_tree(pts)
    sheet = robust.sheet_parameters()
    kw = {"relative": True, "noise_k": 7, "sheet": sheet}
    whole = _kernels.cloud_projected_distances(tree, SCALES, **kw)
    some = _kernels.cloud_projected_distances(tree, SCALES, rows=rows, **kw)
    assert whole.relative is not None and some.relative is not None
    assert np.array_equal(whole.relative[:, rows], some.relative[:, rows])
    assert np.array_equal(whole.score[rows], some.score[rows])
    for name in ("near", "kth_d2", "kth_idx", "nth_d2", "ref_d2", "noise"):
        assert np.array_equal(getattr(whole.stats, name)[rows], getattr(some.stats, name)[rows])
    idx, pdis = _kernels.cloud_knn_projected_distances(tree, SCALES)
    idx_r, pdis_r = _kernels.cloud_knn_projected_distances(tree, SCALES, rows=rows)
    assert np.array_equal(idx[rows], idx_r[rows]) and np.array_equal(pdis[:, rows], pdis_r[:, rows])
    assert np.array_equal(
        _kernels.cloud_knn(tree, 9)[rows], _kernels.cloud_knn(tree, 9, rows=rows)[rows]
    )


def test_default_scales_and_far_outliers_only_tiles() -> None:
    """Default scales (k up to 40), tiles that hold nothing but far points (and, in
    robust mode, nothing but isolated points)."""
    pts = hostile_cloud(3000, seed=11)
    for mode in ("paper", "robust"):
        ref = meshlab_sharp.detect(pts, mode=mode)
        out = detect_tiled(pts, scales=DEFAULT_KNN_SCALES, mode=mode, tile_points=500)
        assert_same(out, ref)
    assert not ref.kept.all()  # robust mode left the lone outlier out


@pytest.mark.parametrize("share", [None, 0.02])
def test_neighbourhoods_of_every_tile_are_the_global_ones(tmp_path, share: float | None) -> None:
    """The halo check: whatever the first halo (none at all), every row's k nearest in
    its tile context are the cloud's k nearest, in the same order; with rows marked
    (a few, none in some tiles: the box is then the marked points' own), exactly those
    rows."""
    pts = hostile_cloud(2500, seed=3)
    store = Store(str(tmp_path))
    layout = build_layout(
        len(pts), lambda: iter([pts[:1000], pts[1000:]]), store, tile_points=250, source="t"
    )
    to_first, _, _ = _kernels.merge_duplicates(pts)
    k = 12
    ref = KnnNeighbourhoods(pts[to_first], k).indices
    ids = store.read("ids", 0, len(pts))
    query, want = Query(k), len(to_first)
    if share is not None:
        marked = np.zeros(len(pts), bool)  # distinct points only, as the steps mark
        marked[to_first] = np.random.default_rng(5).random(len(to_first)) < share
        store.create("marked", (len(pts),), bool)
        store.write("marked", 0, marked[ids])
        query = Query(k, rows="marked")
        want = int(marked[to_first].sum())
        empty = [
            t
            for t in range(layout.n_tiles)
            if not marked[ids[layout.offsets[t] : layout.offsets[t + 1]]].any()
        ]
        assert len(empty) >= 2
    seen, halos, streamed = 0, [], 0
    for t in range(layout.n_tiles):
        contexts, halo, _, far = neighbours(store, layout, t, query, halo=0.0, most_points=900)
        halos.append(halo)
        streamed += far
        for ctx in contexts:
            input_ids = ids[ctx.pos]
            cleaned = np.searchsorted(to_first, input_ids)
            rows = cleaned[ctx.rows]
            assert np.array_equal(cleaned[ctx.idx], ref[rows])
            if share is not None:
                assert marked[input_ids[ctx.rows]].all()
            seen += len(rows)
    assert seen == want
    assert max(halos) > 0.0  # widened from nothing
    assert streamed >= (5 if share is None else 0)  # the far points


def test_max_memory_api_and_cli_output(tmp_path) -> None:
    """detect(max_memory=) gives the in-memory result; the CLI's streamed PLY has the
    bytes of the in-memory CLI's PLY, and the same indices."""
    from meshlab_sharp.cli import main
    from meshlab_sharp.io import save_features_ply

    pts = hostile_cloud(3000, seed=5)
    src = tmp_path / "cloud.ply"
    save_features_ply(src, pts, None, np.zeros(len(pts)), np.zeros(len(pts), bool))
    ref = meshlab_sharp.detect(pts, mode="robust")
    res = meshlab_sharp.detect(src, mode="robust", max_memory="2GB")
    assert np.array_equal(res.mask, ref.mask) and np.array_equal(res.strength, ref.strength)
    assert res.tiling is not None and res.summary()["tiling"]["tiles"] >= 1
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    assert main(["detect", str(src), "-o", str(a), "--indices", str(a) + ".txt", "-q"]) == 0
    args = ["detect", str(src), "-o", str(b), "--indices", str(b) + ".txt", "-q"]
    assert main([*args, "--max-memory", "1GB"]) == 0
    assert a.read_bytes() == b.read_bytes()
    assert (tmp_path / "a.ply.txt").read_text() == (tmp_path / "b.ply.txt").read_text()


@pytest.mark.slow
def test_dask_equals_in_memory() -> None:
    """--dask local:2 (paper) and --dask tcp://127.0.0.1:PORT (robust, a running
    cluster of 2 worker processes on the loopback)."""
    distributed = pytest.importorskip("dask.distributed")
    pts = hostile_cloud(2500, seed=9)
    ref = meshlab_sharp.detect(pts, scales=SCALES, mode="paper")
    # 2 single-thread workers on this machine: each task's searches get half the cores
    shared = task_threads(len(os.sched_getaffinity(0)), 2)
    out = detect_tiled(pts, scales=SCALES, mode="paper", tile_points=400, dask="local:2")
    assert out["tiling"]["worker_peak_bytes"] > 0 and out["tiling"]["tiles"] >= 4
    assert out["tiling"]["task_threads"] == shared
    assert_same(out, ref)
    ref = meshlab_sharp.detect(pts, scales=SCALES, mode="robust")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address="127.0.0.1:0"
    ) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        with distributed.Client(address) as client:
            assert machine_threads(client) == {"127.0.0.1": 2}
        out = detect_tiled(pts, scales=SCALES, mode="robust", tile_points=400, dask=address)
        assert out["tiling"]["task_threads"] == shared
        one = detect_tiled(pts, scales=SCALES, tile_points=400, dask=address, workers=1)
        assert one["tiling"]["task_threads"] == 1
    assert_same(out, ref)
    assert_same(one, ref)


def _no_values(ctx: object) -> dict:
    """A step that only needs the neighbourhoods (their halos)."""
    return {}


def test_dask_tiles_start_from_the_first_tiles_halo(tmp_path) -> None:
    """On Dask as on threads, a search step's first tile runs alone and every other
    tile starts from the halo it held: none searches its bare box first, so every
    halo is at least the first tile's (from no halo, some tiles would hold less)."""
    distributed = pytest.importorskip("dask.distributed")
    from meshlab_sharp.tiles.run import Runner
    from meshlab_sharp.tiles.steps import Step

    pts = random_box_points(3000, seed=3)
    store = Store(str(tmp_path))
    layout = build_layout(len(pts), lambda: iter([pts]), store, tile_points=250, source="t")
    query = Query(12)
    alone = [
        neighbours(store, layout, t, query, halo=0.0, most_points=900)[1]
        for t in range(layout.n_tiles)
    ]
    assert layout.n_tiles >= 8 and min(alone) < alone[0]
    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=2, processes=False, dashboard_address="127.0.0.1:0"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        runner = Runner(store, layout, most_points=900, workers=1, client=client)
        runner.step(Step("search", _no_values, query))
    assert runner.halos[0] == alone[0]
    assert (runner.halos >= alone[0]).all()


def test_local_cluster_workers_keep_glibc_memory_handling(monkeypatch) -> None:
    """--dask local:N starts its workers without Dask's MALLOC_TRIM_THRESHOLD_ (which
    fixes glibc's mmap threshold: every large array mapped and faulted in anew); the
    warm-up runs a task on each worker."""
    pytest.importorskip("dask.distributed")
    from contextlib import ExitStack

    from meshlab_sharp.tiles import _client

    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    with ExitStack() as stack:
        client = _client("local:1", stack)
        got = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_", "unset"))
        assert client.gather(warm_up(client)) == [None]  # a no-op task per worker
    assert list(got.values()) == ["unset"]


def test_task_threads_share_the_machine() -> None:
    """A Dask tile task's threads: the machine's cores over the threads of the workers
    on it, at least one (8 single-thread workers on 8 cores: one each, not 8 x 8)."""
    assert task_threads(8, 8) == 1
    assert task_threads(8, 2) == 4
    assert task_threads(8, 3) == 2
    assert task_threads(2, 4) == 1
    assert task_threads(4, 0) == 4


def test_las_laz_round_trip_keeps_order(tmp_path) -> None:
    pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    from meshlab_sharp.io.las import read_las, write_las

    pts = np.round(hostile_cloud(1500, seed=2), 4)
    for ext in (".las", ".laz"):
        path = tmp_path / f"cloud{ext}"
        write_las(path, pts)
        back = read_las(path)
        assert np.allclose(back, pts, atol=1e-9, rtol=0)
        ref = meshlab_sharp.detect(back, scales=SCALES)
        res = meshlab_sharp.detect(path, scales=SCALES, max_memory="1GB")
        assert np.array_equal(res.mask, ref.mask)
        assert np.array_equal(meshlab_sharp.detect(path, scales=SCALES).mask, ref.mask)


def test_e57_round_trip(tmp_path) -> None:
    pytest.importorskip("pye57")
    from meshlab_sharp.io.e57 import read_e57, write_e57

    pts = hostile_cloud(1200, seed=4)
    path = tmp_path / "cloud.e57"
    write_e57(path, pts)
    back = read_e57(path)  # pye57 stores single precision
    assert np.allclose(back, pts, atol=1e-6, rtol=0)
    ref = meshlab_sharp.detect(back, scales=SCALES)
    assert np.array_equal(
        meshlab_sharp.detect(path, scales=SCALES, max_memory="1GB").mask, ref.mask
    )


def test_bad_options() -> None:
    pts = hostile_cloud(800)
    assert parse_memory("1GB") == 1 << 30
    assert parse_memory("512 MiB") == 512 << 20
    assert parse_memory(1000) == 1000
    for bad in ("lots", "-1GB", "0"):
        with pytest.raises(InputError):
            parse_memory(bad)
    with pytest.raises(InputError, match="point clouds only"):
        meshlab_sharp.detect(pts[:3], np.array([[0, 1, 2]]), max_memory="1GB")
    with pytest.raises(InputError, match="return_details"):
        meshlab_sharp.detect(pts, max_memory="1GB", return_details=True)
    with pytest.raises(InputError, match="too little memory"):
        meshlab_sharp.detect(pts, max_memory="1MB")
    with pytest.raises(InputError, match="local:N"):
        meshlab_sharp.detect(pts, dask="local:0")
    with pytest.raises(InputError, match="fewer than the largest scale"):
        meshlab_sharp.detect(pts[:10], scales=[16], max_memory="1GB")


@pytest.mark.parametrize("noise", [0.006, 0.012])
def test_noise_grown_scales_equal_in_memory(noise: float) -> None:
    """Robust mode's scales grow with the measured noise (a lower median over all
    points, reduced exactly): the tiled run grows them the same way; at the cap (x3)
    thinning ranks by the mean score (the tiles' "rank" step)."""
    pts = hostile_cloud(3000, seed=7)
    noisy = pts + np.random.default_rng(1).normal(scale=noise, size=pts.shape)
    ref = meshlab_sharp.detect(noisy, mode="robust")
    assert ref.scales != DEFAULT_KNN_SCALES
    assert (max(ref.scales) == 3 * max(DEFAULT_KNN_SCALES)) == (noise == 0.012)
    out = detect_tiled(noisy, scales=DEFAULT_KNN_SCALES, mode="robust", tile_points=500)
    assert out["scales"] == ref.scales
    assert_same(out, ref)


def test_noise_floor_equal_in_memory() -> None:
    """The largest scale's noise floor (reference_sequence.scale_floor) read from the tiles' summed
    histogram is the in-memory one: on a noisy sphere it, not Otsu's split, sets the
    threshold, and few points are features."""
    pts = noisy_sphere_points(6000, 0.25)
    ref = meshlab_sharp.detect(pts, mode="robust")
    assert ref.thresholds[-1] > max(ref.thresholds[:-1])
    out = detect_tiled(pts, scales=DEFAULT_KNN_SCALES, mode="robust", tile_points=500)
    assert_same(out, ref)
    assert ref.mask.mean() <= 0.002


@pytest.mark.parametrize("collect", [1, 7, 1 << 21])
def test_order_statistic_is_exact(tmp_path, monkeypatch, collect: int) -> None:
    """The k-th smallest by counting passes equals np.partition's, with many equal
    values and values gathered from a tiny bin; a rank among many equal values is
    found without gathering them."""
    from meshlab_sharp.tiles import select
    from meshlab_sharp.tiles.run import Runner

    monkeypatch.setattr(select, "COLLECT", collect)
    rng = np.random.default_rng(0)
    pts = rng.random((3000, 3))
    values = np.concatenate([np.zeros(900), rng.random(1500) ** 3, np.full(600, 0.25)])
    keep = rng.random(3000) < 0.9
    store = Store(str(tmp_path))
    layout = build_layout(3000, lambda: iter([pts]), store, tile_points=400, source="t")
    ids = store.read("ids", 0, 3000)
    store.create("v", (3000,), np.float64)
    store.create("keep", (3000,), bool)
    store.write("v", 0, values[ids])
    store.write("keep", 0, keep[ids])
    runner = Runner(store, layout, most_points=1000, workers=1)
    kept = values[keep]
    for rank in (0, 1, len(kept) // 3, (len(kept) - 1) // 2, len(kept) - 1):
        want = np.partition(kept, rank)[rank]
        assert select.order_statistic(runner, "v", "keep", rank) == want
    runner = Runner(store, layout, most_points=1000, workers=1)
    assert select.order_statistic(runner, "v", "keep", 5) == 0.0  # one of the 900 zeros
    assert "noise pick" not in runner.seconds  # a bin of zeros alone: not gathered
    # values over 600 orders of magnitude, negative ones and -0.0 among them
    spread = 10.0 ** rng.uniform(-300, 300, 3000) * rng.choice([-1.0, 1.0], 3000)
    spread[:50] = -0.0
    store.write("v", 0, spread[ids])
    kept = spread[keep]
    for rank in (0, 7, len(kept) // 2, len(kept) - 1):
        assert select.order_statistic(runner, "v", "keep", rank) == np.partition(kept, rank)[rank]


def assert_same_curves(
    got: meshlab_sharp.DetectionResult, ref: meshlab_sharp.DetectionResult
) -> None:
    assert got.curves is not None and ref.curves is not None
    assert got.corners is not None and ref.corners is not None
    assert len(got.curves) == len(ref.curves)
    for a, b in zip(got.curves, ref.curves, strict=True):
        assert np.array_equal(a.points, b.points) and np.array_equal(a.indices, b.indices)
        assert (a.kind, a.closed, repr(a.params)) == (b.kind, b.closed, repr(b.params))
    assert np.array_equal(got.corners.points, ref.corners.points)
    assert np.array_equal(got.corners.indices, ref.corners.indices)


@pytest.mark.parametrize("mode", ["robust", "paper"])
def test_curves_out_of_core_equal_in_memory(monkeypatch, mode: str) -> None:
    """Curves after a tiled run, from the points near the features gathered in blocks
    (many small blocks here), are the in-memory curves and corners, input indices
    included; a cloud without features has none."""
    from meshlab_sharp.io.source import PointSource
    from meshlab_sharp.tiles import curves as tiled_curves

    monkeypatch.setattr(tiled_curves, "BLOCK", 777)
    pts = hostile_cloud(4000, seed=3)
    ref = meshlab_sharp.detect(pts, mode=mode, curves=True)
    got = meshlab_sharp.detect(
        PointSource.from_array(pts), mode=mode, curves=True, max_memory="1GB"
    )
    assert ref.curves is not None and len(ref.curves) >= 10  # most of a box's 12 edges
    assert_same_curves(got, ref)
    assert "curves" in got.timings
    flat = np.column_stack([np.random.default_rng(0).random((500, 2)), np.zeros(500)])
    none = meshlab_sharp.detect(flat, mode=mode, curves=True, max_memory="1GB")
    assert none.curves == [] and none.corners is not None and len(none.corners) == 0


def test_curves_out_of_core_cli(tmp_path) -> None:
    """detect --curves with --max-memory writes the in-memory run's curves file."""
    from meshlab_sharp.cli import main
    from meshlab_sharp.io import save_features_ply

    pts = hostile_cloud(3000, seed=5)
    src = tmp_path / "cloud.ply"
    save_features_ply(src, pts, None, np.zeros(len(pts)), np.zeros(len(pts), bool))
    for name, extra in (("a", []), ("b", ["--max-memory", "1GB"])):
        args = ["detect", str(src), "-o", str(tmp_path / f"{name}.ply"), "-q"]
        assert main([*args, "--curves", str(tmp_path / f"{name}.obj"), *extra]) == 0
    assert (tmp_path / "a.obj").read_bytes() == (tmp_path / "b.obj").read_bytes()
    assert b"\nl " in (tmp_path / "a.obj").read_bytes()


def _detect_in_child(tmp_path, pts: np.ndarray, options: str, prints: str) -> list[int]:
    """Write ``pts`` (n, 3) as a binary PLY, run ``meshlab_sharp.detect(path, <options>)``
    in a fresh interpreter and return the integers it prints: the tile count, then
    ``prints`` (an expression list over the result ``r`` and ``peak_rss``)."""
    import subprocess
    import sys
    from pathlib import Path

    path = tmp_path / "cloud.ply"
    header = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(pts)}\n"
        "property double x\nproperty double y\nproperty double z\nend_header\n"
    )
    path.write_bytes(header.encode() + pts.astype("<f8").tobytes())
    code = (
        "import meshlab_sharp\n"
        "from meshlab_sharp.tiles.run import peak_rss\n"
        f"r = meshlab_sharp.detect({str(path)!r}, {options})\n"
        f"print(r.tiling['tiles'], {prints})\n"
    )
    root = str(Path(__file__).resolve().parent.parent)
    env = {"PYTHONPATH": root, "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    )
    return [int(v) for v in proc.stdout.split()]


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["robust", "paper"])
def test_peak_memory_stays_under_the_limit(tmp_path, mode: str) -> None:
    """A fresh process reading a 400k-point binary PLY with --max-memory 300MB peaks
    below 300 MB (interpreter, imports, tiles and result included), in both modes.

    The peak is the child's ``VmHWM`` (``tiles.run.peak_rss``), not ``ru_maxrss``: a
    child started by ``subprocess`` (vfork + exec) inherits its parent's peak in
    ``ru_maxrss``, which would make this test report pytest's own memory (653-672 MB
    after a long test run). This test holds 400 MB itself while the child runs, so an inherited
    peak would fail it."""
    rng = np.random.default_rng(0)
    pts = random_box_points(400_000, seed=1) + rng.normal(scale=1e-4, size=(400_000, 3))
    ballast = np.ones(400 << 17)  # 400 MB resident in this process during the run
    out = _detect_in_child(
        tmp_path,
        pts,
        f"max_memory='300MB', mode={mode!r}",
        "r.n_features, peak_rss(), r.tiling['peak_bytes']",
    )
    assert ballast.sum() == 400 << 17
    tiles, features, peak, reported = out
    assert tiles >= 2 and features > 0
    assert 50 * 2**20 < peak < 300 * 2**20
    assert reported <= peak  # the summary's peak is the same measure, taken earlier


@pytest.mark.slow
def test_peak_memory_stays_under_the_limit_when_the_noise_grows_the_scales(tmp_path) -> None:
    """The tiles are sized for two at a time at the given scales; when the noise grows
    robust mode's scales threefold (more memory per point than the sizing's scales),
    the grown steps run one tile at a time and a fresh process still peaks below the
    limit."""
    rng = np.random.default_rng(0)
    pts = random_box_points(200_000, seed=1) + rng.normal(scale=0.003, size=(200_000, 3))
    out = _detect_in_child(
        tmp_path, pts, "max_memory='200MB', mode='robust'", "max(r.scales), peak_rss()"
    )
    tiles, k_top, peak = out
    assert tiles >= 4 and k_top == 3 * max(DEFAULT_KNN_SCALES)
    assert 50 * 2**20 < peak < 200 * 2**20


def test_tile_size_known_answers() -> None:
    """Bytes per tile point at k: (BYTES_PER_POINT + 8 k + 16 s) * HALO_FACTOR, 2870 at
    the default scales (k = 40, s = 8), 4470 at robust mode's largest growth (k = 120).
    In this process two tiles run at once: paper mode sizes for two at k = 40, robust
    mode for the larger of two at k = 40 and one at k = 120; a Dask task runs one."""
    from meshlab_sharp.tiles import BYTES_PER_POINT, HALO_FACTOR, tile_size

    assert (BYTES_PER_POINT, HALO_FACTOR) == (700, 2.5)
    assert tile_size(10**9, DEFAULT_KNN_SCALES, "paper", 2) == 10**9 // 5740
    assert tile_size(10**9, DEFAULT_KNN_SCALES, "paper", 1) == 10**9 // 2870
    assert tile_size(10**9, DEFAULT_KNN_SCALES, "robust", 2) == 10**9 // 5740
    assert tile_size(10**9, DEFAULT_KNN_SCALES, "robust", 1) == 10**9 // 4470
    # one scale: two tiles at k = 40 take more than one at 120; one at k = 300 more
    # than two at 100
    assert tile_size(10**9, (40,), "robust", 2) == 10**9 // ((700 + 320 + 16) * 2.5 * 2)
    assert tile_size(10**9, (100,), "robust", 2) == 10**9 // ((700 + 2400 + 16) * 2.5)


@pytest.mark.slow
def test_tiles_run_two_at_once_until_the_scales_grow(monkeypatch) -> None:
    """Without Dask two tiles run at a time (each search's first tile alone, for the
    halo guess); once the noise grows robust mode's scales, one at a time (the tiles
    are sized for that); with one thread (``workers=1``), one at a time. The answer is
    the in-memory one."""
    import threading
    import time

    from meshlab_sharp.tiles import run

    lock = threading.Lock()
    active, most, first = [0], {}, {}
    real = run.tile_task

    def counted(step, store, layout, tile, *args):
        with lock:
            active[0] += 1
            most[step.label] = max(most.get(step.label, 0), active[0])
            first.setdefault(step.label, (tile, active[0]))
        try:
            time.sleep(0.02)  # time for a second tile to start, where one may
            return real(step, store, layout, tile, *args)
        finally:
            with lock:
                active[0] -= 1

    monkeypatch.setattr(run, "tile_task", counted)
    pts = hostile_cloud(3000, seed=7)
    noisy = pts + np.random.default_rng(1).normal(scale=0.012, size=pts.shape)
    ref = meshlab_sharp.detect(noisy, mode="robust")
    out = detect_tiled(noisy, scales=DEFAULT_KNN_SCALES, mode="robust", tile_points=500, workers=2)
    assert out["scales"] == ref.scales != DEFAULT_KNN_SCALES
    assert_same(out, ref)
    assert out["tiling"]["tiles"] >= 6
    assert most["pass"] == most["isolated"] == 2
    assert first["pass"] == (0, 1)  # alone
    grown = ("pass grown", "decide", "support", "thin")
    assert all(most[label] == 1 for label in grown)
    most.clear()
    one = detect_tiled(noisy, scales=DEFAULT_KNN_SCALES, mode="robust", tile_points=500, workers=1)
    assert_same(one, ref)
    assert set(most.values()) == {1}  # one thread asked for: one tile at a time


def test_store_writes_rows_in_runs_and_scattered(tmp_path, monkeypatch) -> None:
    """write_at gives the same array whether the rows form a few runs or many short
    ones with gaps (written by pwrite) or are scattered (through a map), in any order;
    a block that does not fit is refused."""
    from meshlab_sharp.tiles import store as store_module

    mapped: list[str] = []
    real_map = Store._map

    def recorded(self: Store, name: str, mode: str) -> np.ndarray:
        mapped.append(name)
        return real_map(self, name, mode)

    monkeypatch.setattr(Store, "_map", recorded)
    rng = np.random.default_rng(3)
    n = 2000
    want = np.zeros((n, 2))
    store = Store(str(tmp_path))
    store.create("a", (n, 2), np.float64)
    runs = np.concatenate([np.arange(10, 60), np.arange(100, 180), np.arange(400, 401)])
    gaps = np.setdiff1d(np.arange(n), np.arange(0, n, 20))  # 100 gaps, runs of 19
    scattered = rng.choice(np.setdiff1d(np.arange(n), runs), store_module.RUNS * 2, False)
    for rows, through_map in ((runs[::-1], False), (gaps, False), (scattered, True)):
        values = rng.random((len(rows), 2))
        want[rows] = values
        store.write_at("a", rows, values)
        assert np.array_equal(store.read("a", 0, n), want)
        assert bool(mapped) == through_map
    with pytest.raises(ValueError, match="do not fit"):
        store.write("a", n - 1, np.zeros((2, 2)))
    store.remove("a")
    assert not store.path("a").exists() and "a" not in store.arrays


@pytest.mark.parametrize("scale", [1e-6, 1e-2, 1.0, 1e6])
def test_knn_near_equals_the_search_of_all_points(scale: float, monkeypatch) -> None:
    """The k nearest of a few rows searched among the points near them equal those
    searched among all points, ties (integer grid) broken the same, with hints far too
    small (all points after the widenings), too small (widened), right and too large
    (all points)."""
    from meshlab_sharp.tiles import neighbours as nb

    rng = np.random.default_rng(5)
    xy = np.stack(np.meshgrid(np.arange(200.0), np.arange(200.0)), -1).reshape(-1, 2)
    xy = xy[rng.random(len(xy)) < 0.7]
    points = np.column_stack([xy, np.zeros(len(xy))])[rng.permutation(len(xy))]
    rows = np.sort(rng.choice(len(points), 40, replace=False))
    k = 16
    want = _kernels.cloud_knn_rows(_kernels.build_tree(points), rows, k, 1)
    kth = ((points[want[:, -1]] - points[rows]) ** 2).sum(axis=1)
    sizes: list[int] = []
    near = nb._points_near

    def recorded(*args):
        got = near(*args)
        sizes.append(len(got))
        return got

    monkeypatch.setattr(nb, "_points_near", recorded)
    assert np.array_equal(nb._knn_near(points, rows, k, 1, kth * scale), want)
    if scale in (1e-2, 1.0):  # the search ran on a part of the points
        assert 0 < min(sizes) < len(points) // 2
