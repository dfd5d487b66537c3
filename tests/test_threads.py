"""The worker threads: one pool for the process, chunks shared out, errors raised;
robust mode's line directions in parts on threads giving the answers of one call; a
cloud's kd-tree built beside its cleaning."""

from __future__ import annotations

import os
import signal
import threading

import numpy as np
import pytest
import shapes

from meshlab_sharp import _kernels
from meshlab_sharp.io import Geometry
from meshlab_sharp.neighbourhoods import Neighbourhood, knn
from meshlab_sharp.reference import detect as reference_sequence
from meshlab_sharp.reference import robust as reference_robust


def _record(calls: list[tuple[int, int, int]]):
    def task(a: int, b: int) -> int:
        calls.append((a, b, threading.get_ident()))
        return 0

    return task


def test_chunks_cover_the_range_once_and_reuse_the_pool_threads():
    first: list[tuple[int, int, int]] = []
    _kernels._run_chunks(1000, 3, _record(first), chunk=7)
    assert sorted((a, b) for a, b, _ in first) == [(s, min(s + 7, 1000)) for s in range(0, 1000, 7)]
    pool = _kernels._Pool.get()
    second: list[tuple[int, int, int]] = []
    _kernels._run_chunks(1000, 3, _record(second), chunk=7, spans=[(10, 20), (500, 503)])
    assert sorted((a, b) for a, b, _ in second) == [(10, 17), (17, 20), (500, 503)]
    assert _kernels._Pool.get() is pool
    # the calling thread and the pool's threads, no thread started per call
    pool_threads = {t.ident for t in threading.enumerate() if t.name.startswith("meshlab_sharp")}
    assert {t for *_, t in first + second} <= pool_threads | {threading.get_ident()}
    assert len(pool_threads) <= os.cpu_count() + 4  # ThreadPoolExecutor's default cap


def test_one_worker_runs_on_the_calling_thread():
    calls: list[tuple[int, int, int]] = []
    _kernels._run_chunks(100, 1, _record(calls), chunk=10)
    assert {t for *_, t in calls} == {threading.get_ident()} and len(calls) == 10


def test_a_failing_chunk_raises_after_the_others_stop():
    def task(a: int, b: int) -> int:
        if a == 40:
            raise ValueError("chunk 40")
        return 0

    with pytest.raises(ValueError, match="chunk 40"):
        _kernels._run_chunks(200, 2, task, chunk=10)
    with pytest.raises(MemoryError):
        _kernels._run_chunks(200, 2, lambda a, b: int(a == 100), chunk=10)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork")
