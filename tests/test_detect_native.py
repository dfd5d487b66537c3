"""The native library's whole detection (``ms_detect``) as :func:`meshlab_sharp.detect`
takes it by default: the same bits as the Python-driven sequence
(:mod:`meshlab_sharp.reference.detect`), the details included, its options and errors
through the C ABI, the scales grammar (``ms_parse_scales``) the command line's, the
progress bar fed from the library's callback."""

from __future__ import annotations

import argparse
import ctypes
import functools
import importlib.machinery
import sys
from pathlib import Path

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp import _detect_native, _header, _kernels
from meshlab_sharp.cli import parse_scales
from meshlab_sharp.defaults import MAX_KNN_SCALE, MAX_RING_SCALE, MAX_SCALES
from meshlab_sharp.options import check_scales
from meshlab_sharp.progress import Progress
from meshlab_sharp.reference import detect as reference_sequence

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
from bench import cad_mesh


def test_a_built_library_loads_whole():
    """A built library binds every function of the header (a hidden one would leave the
    package on the numpy path, silently)."""
    here = Path(_kernels.__file__).parent
    suffixes = importlib.machinery.EXTENSION_SUFFIXES
    built = any((here / f"_ckernels{suffix}").is_file() for suffix in suffixes)
    assert not built or _kernels.available()


needs_library = pytest.mark.skipif(not _kernels.available(), reason="compiled kernels not built")

LIB = _kernels._LIB
EINPUT = _header.integer("EINPUT")


def _cases() -> dict[str, tuple[np.ndarray, np.ndarray | None, dict[str, object]]]:
    cube = shapes.cube_grid_mesh(3)
    return {
        "box": (shapes.random_box_points(2000, seed=2), None, {}),
        "box-unweighted": (shapes.random_box_points(2000, seed=2), None, {"weighting": "none"}),
        "noisy-outliers": (
            shapes.with_outliers(shapes.noisy_box_points(3000, 0.6, seed=2), 30, seed=3),
            None,
            {},
        ),
        "cube-mesh": (*cube, {}),
        "noisy-mesh": (*shapes.noisy_mesh(*cube, 0.2, seed=5), {"scales": (1, 3)}),
        "cube-mesh-as-points": (*cube, {"as_points": True}),
        # faces wound either way round (the normals' windings turn some)
        "flipped-mesh": (cube[0], _flipped(cube[1]), {}),
        # a vertex order the library renumbers breadth-first (with duplicates merged)
        "scattered-mesh": (*_scattered_mesh(), {}),
    }


def _flipped(faces: np.ndarray) -> np.ndarray:
    """``faces`` with every third one wound the other way round."""
    out = faces.copy()
    out[::3] = out[::3, ::-1]
    return out


@functools.cache
def _scattered_mesh() -> tuple[np.ndarray, np.ndarray]:
    """The bench's CAD mesh of about 80,000 vertices (some duplicated) in a scattered
    vertex order: one cleaning renumbers (``ms_scattered_faces``)."""
    vertices, faces = shapes.shuffled_mesh(*cad_mesh(80_000), seed=3)
    assert _kernels.scattered_faces(faces, len(vertices))
    return vertices, faces


@needs_library
@pytest.mark.parametrize("mode", ["paper", "robust"])
@pytest.mark.parametrize("case", sorted(_cases()))
def test_the_library_gives_the_python_driven_bits(case, mode):
    """Every output of the library's sequence (the default path of clouds and meshes; a
    scattered mesh renumbered) equals the Python-driven sequence's, bit for bit, on one
    thread and on every core, with and without the per-scale details."""
    vertices, faces, options = _cases()[case]
    expected = reference_sequence.detect(
        vertices, faces, mode=mode, return_details=True, backend="compiled", **options
    )
    for workers, details in ((1, False), (-1, False), (-1, True)):
        got = meshlab_sharp.detect(
            vertices, faces, mode=mode, workers=workers, return_details=details, **options
        )
        assert "thresholds" in got.timings  # the library's
        assert got.scales == expected.scales and got.kind == expected.kind
        if details:
            for name in ("distances", "normals"):
                a, b = np.asarray(getattr(got, name)), np.asarray(getattr(expected, name))
                assert a.shape == b.shape and a.tobytes() == b.tobytes(), name
        else:
            assert got.distances is None and got.normals is None
        assert got.n_clean == expected.n_clean
        for name in ("mask", "strength", "thresholds", "candidate_counts", "kept"):
            a, b = np.asarray(getattr(got, name)), np.asarray(getattr(expected, name))
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), name
    if case == "noisy-outliers" and mode == "robust":
        assert got.scales[0] > 12 and not got.kept.all()  # grown scales, isolated points


