"""One far point cannot move the result nor the curves, and the unit never matters, out of
core too.

A single corrupted coordinate (1e300 in a binary file) used to set the unit the cloud was
scaled to: the rest shrank until its squared distances underflowed, and the features
changed or vanished. Far points are dropped first, as isolated points are (counted in
``n_dropped``), and the out-of-core store holds the coordinates in the in-memory run's
unit.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import shapes
from files import write_ply
from shapes import random_box_points

from meshlab_sharp import _kernels, detect
from meshlab_sharp.cli import main
from meshlab_sharp.curves import extract_curves
from meshlab_sharp.neighbourhoods import FAR_SPREADS, far_points

BACKENDS = ["numpy", "compiled"] if _kernels.available() else ["numpy"]
FAR = [1e3, 1e50, 1e100, 1e160, 1e200, 1e300, 1.7e308]


def _with(points: np.ndarray, *extra: tuple[float, float, float]) -> np.ndarray:
    return np.vstack([points, np.array(extra, float)])


def _check_same(result, base, n_box: int) -> None:
    """The box's own features, the extra points dropped (not features), no warning."""
    np.testing.assert_array_equal(result.mask[:n_box], base.mask)
    np.testing.assert_array_equal(result.strength[:n_box], base.strength)
    assert not result.mask[n_box:].any()
    assert not result.kept[n_box:].any()
    assert result.summary()["n_dropped"] == base.summary()["n_dropped"] + len(result.mask) - n_box


def test_far_points_found_only_far() -> None:
    box = random_box_points(3000)
    assert far_points(box) is None
    # just inside the reach: kept (the unit then stays in range); beyond it: far
    spread = float(np.ptp(np.quantile(box, [0.25, 0.75], axis=0), axis=0).max())
    median = np.median(box, axis=0)
    near = median + [0.5 * FAR_SPREADS * spread, 0.0, 0.0]
    far = median - [0.0, 0.0, 2.0 * FAR_SPREADS * spread]
    got = far_points(_with(box, tuple(near), tuple(far), (1e308, -1e308, 0.0)))
    assert got is not None
    np.testing.assert_array_equal(np.flatnonzero(got), [3001, 3002])
    assert far_points(np.zeros((10, 3))) is None  # no spread: nothing to measure


def test_one_far_point_leaves_the_box_features() -> None:
    box = random_box_points(20000)
    backend = BACKENDS[-1]
    base = detect(box, backend=backend)
    assert base.n_features == 751
    for far in FAR:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            got = detect(_with(box, (far, 0.5 * far, -far)), backend=backend)
        _check_same(got, base, len(box))
    both = _with(box, (1.7e308, 1.7e308, 1.7e308), (-1.7e308, -1.7e308, -1.7e308))
    _check_same(detect(both, backend=backend), base, len(box))


@pytest.mark.parametrize("backend", BACKENDS)
def test_far_points_same_in_both_paths(backend: str) -> None:
    box = random_box_points(3000)
    base = detect(box, backend=backend)
    for far in (1e100, 1e200, 1.7e308):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            got = detect(_with(box, (far, -far, far)), mode="robust", backend=backend)
        _check_same(got, base, len(box))
    paper = detect(box, mode="paper", backend=backend)
    got = detect(_with(box, (1e250, 0.0, 0.0)), mode="paper", backend=backend)
    _check_same(got, paper, len(box))


@pytest.mark.skipif(not _kernels.available(), reason="out of core needs the compiled kernels")
@pytest.mark.parametrize("scale", [1e-300, 1e-120, 1e155, 1e300, 2.0**-1000])
def test_uniform_scaling_out_of_core(scale: float) -> None:
    box = random_box_points(4000)
    base = detect(box)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow RuntimeWarning either
        tiled = detect(box * scale, max_memory="2GB")
        in_memory = detect(box * scale)
    np.testing.assert_array_equal(tiled.mask, base.mask)
    np.testing.assert_array_equal(in_memory.mask, base.mask)


@pytest.mark.skipif(not _kernels.available(), reason="out of core needs the compiled kernels")
@pytest.mark.parametrize("mode", ["robust", "paper"])
def test_far_points_out_of_core(mode: str) -> None:
    box = random_box_points(4000)
    base = detect(box, mode=mode)
    for far in (1e200, 1.7e308):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            got = detect(
                _with(box, (far, -far, far), (-far, 0.0, 1.0)), mode=mode, max_memory="2GB"
            )
        _check_same(got, base, len(box))


