"""The native library's feature curves (native/src/curves.cpp behind the C ABI of
native/include/meshlab_sharp.h): the ctypes binding against the header, the
curves to the bit of the numpy reference (meshlab_sharp.reference.curves) on small
clouds and meshes, and the C ABI's refusals."""

from __future__ import annotations

import ctypes
import re
import subprocess
import sys

import numpy as np
import pytest
import shapes
from scipy.spatial import cKDTree

import meshlab_sharp
from evaluation import groundtruth as gt
from meshlab_sharp import _header
from meshlab_sharp.curves import _native, extract_curves
from meshlab_sharp.reference import curves as reference

pytestmark = pytest.mark.skipif(not _native.available(), reason="the native curves are not built")

HEADER = _header.CURVES.path
#: C types of the header's prototypes, as ctypes declares them.
C_TYPES = {
    "void": None,
    "int": ctypes.c_int,
    "int64_t": ctypes.c_int64,
    "double": ctypes.c_double,
}


def _ctype(declaration: str) -> type | None:
    """The ctypes type of a C parameter or return declaration (its name dropped)."""
    words = declaration.replace("const ", "").strip()
    if "*" in words:
        return ctypes.c_void_p
    return C_TYPES[words.split()[0]]


def test_the_binding_declares_the_headers_prototypes():
    """Every ``ms_curves_`` function of the header is in _native.SIGNATURES with the
    header's return and argument types, and nothing else is; the math table's fields
    are the header's, in its order."""
    text = re.sub(r"/\*.*?\*/", "", HEADER.read_text(), flags=re.S)
    found = {}
    for ret, name, args in re.findall(r"^([\w ]+?\**)\s*\b(ms_curves_\w+)\(([^)]*)\);", text, re.M):
        params = [a for a in (p.strip() for p in args.split(",")) if a and a != "void"]
        found[name] = (_ctype(ret), [_ctype(p) for p in params])
    assert len(found) == 8
    assert found == _native.SIGNATURES
    struct = re.search(r"typedef struct ms_curves_math \{(.*?)\}", text, re.S)
    assert struct is not None
    fields = re.findall(r"ms_curves_fn\d (\w+);", struct.group(1))
    assert fields == [name for name, _ in _native._Math._fields_] == ["exp", "acos", "atan2"]


def _assert_same(got: reference.CurveSet, want: reference.CurveSet) -> None:
    """The same curves and corners to the bit."""
    assert got.spacing == want.spacing
    assert len(got.curves) == len(want.curves)
    for (p, i, c, length), (wp, wi, wc, wlength) in zip(got.curves, want.curves, strict=True):
        assert p.tobytes() == np.ascontiguousarray(wp).tobytes() and p.shape == wp.shape
        np.testing.assert_array_equal(i, wi)
        assert (c, np.float64(length).tobytes()) == (wc, np.float64(wlength).tobytes())
    assert got.corner_points.tobytes() == want.corner_points.tobytes()
    np.testing.assert_array_equal(got.corner_indices, want.corner_indices)


def _cloud(case: str) -> tuple[np.ndarray, str]:
    """A small cloud with edges and corners, and the mode to detect it in."""
    if case == "cube-grid":  # a regular grid: neighbours at equal distances
        return shapes.cube_grid_points(15), "robust"
    if case == "random-box":
        return shapes.random_box_points(4000, seed=2), "robust"
    if case == "iid-box":  # iid: the spacing from the density, short pieces joined
        return shapes.random_box_points(8000, seed=2), "robust"
    if case == "box-cylinder":
        return shapes.box_cylinder_points(4000, seed=3), "paper"
    if case == "noisy-box":
        return shapes.noisy_box_points(8000, 0.01, seed=4), "robust"
    if case == "thin-tube":  # walls 3 spacings thick (MS_CURVE_WALL_GAP)
        return gt.make_thin_part("tube", 3, n_points=3000).vertices, "robust"
    if case == "iid":  # no surface: false detections everywhere
        return np.random.default_rng(11).random((4000, 3)), "robust"
    raise AssertionError(case)


@pytest.mark.parametrize(
    "case", ["cube-grid", "random-box", "iid-box", "box-cylinder", "noisy-box", "thin-tube", "iid"]
)
def test_cloud_curves_are_the_references_to_the_bit(case):
    """Refined positions, indices, loops, lengths, corners and their order: the same
    bits as the numpy reference, and some curves to compare; on the iid box, the
    spacing is the density's (:func:`meshlab_sharp.reference.curves.extract.cloud_spacing`)
    and its edges are one curve each."""
    vertices, mode = _cloud(case)
    result = meshlab_sharp.detect(vertices, mode=mode)
    want = reference.extract_curves(vertices, result.mask, None, result.kept)
    got = _native.extract_curves(vertices, result.mask, None, result.kept, None)
    assert want.curves
    _assert_same(got, want)
    if case in ("cube-grid", "iid-box"):  # one curve per edge of the box, corner to corner
        assert len(got.curves) == 12 and len(got.corner_points) == 8
    if case == "iid-box":
        features = np.unique(vertices[result.mask], axis=0)
        d, _ = cKDTree(vertices).query(features, k=reference.extract.DENSITY_NEIGHBOURS + 1)
        q = reference.extract.DENSITY_SCALE * np.median(d[:, -1]) / np.median(d[:, 1])
        assert q > 1.3  # irregular: the spacing is d q^1.5
        assert got.spacing == pytest.approx(np.median(d[:, 1]) * q**1.5, rel=1e-12)


