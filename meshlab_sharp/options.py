"""What a detection is asked for, checked once for every way in (in memory, out of
core): the input turned into a :class:`~meshlab_sharp.io.Geometry`, the mode, the
weighting and the scales."""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import pymeshlab

from . import _header
from .defaults import (
    DEFAULT_KNN_SCALES,
    DEFAULT_RING_SCALES,
    MAX_KNN_SCALE,
    MAX_RING_SCALE,
    MAX_SCALES,
    MODES,
    WEIGHTINGS,
)
from .errors import InputError
from .io import Geometry, as_geometry, load, mesh_arrays

Source = str | os.PathLike[str] | np.ndarray | Geometry | pymeshlab.MeshSet | pymeshlab.Mesh

#: The smallest scales: k nearest neighbours (the point itself and one more) ...
MIN_KNN_SCALE = _header.integer("MIN_KNN_SCALE")
#: ... and rings.
MIN_RING_SCALE = _header.integer("MIN_RING_SCALE")


def check_mode_and_weighting(mode: object, weighting: object) -> None:
    """Raise InputError unless ``mode`` is one of :data:`MODES` and ``weighting`` one of
    :data:`~meshlab_sharp.defaults.WEIGHTINGS`."""
    if weighting not in WEIGHTINGS:
        raise InputError(f"unknown weighting {weighting!r}; choose from {', '.join(WEIGHTINGS)}")
    if not isinstance(mode, str) or mode not in MODES:
        raise InputError(f"unknown mode {mode!r}; choose from {', '.join(MODES)}")


def as_input(source: Source, faces: np.ndarray | None, as_points: bool) -> Geometry:
    """Turn whatever the caller gave into a validated Geometry."""
    if isinstance(source, Geometry):
        return source
    if isinstance(source, pymeshlab.MeshSet):
        if source.mesh_number() == 0:
            raise InputError("the MeshSet holds no mesh")
        return as_geometry(*mesh_arrays(source), source="MeshSet current mesh")
    if isinstance(source, pymeshlab.Mesh):
        mesh_faces = source.face_matrix() if source.face_number() > 0 else None
        return as_geometry(source.vertex_matrix(), mesh_faces, source="pymeshlab Mesh")
    if isinstance(source, str | os.PathLike):
        if faces is not None:
            raise InputError("faces are taken from the file; do not pass faces with a path")
        return load(source, as_points=as_points)
    return as_geometry(source, faces, source="array")


def load_input(
    source: Source,
    faces: np.ndarray | None,
    as_points: bool,
    mode: object,
    weighting: object,
    timings: dict[str, float],
) -> Geometry:
    """:func:`check_mode_and_weighting`, then :func:`as_input`, its seconds added to
    ``timings["load"]``: how every in-memory detection starts."""
    check_mode_and_weighting(mode, weighting)
    t0 = time.perf_counter()
    geometry = as_input(source, faces, as_points)
    timings["load"] = time.perf_counter() - t0
    return geometry


def input_scales(
    geometry: Geometry, as_points: bool, scales: Sequence[int] | int | None
) -> tuple[bool, tuple[int, ...]]:
    """Whether ``geometry`` is detected as a mesh (it has faces and not ``as_points``) and
    its scales (:func:`check_scales`: rings for a mesh, kNN sizes for a cloud)."""
    is_mesh = geometry.is_mesh and not as_points
    default = DEFAULT_RING_SCALES if is_mesh else DEFAULT_KNN_SCALES
    return is_mesh, check_scales(scales, default, "mesh" if is_mesh else "points")


def check_scales(
    scales: Sequence[int] | int | None, default: tuple[int, ...], kind: str
) -> tuple[int, ...]:
    """Sorted, distinct, positive integer scales (a single int is one scale), at most
    :data:`MAX_SCALES` of them, within :data:`MIN_KNN_SCALE`..:data:`MAX_KNN_SCALE`
    (clouds) or :data:`MIN_RING_SCALE`..:data:`MAX_RING_SCALE` (meshes); the default
    when None."""
    if scales is None:
        return default
    given: Any = [int(scales)] if isinstance(scales, int | np.integer) else scales
    if isinstance(scales, bool | str | bytes) or not hasattr(given, "__len__"):
        raise InputError(f"scales must be a sequence of integers, e.g. [12, 16], got {scales!r}")
    if len(given) > MAX_SCALES:
        raise InputError(f"{len(given)} scales given; at most {MAX_SCALES} are allowed")
    try:
        values = sorted({int(s) for s in given})
        exact = all(float(s) == int(s) for s in given)
    except (TypeError, ValueError, OverflowError):
        exact = False
    if not exact:
        raise InputError(f"scales must be integers, got {list(given)!r}")
    if not values:
        raise InputError("at least one scale is needed")
    low, high = (
        (MIN_RING_SCALE, MAX_RING_SCALE) if kind == "mesh" else (MIN_KNN_SCALE, MAX_KNN_SCALE)
    )
    what = "rings" if kind == "mesh" else "kNN sizes"
    if values[0] < low:
        raise InputError(f"{what} must be >= {low}, got {values[0]}")
    if values[-1] > high:
        raise InputError(f"{what} must be <= {high}, got {values[-1]}")
    return tuple(values)
