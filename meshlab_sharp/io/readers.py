"""Reading geometry files: every accepted format is parsed and checked here, with numpy.

pymeshlab never parses an input file: its readers crash the interpreter on some bad
files (out-of-range or zero OBJ face indices, odd OFF face lines) and load others
silently wrong (NaN vertices dropped, 1- and 2-index PLY faces, extra data, point lists
read as zeros). Each format module reads the whole file with numpy and turns every such
problem into an :class:`InputError` naming the line or item. Headers and sizes are
checked with bounded reads before the data is read.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import InputError
from .child import CHILD_EXTENSIONS, read_with_pymeshlab
from .geometry import Geometry
from .obj import read_obj
from .off import read_off
from .ply import read_ply
from .pointlist import read_point_list
from .source import PointSource
from .stl import read_stl

#: Extensions read as plain-text point lists (one point per line).
POINT_LIST_EXTENSIONS = frozenset({".xyz", ".pts", ".asc", ".txt"})

#: Scanners' formats, read in blocks by laspy and pye57.
SCANNER_EXTENSIONS = (".las", ".laz", ".e57")

_Reader = Callable[[Path, str], tuple[np.ndarray, np.ndarray | None]]
_READERS: dict[str, _Reader] = {
    ".ply": read_ply,
    ".obj": read_obj,
    ".off": read_off,
    ".stl": read_stl,
    **dict.fromkeys(POINT_LIST_EXTENSIONS, read_point_list),
    **dict.fromkeys(CHILD_EXTENSIONS, read_with_pymeshlab),
    **dict.fromkeys(SCANNER_EXTENSIONS, lambda p, name: _read_scanner(p)),
}


def scanner_points(path: Path) -> PointSource:
    """A LAS/LAZ (laspy) or E57 (pye57) scan as a :class:`PointSource` (read in blocks);
    the optional extras ``las`` and ``e57``."""
    if path.suffix.lower() == ".e57":
        from .e57 import e57_points

        return e57_points(path)
    from .las import las_points

    return las_points(path)


def _read_scanner(path: Path) -> tuple[np.ndarray, None]:
    """A scanner's file (:func:`scanner_points`), read whole."""
    source = scanner_points(path)
    parts = list(source.blocks(1 << 20))
    if source.n == 0 or not parts:
        raise InputError(f"{source.name}: the file holds no points")
    points = np.concatenate(parts)
    if len(points) != source.n:
        raise InputError(f"{source.name}: {len(points)} points read, the header says {source.n}")
    return points, None


def load(path: str | os.PathLike[str], *, as_points: bool = False) -> Geometry:
    """Read a mesh or point cloud.

    Formats: PLY (ASCII, binary little and big endian), OBJ, OFF (ASCII), STL (ASCII and
    binary), and point lists ``.xyz``, ``.pts``, ``.asc``, ``.txt``, parsed and
    checked here; the other formats MeshLab reads (:data:`~meshlab_sharp.io.child.
    CHILD_EXTENSIONS`: COLLADA, glTF, VRML, X3D...) through pymeshlab in a child process.
    A file without faces is a point cloud. Polygons are split into triangle fans.

    Parameters
    ----------
    path : path-like
        The file to read. It is never modified.
    as_points : bool, default False
        Ignore the faces and treat the vertices as a point cloud.

    Returns
    -------
    Geometry
        Vertices in the file's order (STL: distinct corners in order of first
        appearance), faces or None.

    Raises
    ------
    InputError
        Missing, empty, unsupported, truncated or malformed file; counts that do not
        match the data; non-finite coordinates; invalid face indices; faces with fewer
        than 3 vertices; no points.
    MemoryError
        The file does not fit in memory.
    """
    p = Path(path)
    name = str(p) if str(p).isprintable() else ascii(str(p))  # messages stay one line
    if not p.exists():
        raise InputError(f"{name}: no such file")
    if not p.is_file():
        raise InputError(f"{name}: not a regular file")
    ext = p.suffix.lower()
    reader = _READERS.get(ext)
    if reader is None:
        known = ", ".join(sorted(_READERS))
        raise InputError(f"{name}: unsupported format {ext or '(no extension)'!r}; use {known}")
    if p.stat().st_size == 0:
        raise InputError(f"{name}: the file is empty")
    vertices, faces = reader(p, name)
    return Geometry(vertices, None if as_points else faces, name)
