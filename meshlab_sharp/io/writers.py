"""Writers of the results: the feature PLY (every input vertex property kept), the
indices, the JSON report, and the MeshSet MeshLab shows. Each writes through
:mod:`meshlab_sharp.outputs` (temporary siblings, then renames)."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pymeshlab

from ..outputs import OutputSet, atomic_write

#: Vertex properties the output PLY sets itself; an input property of the same name is
#: replaced (the colour ones only when the features are coloured).
OWN_PROPERTIES = ("flags", "quality")
COLOUR_PROPERTIES = ("red", "green", "blue", "alpha")
#: PLY ``flags``: MeshLab's selection bit, and the bit MeshLab leaves on a vertex that
#: no face references (every vertex of a point cloud): the same bytes as MeshLab writes.
_SELECTED, _UNREFERENCED = 0x20, 0x10
_PLY_NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int",
              "u4": "uint", "f4": "float", "f8": "double"}  # fmt: skip


def save_features_ply(
    path: str | os.PathLike[str],
    vertices: np.ndarray,
    faces: np.ndarray | None,
    strength: np.ndarray,
    mask: np.ndarray,
    *,
    normals: np.ndarray | None = None,
    attributes: Mapping[str, np.ndarray] | None = None,
    colour: bool = True,
    binary: bool = True,
    into: OutputSet | None = None,
) -> Path:
    """Write a PLY that MeshLab shows: quality = strength, selection = features.

    The vertex element holds ``x y z`` (double), then ``nx ny nz`` when ``normals`` are
    given, then every property of ``attributes`` in its order and type, then ``flags``
    (int, selection bit 0x20 on the features), ``red green blue alpha`` (uchar; features
    red, the rest grey) unless ``colour`` is False, and ``quality`` (double) = strength.
    An attribute named like one of these last ones is replaced by it.

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
        Written as vertex selection (PLY ``flags`` bit 0x20) and, with ``colour``, as
        red colour.
    normals : (n, 3) float64, optional
        Written as vertex normals when given.
    attributes : mapping of str to (n,) arrays, optional
        Other per-vertex properties to keep (the input's normals, colours, scalar
        fields), numeric scalars each; ``x``, ``y`` and ``z`` are ignored.
    colour : bool, default True
        Colour the features red and the rest grey; False keeps the colour properties of
        ``attributes`` (if any) as they are.
    binary : bool, default True
        Binary (little endian) or ASCII PLY.
    into : OutputSet, optional
        Only stage the file in this set (see :func:`atomic_write`).

    Raises
    ------
    OutputError
        The file cannot be written (the message names ``path`` and the reason).
    """
    n = len(vertices)
    columns: dict[str, np.ndarray] = {a: vertices[:, i] for i, a in enumerate("xyz")}
    if normals is not None:
        columns.update({a: normals[:, i] for i, a in enumerate(("nx", "ny", "nz"))})
    replaced = (*OWN_PROPERTIES, *(COLOUR_PROPERTIES if colour else ()))
    for name, values in (attributes or {}).items():
        if name not in ("x", "y", "z", *replaced):
            columns[name] = _ply_typed(np.asarray(values))
    mask = np.asarray(mask, bool)
    referenced = np.zeros(n, bool)
    if faces is not None:
        referenced[np.asarray(faces).ravel()] = True
    columns["flags"] = (np.where(referenced, 0, _UNREFERENCED) | _SELECTED * mask).astype(np.int32)
    if colour:
        rgba = (feature_colors(mask) * 255).astype(np.uint8)
        columns.update({c: rgba[:, i] for i, c in enumerate(COLOUR_PROPERTIES)})
    columns["quality"] = np.asarray(strength, np.float64)
    record = np.dtype([(k, v.dtype.newbyteorder("<")) for k, v in columns.items()])
    header = "".join(
        [
            f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\n",
            f"comment VCGLIB generated\nelement vertex {n}\n",
            *(f"property {_PLY_NAMES[record[k].str[1:]]} {k}\n" for k in columns),
            f"element face {0 if faces is None else len(faces)}\n",
            "property list uchar int vertex_indices\nend_header\n",
        ]
    )

    def write(tmp: str) -> None:
        table = np.empty(n, record)
        for k, v in columns.items():
            table[k] = v
        tri = np.asarray(np.zeros((0, 3)) if faces is None else faces, np.int32)
        with open(tmp, "wb") as fh:
            fh.write(header.encode("ascii"))
            if binary:
                fh.write(table.tobytes())
                packed = np.empty(len(tri), [("n", "u1"), ("v", "<i4", (3,))])
                packed["n"], packed["v"] = 3, tri
                fh.write(packed.tobytes())
                return
            formats = " ".join("%.17g" if record[k].kind == "f" else "%d" for k in columns)
            np.savetxt(fh, table, fmt=formats)
            np.savetxt(fh, tri, fmt="3 %d %d %d")

    return atomic_write(path, write, into=into)


def _ply_typed(values: np.ndarray) -> np.ndarray:
    """``values`` in a type PLY has: as they are, or booleans as uchar and the rest
    (64-bit integers, half floats...) as double."""
    if values.dtype.str[1:] in _PLY_NAMES:
        return values
    return values.astype(np.uint8 if values.dtype.kind == "b" else np.float64)


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


def select_vertices(ms: pymeshlab.MeshSet, mask: np.ndarray) -> str:
    """Make ``mask`` the vertex selection of the current mesh of ``ms``.

    pymeshlab has no selection setter: the mask goes into a custom per-vertex
    attribute (``sharp_feature``, or ``sharp_feature_2``... when taken), which stays on
    the mesh, and MeshLab's select-by-condition filter reads it. Returns that
    attribute's name.
    """
    name = add_vertex_attribute(ms.current_mesh(), "sharp_feature", mask)
    ms.compute_selection_by_condition_per_vertex(condselect=f"({name} > 0.5)")
    return name


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


#: Mask entries per block when writing indices.
INDEX_BLOCK = 1 << 22


def save_indices(
    path: str | os.PathLike[str], mask: np.ndarray, *, into: OutputSet | None = None
) -> Path:
    """Write the 0-based indices of the features, one per line (``mask``: (n,) bool;
    ``into``: see :func:`atomic_write`)."""

    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="ascii") as fh:
            for start in range(0, len(mask), INDEX_BLOCK):
                idx = start + np.flatnonzero(mask[start : start + INDEX_BLOCK])
                fh.writelines(f"{i}\n" for i in idx)

    return atomic_write(path, write, into=into)


def save_json(
    path: str | os.PathLike[str], data: dict[str, Any], *, into: OutputSet | None = None
) -> Path:
    """Write ``data`` as indented JSON (``into``: see :func:`atomic_write`)."""

    def write(tmp: str) -> None:
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=2)
            fh.write("\n")

    return atomic_write(path, write, into=into)
