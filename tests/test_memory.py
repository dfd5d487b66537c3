"""Memory kept between calls: a batch pipeline calls ``detect`` thousands of times.

NumPy arrays do not count towards the garbage collector's thresholds, so arrays held
in a reference cycle stay until a collection happens to run: robust mode's setup once
referred to itself through its rule, and a process grew by about 55 bytes a point per
call (1M points: 54 MB a call, 634 MB after 8 calls). ``detect`` must leave nothing for
the collector.
"""

import gc
import time
import tracemalloc

import numpy as np
import pytest
from shapes import box_cylinder_points, cube_grid_mesh, noisy_box_points, with_outliers

import meshlab_sharp as ms
from meshlab_sharp import _kernels

CASES = {
    "cloud": lambda: (box_cylinder_points(3000),),
    "mesh": lambda: cube_grid_mesh(6),
    "noisy cloud with outliers": lambda: (with_outliers(noisy_box_points(4000, 0.3), 20),),
}


def _settle(timeout: float = 10.0) -> None:
    """Collect until a collection finds nothing: the garbage of earlier tests' background
    threads (a Dask cluster's event loop, closed by test_tiles.py, finishes in its own
    thread a moment later) must not count as detect's."""
    deadline = time.monotonic() + timeout
    while gc.collect() and time.monotonic() < deadline:
        time.sleep(0.05)


@pytest.mark.parametrize("backend", ["compiled", "numpy"])
@pytest.mark.parametrize("mode", ["robust", "paper"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_detect_leaves_no_reference_cycles(case: str, mode: str, backend: str) -> None:
    if backend == "compiled" and not _kernels.available():
        pytest.skip("compiled kernel not built")
    args = CASES[case]()
    assert callable(ms.detect)  # imported first (lazily): an import's garbage is not detect's
    _settle()
    gc.disable()
    try:
        result = ms.detect(*args, mode=mode, backend=backend, return_details=True)
        assert result.mask.any()
        del result
        gc.set_debug(gc.DEBUG_SAVEALL)
        found = gc.collect()
        kinds = sorted({type(o).__name__ for o in gc.garbage})
    finally:
        gc.garbage.clear()
        gc.set_debug(0)
        gc.enable()
    assert found == 0, f"detect left {found} objects in reference cycles: {kinds}"


def test_repeated_detect_keeps_no_arrays() -> None:
    """Ten robust calls on one cloud: the memory NumPy holds does not grow."""

    points = box_cylinder_points(20000)
    gc.collect()
    gc.disable()
    tracemalloc.start()
    try:
        ms.detect(points)
        first = tracemalloc.get_traced_memory()[0]
        for _ in range(10):
            ms.detect(points)
        growth = tracemalloc.get_traced_memory()[0] - first
    finally:
        tracemalloc.stop()
        gc.enable()
    # one call's arrays are about 55 bytes a point (1.1 MB here): ten calls kept would
    # be 11 MB; allow a few small caches
    assert growth < 0.2 * 55 * len(points), growth


@pytest.mark.parametrize("mode", ["robust", "paper"])
def test_cleaned_faces_freed_before_the_scales_pass(mode: str, monkeypatch) -> None:
    """The cleaned faces (48 bytes a vertex, a copy of the input's) are gone by the time
    the scales' pass runs, where the peak memory is: neither the ring neighbourhoods
    (compiled: their adjacency only) nor robust mode's set-up keeps them (the
    Python-driven sequence; the library's sequence drops them too, once the normals are
    known)."""
    if not _kernels.available():
        pytest.skip("compiled kernel not built")
    import weakref

    from meshlab_sharp.reference import detect as pipeline

    vertices, faces = cube_grid_mesh(6)
    faces = faces.astype(np.int32)  # cleaning then makes its own int64 copy
    refs: list[weakref.ref] = []
    alive: list[bool] = []
    clean, run_scales = pipeline.clean, pipeline.run_scales

    def spy_clean(*args, **kwargs):
        cleaned = clean(*args, **kwargs)
        assert cleaned.faces is not faces
        refs.append(weakref.ref(cleaned.faces))
        return cleaned

    def spy_run_scales(*args, **kwargs):
        alive.append(refs[0]() is not None)
        return run_scales(*args, **kwargs)

    monkeypatch.setattr(pipeline, "clean", spy_clean)
    monkeypatch.setattr(pipeline, "run_scales", spy_run_scales)
    result = pipeline.detect(vertices, faces, mode=mode, return_details=True, backend="compiled")
    assert result.mask.any()
    assert alive == [False]
