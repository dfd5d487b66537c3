"""The native library's feature curves (``_ccurves``, built from native/src/curves*.cpp)
loaded with ctypes: the C ABI of ``native/include/meshlab_sharp.h``.

``tests/test_curves_native.py`` checks :data:`SIGNATURES` against the header's
prototypes. The library takes numpy's exp, arccos and arctan2 (:data:`NUMPY_MATH`), so
that its curves are the numpy reference's to the bit.
"""

from __future__ import annotations

import ctypes

import numpy as np

from .._kernels import load_library
from ..reference.curves import CurveSet

__all__ = ["SIGNATURES", "available", "extract_curves"]

_p = ctypes.c_void_p
_i64 = ctypes.c_int64
_doubles = ctypes.POINTER(ctypes.c_double)
_FN1 = ctypes.CFUNCTYPE(None, _doubles, _doubles, _i64)
_FN2 = ctypes.CFUNCTYPE(None, _doubles, _doubles, _doubles, _i64)


class _Math(ctypes.Structure):
    """``ms_curves_math``: elementwise exp, acos and atan2."""

    _fields_ = [("exp", _FN1), ("acos", _FN1), ("atan2", _FN2)]


def _unary(ufunc: np.ufunc) -> _FN1:
    def apply(x: _doubles, out: _doubles, n: int) -> None:
        if n:
            ufunc(np.ctypeslib.as_array(x, (n,)), out=np.ctypeslib.as_array(out, (n,)))

    return _FN1(apply)


def _binary(ufunc: np.ufunc) -> _FN2:
    def apply(y: _doubles, x: _doubles, out: _doubles, n: int) -> None:
        if n:
            args = (np.ctypeslib.as_array(y, (n,)), np.ctypeslib.as_array(x, (n,)))
            ufunc(*args, out=np.ctypeslib.as_array(out, (n,)))

    return _FN2(apply)


#: numpy's functions, as the numpy reference calls them.
NUMPY_MATH = _Math(_unary(np.exp), _unary(np.arccos), _binary(np.arctan2))

#: The ABI's functions: name -> (return type, argument types).
SIGNATURES: dict[str, tuple[type | None, list[type]]] = {
    "ms_curves_extract": (ctypes.c_int, [_p, _p, _p, _i64, _p, ctypes.c_int, _i64, _p, _p, _p]),
    "ms_curves_count": (_i64, [_p]),
    "ms_curves_vertex_count": (_i64, [_p]),
    "ms_curves_corner_count": (_i64, [_p]),
    "ms_curves_spacing": (ctypes.c_double, [_p]),
    "ms_curves_copy": (None, [_p, _p, _p, _p, _p, _p]),
    "ms_curves_copy_corners": (None, [_p, _p, _p]),
    "ms_curves_free": (None, [_p]),
}
#: ms_curves_extract's status codes (the header's MS_CURVES_ENOMEM, MS_CURVES_EINVAL).
_ERRORS = {-1: MemoryError, -2: ValueError}


_LIB = load_library("_ccurves", SIGNATURES)


def available() -> bool:
    """True when the native curves were built and load."""
    return _LIB is not None


def _ptr(a: np.ndarray | None) -> int | None:
    return None if a is None else a.ctypes.data


def extract_curves(
    vertices: np.ndarray,
    mask: np.ndarray,
    faces: np.ndarray | None,
    valid: np.ndarray | None,
    bounds: tuple[np.ndarray, np.ndarray] | None,
) -> CurveSet:
    """:func:`meshlab_sharp.reference.curves.extract_curves` in the native library: the
    same arguments and the same bits.

    Raises ValueError for input the library refuses (a face index out of range) and
    MemoryError when it runs out of memory.
    """
    assert _LIB is not None, "the native curves are not built"
    pts = np.ascontiguousarray(vertices, np.float64).reshape(-1, 3)
    n = len(pts)
    feature = np.ascontiguousarray(np.asarray(mask, bool).reshape(n), np.uint8)
    ok = None
    if valid is not None:
        ok = np.ascontiguousarray(np.asarray(valid, bool).reshape(n), np.uint8)
    tri = None
    if faces is not None:
        tri = np.asarray(faces)
        tri = np.ascontiguousarray(tri, np.int32 if tri.dtype == np.int32 else np.int64)
        tri = tri.reshape(-1, 3)
    box = None
    if bounds is not None and faces is None:
        box = np.ascontiguousarray(np.concatenate([bounds[0], bounds[1]]), np.float64)
    handle = ctypes.c_void_p()
    status = _LIB.ms_curves_extract(
        _ptr(pts),
        _ptr(feature),
        _ptr(ok),
        n,
        _ptr(tri),
        4 if tri is not None and tri.dtype == np.int32 else 8,
        0 if tri is None else len(tri),
        _ptr(box),
        ctypes.byref(NUMPY_MATH),
        ctypes.byref(handle),
    )
    if status != 0:
        raise _ERRORS.get(status, RuntimeError)(f"ms_curves_extract failed (status {status})")
    try:
        return _read(handle)
    finally:
        _LIB.ms_curves_free(handle)


def _read(handle: ctypes.c_void_p) -> CurveSet:
    """The curves and corners held by an ms_curves handle."""
    count = _LIB.ms_curves_count(handle)
    total = _LIB.ms_curves_vertex_count(handle)
    sizes = np.zeros(count, np.int64)
    closed = np.zeros(count, np.uint8)
    lengths = np.zeros(count, np.float64)
    points = np.zeros((total, 3), np.float64)
    indices = np.zeros(total, np.int64)
    _LIB.ms_curves_copy(
        handle, _ptr(sizes), _ptr(closed), _ptr(lengths), _ptr(points), _ptr(indices)
    )
    corners = _LIB.ms_curves_corner_count(handle)
    corner_points = np.zeros((corners, 3), np.float64)
    corner_indices = np.zeros(corners, np.int64)
    _LIB.ms_curves_copy_corners(handle, _ptr(corner_points), _ptr(corner_indices))
    stops = np.cumsum(sizes)
    rows = zip(sizes.tolist(), stops.tolist(), closed.tolist(), lengths.tolist(), strict=True)
    curves = [
        (points[stop - size : stop], indices[stop - size : stop], bool(c), length)
        for size, stop, c, length in rows
    ]
    return CurveSet(curves, corner_points, corner_indices, _LIB.ms_curves_spacing(handle))
