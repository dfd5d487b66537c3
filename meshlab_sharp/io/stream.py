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
from ..outputs import OutputSet, atomic_write
from .ply import binary_vertex_layout
from .source import PointSource
from .writers import feature_colors

#: Points per block when reading or writing.
BLOCK = 1 << 20


def ply_points(path: str | os.PathLike[str], *, as_points: bool = False) -> PointSource | None:
    """A binary PLY's vertices through a memory map; None when it is not one
    (:func:`meshlab_sharp.io.ply.binary_vertex_layout`, which checks the file as the
    in-memory reader does).

    Raises
    ------
    InputError
        A malformed file, or a mesh (faces) without ``as_points``.
    """
    layout = binary_vertex_layout(Path(path), str(path))
    if layout is None:
        return None
    offset, dtype, n, faces = layout
    if faces and not as_points:
        raise mesh_error(str(path))

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
    if ext == ".ply" and p.stat().st_size > 0:
        source = ply_points(p, as_points=as_points)
        if source is not None:
            return source
    geometry = load(p, as_points=as_points)
    if geometry.is_mesh:
        raise mesh_error(str(p))
    return PointSource.from_array(geometry.vertices, str(p))


def mesh_error(name: str) -> InputError:
    """The error for a mesh given to out-of-core detection (``name``: the input)."""
    return InputError(
        f"{name}: a mesh; out-of-core detection (--max-memory, --dask) handles point "
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