def test_a_forked_child_starts_its_own_threads():
    _kernels._Pool.get()  # the parent's pool exists before the fork
    _kernels._run_chunks(100, 2, lambda a, b: 0, chunk=10)
    pid = os.fork()
    if pid == 0:  # the child: the parent's threads are not there
        signal.alarm(20)
        calls: list[tuple[int, int, int]] = []
        try:
            _kernels._run_chunks(100, 2, _record(calls), chunk=10)
        finally:
            os._exit(0 if len(calls) == 10 else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0


def _features(seed: int) -> tuple[np.ndarray, np.ndarray, Neighbourhood]:
    rng = np.random.default_rng(seed)
    points = rng.standard_normal((600, 3))
    idx = knn(points, 12)
    lists = Neighbourhood(np.arange(601, dtype=np.int64) * 12, idx.reshape(-1).astype(np.int64))
    return points, rng.random(600) < 0.6, lists


def test_line_directions_in_parts_on_threads_are_one_calls(monkeypatch):
    points, mask, lists = _features(1)
    one = reference_robust.line_directions(points, mask, lists)
    monkeypatch.setattr(reference_robust, "PART_MIN", 5)  # parts of a few hundred features
    for workers in (2, 3, -1):
        assert (
            reference_robust.line_directions(points, mask, lists, workers).tobytes()
            == one.tobytes()
        )
    # unit directions of the features, zero rows elsewhere
    np.testing.assert_allclose(np.linalg.norm(one[mask], axis=1), 1.0)
    assert (one[~mask] == 0).all()


def test_a_stopped_tree_build_raises():
    points = np.random.default_rng(2).random((5000, 3))
    with pytest.raises(_kernels.TreeStopped):
        _kernels.build_tree(points, 2, stop=lambda: True)


@pytest.mark.parametrize("duplicates", [0, 3])
def test_the_tree_built_beside_cleaning_is_the_cleaned_clouds(duplicates):
    points = np.random.default_rng(3).random((20000, 3))
    points[:duplicates] = points[-duplicates - 1 : -1] if duplicates else points[:0]
    geometry = Geometry(points, None, "test")
    cleaned, tree = reference_sequence._clean_beside_tree(geometry, -1, "compiled")
    assert len(cleaned.vertices) == len(points) - duplicates
    if duplicates:
        assert tree is None
        return
    assert tree is not None
    got, want = tree.result(), _kernels.build_tree(cleaned.vertices)
    assert got.depth == want.depth
    for name in ("points", "orig", "boxes"):
        assert getattr(got, name).tobytes() == getattr(want, name).tobytes()
    # one worker: no thread beside cleaning
    assert reference_sequence._clean_beside_tree(geometry, 1, "compiled")[1] is None


def _same_result(got, want) -> None:
    for name in ("mask", "strength", "kept", "thresholds", "candidate_counts"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    np.testing.assert_array_equal(got.distances, want.distances)
    np.testing.assert_array_equal(got.normals, want.normals)
    assert got.scales == want.scales


@pytest.mark.skipif(not _kernels.available(), reason="needs the compiled kernels")
@pytest.mark.parametrize("mode", ["robust", "paper"])
@pytest.mark.parametrize("kind", ["cloud", "mesh"])
def test_each_thread_runs_the_backend_it_names(kind: str, mode: str) -> None:
    """``detect(backend=...)`` on two threads at once, one "numpy" and one "compiled":
    each call runs its own backend all through (``result.backend`` is the backend its
    neighbourhoods were built with) and gives the bits it gives alone. The compiled
    thread runs call after call until the numpy one is done, so they overlap."""
    from meshlab_sharp import detect

    if kind == "cloud":
        args = (shapes.with_outliers(shapes.box_cylinder_points(3000, seed=3), 20, seed=4), None)
    else:
        args = shapes.noisy_mesh(*shapes.cube_grid_mesh(5), 0.05, seed=5)
    options = dict(mode=mode, return_details=True)
    alone = {b: detect(*args, backend=b, **options) for b in _kernels.BACKENDS}
    assert {b: r.backend for b, r in alone.items()} == {b: b for b in _kernels.BACKENDS}
    start, numpy_done = threading.Barrier(2), threading.Event()
    got: dict[str, list] = {b: [] for b in _kernels.BACKENDS}
    errors: list[BaseException] = []

    def run(backend: str) -> None:
        try:
            start.wait()
            while True:
                got[backend].append(detect(*args, backend=backend, **options))
                if backend == "numpy" or numpy_done.is_set() or len(got[backend]) >= 10:
                    break
        except BaseException as exc:  # reported by the test's thread
            errors.append(exc)
        finally:
            if backend == "numpy":
                numpy_done.set()

    threads = [threading.Thread(target=run, args=(b,)) for b in _kernels.BACKENDS]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    assert len(got["numpy"]) == 1 and len(got["compiled"]) >= 2
    for backend, results in got.items():
        for result in results:
            assert result.backend == backend
            _same_result(result, alone[backend])


def test_the_default_backend_is_the_environment_s(monkeypatch) -> None:
    """``backend=None``: ``MESHLAB_SHARP_BACKEND``, read at each call."""
    from meshlab_sharp import detect

    cloud = shapes.random_box_points(500, seed=2)
    monkeypatch.setenv("MESHLAB_SHARP_BACKEND", "numpy")
    assert detect(cloud, mode="paper").backend == "numpy"
    monkeypatch.delenv("MESHLAB_SHARP_BACKEND")
    want = "compiled" if _kernels.available() else "numpy"
    assert detect(cloud, mode="paper").backend == want


@pytest.mark.parametrize("as_points", [False, True])
def test_the_curves_run_the_detection_s_backend(monkeypatch, as_points: bool) -> None:
    """``detect(..., curves=True)`` extracts the curves with the call's backend, not the
    process's default: the native curves only for "compiled" (the same curves either way)."""
    from meshlab_sharp import detect
    from meshlab_sharp.curves import _native

    if not _native.available():
        pytest.skip("the native curves are not built")
    native_calls: list[int] = []
    native = _native.extract_curves

    def counted(*args, **kwargs):
        native_calls.append(1)
        return native(*args, **kwargs)

    monkeypatch.setattr(_native, "extract_curves", counted)
    monkeypatch.delenv("MESHLAB_SHARP_BACKEND", raising=False)
    vertices, faces = shapes.cube_grid_mesh(3)
    runs = {}
    for backend in ("numpy", "compiled"):
        before = len(native_calls)
        runs[backend] = detect(vertices, faces, as_points=as_points, backend=backend, curves=True)
        assert len(native_calls) - before == (backend == "compiled")
    numpy_run, compiled_run = runs["numpy"], runs["compiled"]
    assert len(numpy_run.curves) == len(compiled_run.curves) == 12
    for a, b in zip(numpy_run.curves, compiled_run.curves, strict=True):
        assert a.points.tobytes() == b.points.tobytes()
        assert np.array_equal(a.indices, b.indices)