@needs_library
@pytest.mark.parametrize("mode", ["paper", "robust"])
@pytest.mark.parametrize("case", ["noisy-outliers", "noisy-mesh"])
def test_the_librarys_details_are_the_numpy_references(case, mode):
    """The library's results equal the numpy reference's: the decisions bit for bit, the
    details to the last bits (the two backends' sums round differently; the normals'
    lines), NaN at the same vertices."""
    vertices, faces, options = _cases()[case]
    expected = reference_sequence.detect(
        vertices, faces, mode=mode, return_details=True, backend="numpy", **options
    )
    got = meshlab_sharp.detect(vertices, faces, mode=mode, return_details=True, **options)
    assert "thresholds" in got.timings  # the library's
    for name in ("mask", "strength", "kept", "thresholds", "candidate_counts"):
        a, b = np.asarray(getattr(got, name)), np.asarray(getattr(expected, name))
        assert a.shape == b.shape and a.tobytes() == b.tobytes(), name
    assert got.distances.shape == expected.distances.shape
    np.testing.assert_allclose(
        got.distances, expected.distances, rtol=1e-9, atol=1e-12, equal_nan=True
    )
    # the normals' lines (a PCA normal's sign is either eigenvector's)
    assert got.normals.shape == expected.normals.shape
    dots = np.abs(np.sum(got.normals * expected.normals, axis=-1))
    taking_part = ~np.isnan(expected.distances)
    assert (np.isnan(dots) == ~taking_part).all()
    np.testing.assert_allclose(dots[taking_part], 1.0, atol=1e-9)
    assert np.isnan(got.distances).any() == (not got.kept.all())


@needs_library
def test_a_refused_input_gives_the_commands_message():
    """An input the library refuses takes the Python-driven sequence's error message."""
    with pytest.raises(meshlab_sharp.InputError, match=r"30 distinct points, fewer than .* k = 40"):
        meshlab_sharp.detect(shapes.random_box_points(30))
    with pytest.raises(meshlab_sharp.InputError, match="all 50 points are identical"):
        meshlab_sharp.detect(np.ones((50, 3)))


def _detect(
    vertices: np.ndarray, faces: np.ndarray | None = None, **fields: object
) -> tuple[int, str]:
    """ms_detect's status and message on a cloud (or the mesh of ``faces``) with options
    changed by ``fields``."""
    options = _detect_native._Options()
    LIB.ms_detect_defaults(ctypes.byref(options))
    for name, value in fields.items():
        setattr(options, name, value)
    handle, error = ctypes.c_void_p(), ctypes.create_string_buffer(256)
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = None if faces is None else np.ascontiguousarray(faces, dtype=np.int64)
    status = LIB.ms_detect(
        v.ctypes.data, len(v), None if f is None else f.ctypes.data, 0 if f is None else len(f),
        ctypes.byref(options), None, None, ctypes.byref(handle), error, len(error),
    )  # fmt: skip
    LIB.ms_detection_free(handle)
    return status, error.value.decode()


@needs_library
def test_the_defaults_are_the_headers():
    options = _detect_native._Options()
    LIB.ms_detect_defaults(ctypes.byref(options))
    assert (options.mode, options.weighting, options.as_points, options.threads) == (1, 0, 0, 0)
    assert tuple(options.knn_scales[: options.n_knn_scales]) == (12, 16, 20, 24, 28, 32, 36, 40)
    assert tuple(options.ring_scales[: options.n_ring_scales]) == (1, 2, 3, 4)
    assert _detect(shapes.random_box_points(500)) == (0, "")


@needs_library
@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"mode": 2}, "unknown mode"),
        ({"weighting": -1}, "unknown weighting"),
        ({"n_knn_scales": 0}, "invalid scales"),
        ({"n_ring_scales": 65}, "invalid scales"),
        ({"knn_scales": (ctypes.c_int * 64)(1, 2)}, "invalid scales"),
    ],
)
def test_bad_options_are_refused_with_a_message(fields, message):
    assert _detect(shapes.random_box_points(500), **fields) == (EINPUT, message)


def _scales(kind: str, *values: int) -> dict[str, object]:
    """ms_detect_options fields of a list of ``kind`` scales (``knn`` or ``ring``)."""
    return {f"n_{kind}_scales": len(values), f"{kind}_scales": (ctypes.c_int * MAX_SCALES)(*values)}


