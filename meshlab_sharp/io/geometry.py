"""The geometry every stage works on: vertices, optional triangles, and where they came from."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pymeshlab

from ..errors import InputError


@dataclass(frozen=True)
class Geometry:
    """Vertices and, for a mesh, triangles, as read from a file or given by the caller.

    Attributes
    ----------
    vertices : (n, 3) float64
        Vertex positions in the input's order.
    faces : (m, 3) int64 or None
        Triangle vertex indices, or None for a point cloud.
    source : str
        Where the geometry came from (a path, ``"array"``, ``"MeshSet"``...).
    """

    vertices: np.ndarray
    faces: np.ndarray | None
    source: str

    @property
    def is_mesh(self) -> bool:
        """True when the geometry has at least one face."""
        return self.faces is not None and len(self.faces) > 0


def as_geometry(vertices: Any, faces: Any = None, source: str = "array") -> Geometry:
    """Validate arrays given by a caller and wrap them in a :class:`Geometry`.

    Parameters
    ----------
    vertices : array_like, (n, 3)
        Vertex positions; any real dtype.
    faces : array_like, (m, 3), optional
        Triangle indices into ``vertices``. None or an empty array means a point cloud.
    source : str
        A name for messages.

    Raises
    ------
    InputError
        Wrong shapes, no vertices, non-finite coordinates, or out-of-range face indices.
    """
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{source}: vertices are not numeric: {exc}") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"{source}: vertices must have shape (n, 3), got {v.shape}")
    if len(v) == 0:
        raise InputError(f"{source}: no points")
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{source}: {int(bad.sum())} vertices have non-finite coordinates (NaN or inf), "
            f"the first at index {first}"
        )
    f = None
    if faces is not None:
        f_arr = np.asarray(faces)
        if f_arr.size:
            if f_arr.ndim != 2 or f_arr.shape[1] != 3:
                raise InputError(f"{source}: faces must have shape (m, 3), got {f_arr.shape}")
            if not np.issubdtype(f_arr.dtype, np.integer):
                raise InputError(f"{source}: face indices must be integers, got {f_arr.dtype}")
            f = f_arr.astype(np.int64)
            if f.min() < 0 or f.max() >= len(v):
                raise InputError(
                    f"{source}: face indices must lie in [0, {len(v) - 1}], "
                    f"found {int(f.min())}..{int(f.max())}"
                )
    return Geometry(vertices=v, faces=f, source=source)


def mesh_arrays(ms: pymeshlab.MeshSet) -> tuple[np.ndarray, np.ndarray | None]:
    """Vertices (n, 3) and faces (m, 3) or None of the current mesh of ``ms``.

    No ``pymeshlab.Mesh`` reference outlives this call: one kept in a frame that a
    traceback holds can be freed after its MeshSet by the garbage collector, which
    crashes the interpreter.
    """
    mesh = ms.current_mesh()
    vertices = mesh.vertex_matrix()
    faces = mesh.face_matrix().astype(np.int64) if mesh.face_number() > 0 else None
    return vertices, faces