def test_a_larger_grid_box_gives_the_references_curves():
    """``bounds`` (out of core: the whole cloud's box) lays the refinement's grid over
    the given box, in the library as in the reference: with a box larger than the
    points' the curves are still the reference's to the bit."""
    vertices, _ = _cloud("random-box")
    result = meshlab_sharp.detect(vertices)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    for box in ((lo, hi), (lo - 0.37, hi + 1.3)):
        want = reference.extract_curves(vertices, result.mask, None, result.kept, box)
        _assert_same(_native.extract_curves(vertices, result.mask, None, result.kept, box), want)


@pytest.mark.parametrize("shift", [2.0**30, 2.0**45])
def test_two_clusters_far_apart_give_each_ones_curves(shift):
    """Two copies of a cube's edges (spacing 1) ``shift`` apart on every axis: the grid
    over both has far more cells than an int64 numbers (its cells keyed by their three
    coordinates), and each copy gets its 12 curves: the first the cube's alone to the
    bit, the second the same chains (coordinates of 2**30 and more cost the refined
    positions some precision); the reference's to the bit."""
    cube = shapes.cube_grid_points(15) * 7.0
    edges = shapes.on_cube_edges(cube, half=7.0)
    alone = _native.extract_curves(cube, edges, None, np.ones(len(cube), bool), None)
    points = np.vstack([cube, cube + shift])
    mask, kept = np.concatenate([edges, edges]), np.ones(len(points), bool)
    got = _native.extract_curves(points, mask, None, kept, None)
    _assert_same(got, reference.extract_curves(points, mask, None, kept))
    assert len(alone.curves) == 12 and len(got.curves) == 24 and len(got.corner_points) == 16
    near = [c for c in got.curves if c[0].max() < shift / 2]
    far = [c for c in got.curves if c[0].min() > shift / 2]
    assert len(near) == len(far) == 12
    for (p, *_), (q, *_) in zip(near, alone.curves, strict=True):
        assert p.tobytes() == q.tobytes()
    assert sorted(len(p) for p, *_ in far) == sorted(len(p) for p, *_ in alone.curves)
    for p, *_ in far:  # on the cube's edges: two coordinates within 0.1 of +-7
        off = np.abs(np.abs(p - shift) - 7.0)
        assert ((off < 0.1).sum(axis=1) >= 2).all()


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_mesh_curves_are_the_references_to_the_bit(dtype):
    """Mesh curves (chains of the mesh's edges; faces int32 or int64): the reference's,
    12 edges and 8 corners on a cube."""
    vertices, faces = shapes.cube_grid_mesh(4)
    result = meshlab_sharp.detect(vertices, faces)
    want = reference.extract_curves(vertices, result.mask, faces, result.kept)
    got = _native.extract_curves(vertices, result.mask, faces.astype(dtype), result.kept, None)
    _assert_same(got, want)
    assert len(got.curves) == 12 and len(got.corner_points) == 8
    moved, moved_faces = shapes.shuffled_mesh(*shapes.noisy_mesh(vertices, faces, 0.05))
    result = meshlab_sharp.detect(moved, moved_faces)
    want = reference.extract_curves(moved, result.mask, moved_faces, result.kept)
    _assert_same(_native.extract_curves(moved, result.mask, moved_faces, result.kept, None), want)


def test_the_public_curves_do_not_depend_on_the_backend(monkeypatch):
    """``extract_curves`` with either backend, and without the built library: the same
    Curve objects (kind and parameters included), each ``length`` the library's."""
    vertices, _ = _cloud("box-cylinder")
    result = meshlab_sharp.detect(vertices, mode="paper")
    args = (vertices, result.mask, None, result.kept)
    runs = [extract_curves(*args, backend=b) for b in ("compiled", "numpy")]
    monkeypatch.setattr(_native, "_LIB", None)
    runs.append(extract_curves(*args, backend="compiled"))
    monkeypatch.undo()
    native = _native.extract_curves(*args, None)
    (curves, corners), *others = runs
    assert [c.length for c in curves] == [length for *_, length in native.curves]
    for other, other_corners in others:
        assert len(other) == len(curves)
        for a, b in zip(curves, other, strict=True):
            assert a.points.tobytes() == b.points.tobytes()
            np.testing.assert_array_equal(a.indices, b.indices)
            assert (a.closed, a.kind, a.params.keys()) == (b.closed, b.kind, b.params.keys())
            for key, value in a.params.items():
                np.testing.assert_array_equal(value, b.params[key])
        assert corners.points.tobytes() == other_corners.points.tobytes()
        np.testing.assert_array_equal(corners.indices, other_corners.indices)
    with pytest.raises(ValueError, match="unknown backend 'fast'"):
        extract_curves(*args, backend="fast")


