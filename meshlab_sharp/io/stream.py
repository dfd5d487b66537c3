"""Point clouds read and written in blocks, for inputs larger than memory.

* :class:`~meshlab_sharp.io.source.PointSource`: a cloud read block by block, as often
  as needed.
* :func:`open_points`: binary PLY through a memory map (no copy of the file),
  LAS/LAZ through laspy (:mod:`meshlab_sharp.io.las`, extra ``las``), E57 through pye57
  (:mod:`meshlab_sharp.io.e57`, extra ``e57``); any other format is loaded whole by
  pymeshlab.
* :func:`write_features_ply`: the output PLY (the same bytes as
  :func:`meshlab_sharp.io.save_features_ply` writes for a cloud), written block by
  block and still atomically.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from .source import PointSource
from .writers import OutputSet, atomic_write, feature_colors

#: Points per block when reading or writing.
BLOCK = 1 << 20

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


def ply_vertex_layout(path: str | os.PathLike[str]) -> tuple[int, np.dtype, int, int] | None:
    """Where a binary PLY's vertices are: (header bytes, record dtype, vertices, faces).

    None for an ASCII PLY, or when the vertex element is not first or has a list
    property (then it cannot be mapped as a plain array).
    """
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None
    stop = head.find(b"\n", end) + 1
    lines = head[:stop].decode("ascii", "replace").splitlines()
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format ")), "")
    if fmt not in ("binary_little_endian", "binary_big_endian"):
        return None
    order = "<" if fmt == "binary_little_endian" else ">"
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for ln in lines:
        parts = ln.split()
        if parts[:1] == ["element"] and len(parts) == 3:
            elements.append((parts[1], int(parts[2]), []))
        elif parts[:1] == ["property"] and elements:
            if parts[1] == "list":
                elements[-1][2].append(("list", ""))
            elif len(parts) == 3 and parts[1] in _PLY_TYPES:
                elements[-1][2].append((parts[2], order + _PLY_TYPES[parts[1]]))
            else:
                return None
    if not elements or elements[0][0] != "vertex":
        return None
    _, n, props = elements[0]
    names = [p[0] for p in props]
    if "list" in names or not {"x", "y", "z"} <= set(names):
        return None
    faces = sum(count for name, count, _ in elements if name == "face")
    return stop, np.dtype(props), n, faces


def ply_points(path: str | os.PathLike[str]) -> PointSource | None:
    """A binary PLY's vertices through a memory map; None when it is not one
    (:func:`ply_vertex_layout`)."""
    layout = ply_vertex_layout(path)
    if layout is None:
        return None
    offset, dtype, n, _ = layout
    if Path(path).stat().st_size < offset + n * dtype.itemsize:
        raise InputError(f"{path}: the file is truncated ({n} vertices announced)")

    def blocks(size: int) -> Iterator[np.ndarray]:
        for s in range(0, n, size):
            m = np.memmap(path, dtype=dtype, mode="r", offset=offset, shape=(n,))
            part = m[s : s + size]
            out = np.empty((len(part), 3))
            for i, axis in enumerate("xyz"):
                out[:, i] = part[axis]
            del m, part
            yield out

    return PointSource(n, blocks, str(path))


def open_points(path: str | os.PathLike[str], *, as_points: bool = False) -> PointSource:
    """A point cloud file as a :class:`~meshlab_sharp.io.source.PointSource`, streamed
    where the format allows.

    Raises
    ------
    InputError
        A mesh (faces) without ``as_points``: meshes are not processed out of core.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    from .readers import SCANNER_EXTENSIONS, load, scanner_points

    if ext in SCANNER_EXTENSIONS:
        return scanner_points(p)
    if ext == ".ply":
        layout = ply_vertex_layout(p)
        if layout is not None and layout[3] > 0 and not as_points:
            raise _mesh_error(p)
        if layout is not None:
            source = ply_points(p)
            assert source is not None
            return source
    geometry = load(p, as_points=as_points)
    if geometry.is_mesh:
        raise _mesh_error(p)
    return PointSource.from_array(geometry.vertices, str(p))


def _mesh_error(path: Path) -> InputError:
    return InputError(
        f"{path}: a mesh; out-of-core detection (--max-memory, --dask) handles point "
        "clouds only: add --as-points, or run without --max-memory"
    )


def write_features_ply(
    path: str | os.PathLike[str],
    source: PointSource,
    strength: np.ndarray,
    mask: np.ndarray,
    *,
    into: OutputSet | None = None,
) -> Path:
    """The output PLY of a cloud (binary, as :func:`meshlab_sharp.io.save_features_ply`
    writes it: flags with the selection bit, colour, quality), block by block.

    Parameters
    ----------
    path : path-like
    source : PointSource
        The input points (read again, block by block).
    strength : (n,) float64
    mask : (n,) bool
    into : OutputSet, optional
        Only stage the file (see :func:`meshlab_sharp.io.atomic_write`).
    """
    record = np.dtype(
        [("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("flags", "<i4"), ("red", "u1"),
         ("green", "u1"), ("blue", "u1"), ("alpha", "u1"), ("quality", "<f8")]
    )  # fmt: skip
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment VCGLIB generated\n"
        f"element vertex {source.n}\nproperty double x\nproperty double y\n"
        "property double z\nproperty int flags\nproperty uchar red\nproperty uchar green\n"
        "property uchar blue\nproperty uchar alpha\nproperty double quality\n"
        "element face 0\nproperty list uchar int vertex_indices\nend_header\n"
    )
    colours = (np.array([[0.78, 0.78, 0.78, 1.0], [0.9, 0.05, 0.05, 1.0]]) * 255).astype("u1")
    assert np.array_equal(colours, (feature_colors(np.array([False, True])) * 255).astype("u1"))

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            fh.write(header.encode("ascii"))
            start = 0
            for block in source.blocks(BLOCK):
                stop = start + len(block)
                sel = np.asarray(mask[start:stop], bool)
                out = np.empty(len(block), record)
                out["x"], out["y"], out["z"] = block[:, 0], block[:, 1], block[:, 2]
                out["flags"] = np.where(sel, 0x30, 0x10)
                rgba = colours[sel.astype(np.int64)]
                for i, c in enumerate(("red", "green", "blue", "alpha")):
                    out[c] = rgba[:, i]
                out["quality"] = strength[start:stop]
                fh.write(out.tobytes())
                start = stop

    return atomic_write(path, write, into=into)