def _same_curves(got, base) -> None:
    """The same curves and corners, bit for bit (a cloud's far points come last, so
    the indices of the box's points do not move)."""
    assert len(got.curves) == len(base.curves) > 0
    for a, b in zip(got.curves, base.curves, strict=True):
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.indices, b.indices)
        assert (a.closed, a.kind) == (b.closed, b.kind)
    np.testing.assert_array_equal(got.corners.points, base.corners.points)
    np.testing.assert_array_equal(got.corners.indices, base.corners.indices)


@pytest.mark.parametrize("backend", BACKENDS)
def test_far_points_leave_the_curves(backend: str) -> None:
    """The curves' grid is laid over the valid points alone: a far point, which the
    detection drops, neither stretches it past what its keys number nor moves it."""
    box = random_box_points(3000)
    base = detect(box, curves=True, backend=backend)
    for far in (1e20, 1e100, 1.7e308):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no invalid cast or overflow either
            got = detect(_with(box, (far, 0.5 * far, -far)), curves=True, backend=backend)
        _same_curves(got, base)
    both = _with(box, (1e20, 1e20, 1e20), (-1.7e308, -1.7e308, -1.7e308))
    _same_curves(detect(both, curves=True, backend=backend), base)


@pytest.mark.parametrize("backend", BACKENDS)
def test_far_vertices_leave_a_meshs_curves(backend: str) -> None:
    """A mesh keeps its far vertices (only clouds drop far points): a far face or an
    unreferenced far vertex leaves the part's curves; read as points, the far vertex
    is dropped and the cloud's curves stay too."""
    vertices, faces = shapes.cube_grid_mesh(8)
    n = len(vertices)
    far = _with(vertices, (1e20, 0.0, 0.0), (1e20, 1.0, 0.0), (1e20, 0.0, 1.0))
    for as_points in (False, True):
        base = detect(vertices, faces=faces, as_points=as_points, curves=True, backend=backend)
        for more in (faces, np.vstack([faces, [[n, n + 1, n + 2]]])):
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                got = detect(far, faces=more, as_points=as_points, curves=True, backend=backend)
            _same_curves(got, base)


@pytest.mark.skipif(not _kernels.available(), reason="out of core needs the compiled kernels")
def test_far_points_leave_the_curves_out_of_core() -> None:
    box = random_box_points(4000)
    base = detect(box, curves=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = detect(_with(box, (1e20, -1e20, 1e20)), curves=True, max_memory="2GB")
    _same_curves(got, base)


def test_far_points_leave_the_command_lines_curves(tmp_path) -> None:
    box = random_box_points(3000).astype(np.float32)  # the file's precision
    curves = {}
    for name, points in (("box", box), ("far", _with(box, (1e20, 1e20, -1e20)))):
        src = write_ply(tmp_path / f"{name}.ply", points)
        out = tmp_path / f"{name}-curves.ply"
        assert main(["detect", str(src), "--curves", str(out), "--quiet"]) == 0
        curves[name] = out.read_bytes()
    assert curves["far"] == curves["box"]


@pytest.mark.parametrize("backend", BACKENDS)
def test_curves_refuse_nan_and_inf_they_would_read(backend: str) -> None:
    """A NaN or infinite coordinate the curves read is a ValueError; on a point the
    detection did not keep it is never read, and the curves stay."""
    box = random_box_points(3000)
    result = detect(box, backend=backend)
    base, _ = extract_curves(box, result.mask, valid=result.kept, backend=backend)
    for bad in (np.nan, np.inf):
        for i in (int(np.flatnonzero(result.mask)[0]), int(np.flatnonzero(~result.mask)[0])):
            points = box.copy()
            points[i, 1] = bad
            with pytest.raises(ValueError, match="finite coordinates"):
                extract_curves(points, result.mask, valid=result.kept, backend=backend)
            valid = result.kept.copy()
            valid[i] = False
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                got, _ = extract_curves(points, result.mask, valid=valid, backend=backend)
            assert len(got) > 0
            if not result.mask[i]:  # a point the curves read only near the features
                assert len(got) == len(base)