@needs_library
@pytest.mark.parametrize(
    ("mesh", "as_points", "kind", "scales", "answer"),
    [
        (False, 0, "knn", (12, MAX_KNN_SCALE + 1), "kNN sizes must be <= 512, got 513"),
        (True, 0, "ring", (1, MAX_RING_SCALE + 1), "rings must be <= 32, got 33"),
        (True, 1, "knn", (12, MAX_KNN_SCALE + 88), "kNN sizes must be <= 512, got 600"),
        (True, 0, "ring", (1, 2, MAX_RING_SCALE), ""),  # at the maximum: it runs
        (True, 0, "knn", (12, MAX_KNN_SCALE + 88), ""),  # a mesh's k: unused
        (False, 0, "ring", (1, MAX_RING_SCALE + 8), ""),  # a cloud's rings: unused
    ],
)  # fmt: skip
def test_scales_above_the_maxima_are_refused_with_the_commands_message(
    mesh, as_points, kind, scales, answer
):
    """The scales the detection would use, above the header's maxima: refused with the
    command line's message before any work; the unused kind's scales are not checked."""
    vertices, faces = shapes.cube_grid_mesh(4)
    if not mesh:
        vertices, faces = shapes.random_box_points(500), None
    status = _detect(vertices, faces, as_points=as_points, **_scales(kind, *scales))
    assert status == ((EINPUT, answer) if answer else (0, ""))
    if answer:
        with pytest.raises(meshlab_sharp.InputError, match=answer):
            check_scales(scales, (), "mesh" if kind == "ring" else "points")


@needs_library
@pytest.mark.parametrize(
    ("vertices", "message"),
    [
        (np.zeros((0, 3)), "the layer has no vertices"),
        (np.array([[0.0, 0.0, np.nan]] * 50), "vertex 0 has a non-finite coordinate (NaN or inf)"),
        (np.tile([[1.0, 2.0, 3.0]], (60, 1)), "all 60 points are identical"),
    ],
)
def test_bad_input_is_refused_with_a_message(vertices, message):
    assert _detect(vertices) == (EINPUT, message)


def _parse(text: str, minimum: int = 2) -> list[int] | str:
    out, error = (ctypes.c_int * 64)(), ctypes.create_string_buffer(256)
    count = LIB.ms_parse_scales(text.encode(), minimum, out, 64, error, len(error))
    return list(out[:count]) if count >= 0 else error.value.decode()


@needs_library
@pytest.mark.parametrize(
    "text",
    ["12 16 20", "20,12, 16", " 8\t12  16 ", "12:40:4", "4:4", "+12 16", "16 16 12", "8 12,16"]
    + ["8,,12", "", "12;16", "12.0 16", "4:2", "1:2:0", "2:66", "99999999999 12", "1 12"],
)
def test_the_library_reads_scales_as_the_command_line_does(text):
    try:
        expected: list[int] | str = sorted(set(parse_scales(text)))
    except argparse.ArgumentTypeError as error:
        expected = str(error)
    if isinstance(expected, list) and expected[0] < 2:
        expected = f"scales must be >= 2, got {expected[0]}"
    assert _parse(text) == expected


@needs_library
def test_the_scales_format_reads_back():
    scales = (ctypes.c_int * 3)(8, 12, 40)
    text = ctypes.create_string_buffer(64)
    assert LIB.ms_format_scales(scales, 3, text, len(text)) == 7
    assert text.value == b"8 12 40" and _parse("8 12 40") == [8, 12, 40]
    short = ctypes.create_string_buffer(4)
    assert LIB.ms_format_scales(scales, 3, short, len(short)) == 7 and short.value == b"8 1"


@needs_library
def test_the_progress_bar_is_fed_by_the_library():
    """The bar moves from the library's callback, never past its end, and ends full."""
    steps: list[tuple[str, int]] = []

    class Recorder(Progress):
        def step(self, label: str, n: int = 1) -> None:
            steps.append((label, n))
            super().step(label, n)

    bar = Recorder(11, enabled=False)
    meshlab_sharp.detect(shapes.random_box_points(100000, seed=1), progress=bar)
    assert bar.done == bar.total
    labels = [label for label, _ in steps]
    assert "neighbours and projected distances" in labels and labels[-1] == "done"
    assert sum(n for _, n in steps[:-1]) == bar.total