def test_too_few_features_give_no_curve():
    """None, one, or two features at one position: no curve, no corner, spacing 0."""
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    for mask in ([0, 0, 0], [0, 1, 0], [1, 0, 1]):
        got = _native.extract_curves(vertices, np.array(mask, bool), None, None, None)
        assert (got.curves, len(got.corner_points), got.spacing) == ([], 0, 0.0)
    got = _native.extract_curves(np.zeros((0, 3)), np.zeros(0, bool), None, None, None)
    assert (got.curves, len(got.corner_points)) == ([], 0)


def test_the_c_abi_refuses_bad_input():
    """A face index outside the vertices, an unknown face index size, a null result
    pointer, a negative count, or a NaN or infinite coordinate the curves read (a
    cloud's valid point, any vertex of a mesh): MS_CURVES_EINVAL (-2), no result."""
    lib = _native._LIB
    vertices = np.zeros((3, 3))
    feature = np.ones(3, np.uint8)
    handle = ctypes.c_void_p()

    def extract(faces: np.ndarray | None, size: int, n: int = 3, no_out: bool = False) -> int:
        m = 0 if faces is None else len(faces)
        ptr = None if faces is None else faces.ctypes.data
        vp, fp = vertices.ctypes.data, feature.ctypes.data
        out = None if no_out else ctypes.byref(handle)
        return lib.ms_curves_extract(vp, fp, None, n, ptr, size, m, None, None, out)

    for bad in ([[0, 1, 3]], [[0, -1, 2]]):
        assert extract(np.array(bad, np.int64), 8) == -2
        assert handle.value is None
        assert extract(np.array(bad, np.int32), 4) == -2
    assert extract(np.array([[0, 1, 2]], np.int64), 2) == -2
    assert extract(None, 8, n=-1) == -2
    assert extract(None, 8, no_out=True) == -2
    for bad in (np.nan, np.inf, -np.inf):
        vertices[1, 2] = bad
        assert extract(None, 8) == -2
        assert extract(np.array([[0, 1, 2]], np.int64), 8) == -2
        valid = np.array([1, 0, 1], np.uint8)  # never read: anything goes
        args = (vertices.ctypes.data, feature.ctypes.data, valid.ctypes.data, 3, None, 8, 0)
        assert lib.ms_curves_extract(*args, None, None, ctypes.byref(handle)) == 0
        lib.ms_curves_free(handle)
    vertices[1, 2] = 0.0
    assert extract(np.array([[0, 1, 2]], np.int64), 8) == 0
    assert lib.ms_curves_count(handle) == 0
    lib.ms_curves_free(handle)
    with pytest.raises(ValueError, match=r"ms_curves_extract failed \(status -2\)"):
        _native.extract_curves(vertices, feature.astype(bool), np.array([[0, 1, 5]]), None, None)


#: Run in a child process: the native curves of 200,000 feature points on a zigzag sheet
#: under an address-space limit a few MB above what the process maps, then again with
#: the limit lifted. Prints what each call gave.
_UNDER_A_LIMIT = """
import resource
import numpy as np
from meshlab_sharp.curves import _native

rng = np.random.default_rng(0)
x, y = rng.random(200_000), rng.random(200_000)
points = np.c_[x, y, np.abs((x * 20) % 1 - 0.5) / 20]
mask = np.ones(len(points), bool)
_native.extract_curves(points[:2000], mask[:2000], None, None, None)  # the library loaded
with open("/proc/self/statm") as f:
    mapped = int(f.read().split()[0]) * resource.getpagesize()
resource.setrlimit(resource.RLIMIT_AS, (mapped + (8 << 20), resource.RLIM_INFINITY))
try:
    _native.extract_curves(points, mask, None, None, None)
    print("no error")
except MemoryError as exc:
    print("MemoryError:", exc)
resource.setrlimit(resource.RLIMIT_AS, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
print("then", len(_native.extract_curves(points, mask, None, None, None).curves), "curves")
"""


def test_out_of_memory_in_the_library_is_a_memory_error():
    """std::bad_alloc inside the library is its out-of-memory status at the C ABI, a
    MemoryError in Python; the process goes on, and the same call with memory to spare
    gives curves."""
    done = subprocess.run(
        [sys.executable, "-c", _UNDER_A_LIMIT], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "MemoryError: ms_curves_extract failed (status -1)", done.stdout
    assert re.fullmatch(r"then [1-9][0-9]* curves", lines[1]), done.stdout
