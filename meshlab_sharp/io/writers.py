"""Writing results atomically: a temporary sibling, then a rename.

Every file written here goes to a temporary file in the destination's folder first and
is renamed into place, so an interrupted run never leaves half a file behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pymeshlab

from ..errors import InputError
from .quiet import quiet_stdout


def atomic_write(path: str | os.PathLike[str], write: Callable[[str], None]) -> Path:
    """Write a file through a temporary sibling and rename it into place.

    Parameters
    ----------
    path : path-like
        Destination. Its folder must exist.
    write : callable
        ``write(tmp_path)`` creates the content at ``tmp_path`` (same extension as
        ``path``, so format-sniffing writers such as pymeshlab's work).

    Returns
    -------
    Path
        The destination.
    """
    dest = Path(path)
    folder = dest.parent if str(dest.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(f"{dest}: the folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.stem}.", suffix=f".part{dest.suffix}", dir=folder)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, dest)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    return dest


def _umask() -> int:
    """The process's file-creation mask (reading it means setting it, so set it back)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def save_features_ply(
    path: str | os.PathLike[str],
    vertices: np.ndarray,
    faces: np.ndarray | None,
    strength: np.ndarray,
    mask: np.ndarray,
    *,
    normals: np.ndarray | None = None,
    binary: bool = True,
) -> Path:
    """Write a PLY that MeshLab shows: quality = strength, selection = features.

    Parameters
    ----------
    path : path-like
        Destination ``.ply``.
    vertices : (n, 3) float64
        Every input vertex, in input order.
    faces : (m, 3) int or None
        The input's faces, kept as they are.
    strength : (n,) float64
        Written as vertex quality.
    mask : (n,) bool
        Written as vertex selection (PLY ``flags`` bit 0x20) and as red colour.
    normals : (n, 3) float64, optional
        Written as vertex normals when given.
    binary : bool, default True
        Binary or ASCII PLY.
    """
    ms = feature_meshset(vertices, faces, strength, mask, normals=normals)

    def write(tmp: str) -> None:
        with quiet_stdout():
            ms.save_current_mesh(
                tmp,
                binary=binary,
                save_vertex_quality=True,
                save_vertex_flag=True,
                save_vertex_color=True,
                save_vertex_normal=normals is not None,
                save_face_color=False,
            )

    return atomic_write(path, write)


def feature_colors(mask: np.ndarray) -> np.ndarray:
    """RGBA colours in [0, 1]: features red, other points light grey. Shape (n, 4)."""
    colors = np.tile(np.array([0.78, 0.78, 0.78, 1.0]), (len(mask), 1))
    colors[mask] = (0.9, 0.05, 0.05, 1.0)
    return colors


def feature_meshset(
    vertices: np.ndarray,
    faces: np.ndarray | None,
    strength: np.ndarray,
    mask: np.ndarray,
    *,
    normals: np.ndarray | None = None,
) -> pymeshlab.MeshSet:
    """A MeshSet holding the geometry with quality, selection and colour set."""
    kwargs: dict[str, Any] = {
        "vertex_matrix": np.ascontiguousarray(vertices, dtype=np.float64),
        "v_scalar_array": np.ascontiguousarray(strength, dtype=np.float64),
        "v_color_matrix": feature_colors(mask),
    }
    if faces is not None and len(faces):
        kwargs["face_matrix"] = np.ascontiguousarray(faces, dtype=np.int32)
    if normals is not None:
        kwargs["v_normals_matrix"] = np.ascontiguousarray(normals, dtype=np.float64)
    mesh = pymeshlab.Mesh(**kwargs)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(mesh, "sharp_features")
    select_vertices(ms, mask)
    return ms


def select_vertices(ms: pymeshlab.MeshSet, mask: np.ndarray) -> None:
    """Make ``mask`` the vertex selection of the current mesh of ``ms``.

    pymeshlab has no selection setter: the mask goes into a custom per-vertex
    attribute (``sharp_feature``, or ``sharp_feature_2``... when taken), which stays on
    the mesh, and MeshLab's select-by-condition filter reads it.
    """
    name = add_vertex_attribute(ms.current_mesh(), "sharp_feature", mask)
    ms.compute_selection_by_condition_per_vertex(condselect=f"({name} > 0.5)")


def add_vertex_attribute(mesh: pymeshlab.Mesh, name: str, values: np.ndarray) -> str:
    """Add a custom per-vertex scalar under ``name`` or the first free ``name_N``.

    pymeshlab can neither overwrite nor delete a custom attribute, so a second run on
    the same mesh gets a fresh name. Returns the name used.
    """
    candidate, n = name, 1
    while True:
        try:
            mesh.vertex_custom_scalar_attribute_array(candidate)
        except Exception:  # absent: pymeshlab raises its own exception class
            break
        n += 1
        candidate = f"{name}_{n}"
    mesh.add_vertex_custom_scalar_attribute(np.asarray(values, dtype=np.float64), candidate)
    return candidate


def save_indices(path: str | os.PathLike[str], mask: np.ndarray) -> Path:
    """Write the 0-based indices of the features, one per line."""
    idx = np.flatnonzero(mask)

    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="ascii") as fh:
            fh.writelines(f"{i}\n" for i in idx)

    return atomic_write(path, write)


def save_json(path: str | os.PathLike[str], data: dict[str, Any]) -> Path:
    """Write ``data`` as indented JSON."""

    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=2)
            fh.write("\n")

    return atomic_write(path, write)
