"""Reading geometry through pymeshlab, guarded against what it does silently.

pymeshlab reads the files; this module guards against what it does silently (see
``PYMESHLAB_NOTES.md``): vertices with NaN/inf coordinates are dropped on load (the
indices shift), a text point list full of garbage loads as junk points, an OFF with an
out-of-range face index loads anyway. Each of those becomes a clear :class:`InputError`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pymeshlab

from ..errors import InputError
from .geometry import Geometry, as_geometry, mesh_arrays
from .quiet import quiet_stdout

#: Extensions read as plain-text point lists (one point per line).
POINT_LIST_EXTENSIONS = frozenset({".xyz", ".pts", ".asc", ".txt"})
#: Text formats scanned for NaN/inf tokens before loading.
_TEXT_EXTENSIONS = POINT_LIST_EXTENSIONS | {".obj", ".off"}
_NONFINITE = re.compile(rb"(?i)(?<![a-z])(nan|inf)")
_PLY_ELEMENT = re.compile(rb"^element\s+(\w+)\s+(\d+)\s*$")
_NUMBER = rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_SEP = rb"(?:[ \t]*[,;][ \t]*|[ \t]+)"
#: A line of a point list: three numbers first (more columns may follow).
_POINT_LINE = re.compile(
    rb"^[ \t]*" + _NUMBER + _SEP + _NUMBER + _SEP + _NUMBER + rb"(?![\d.eE])", re.M
)


def load(path: str | os.PathLike[str], *, as_points: bool = False) -> Geometry:
    """Read a mesh or point cloud with pymeshlab.

    Any format pymeshlab reads works (PLY, OBJ, OFF, STL, XYZ/PTS/ASC point lists...).
    A file without faces is a point cloud.

    Parameters
    ----------
    path : path-like
        The file to read. It is never modified.
    as_points : bool, default False
        Ignore the faces and treat the vertices as a point cloud.

    Returns
    -------
    Geometry
        Vertices in the file's order, faces or None.

    Raises
    ------
    InputError
        Missing, empty, truncated or unreadable file; non-finite coordinates; invalid
        face indices; no points.
    """
    p = Path(path)
    name = str(p)
    if not p.exists():
        raise InputError(f"{name}: no such file")
    if not p.is_file():
        raise InputError(f"{name}: not a regular file")
    if p.stat().st_size == 0:
        raise InputError(f"{name}: the file is empty")
    ext = p.suffix.lower()
    if ext in (".las", ".laz", ".e57"):  # not pymeshlab's: laspy, pye57 (optional extras)
        from .stream import open_points

        source = open_points(p)
        return as_geometry(np.concatenate(list(source.blocks(1 << 20))), None, source=name)
    expected_vertices = _check_before_load(p, ext)

    ms = pymeshlab.MeshSet()
    options = _load_options(p, ext)
    with quiet_stdout():
        try:
            ms.load_new_mesh(str(p), **options)
        except Exception as exc:  # pymeshlab's exceptions share no base class but Exception
            reason = str(exc).strip().splitlines()
            detail = reason[-1].strip() if reason else type(exc).__name__
            raise InputError(
                f"{name}: cannot read the file (truncated, corrupt or unsupported format): {detail}"
            ) from None
    vertices, faces = mesh_arrays(ms)
    del ms  # free pymeshlab's copy before anything can raise
    if ext == ".obj":
        expected_faces = _obj_triangle_count(p.read_bytes())
        n_faces = 0 if faces is None else len(faces)
        if n_faces < expected_faces:
            raise InputError(
                f"{name}: {expected_faces - n_faces} of {expected_faces} triangles could not be "
                "read: their face indices point to missing vertices"
            )
    if as_points:
        faces = None
    if len(vertices) == 0:
        raise InputError(f"{name}: the file holds no points")
    if expected_vertices is not None and len(vertices) != expected_vertices:
        why = "non-finite coordinates (NaN or inf)" if ext == ".ply" else "unreadable lines"
        raise InputError(
            f"{name}: the file holds {expected_vertices} vertices but pymeshlab read "
            f"{len(vertices)}; the others have {why}"
        )
    return as_geometry(vertices, faces, source=name)


def _check_before_load(p: Path, ext: str) -> int | None:
    """Reject what pymeshlab would load silently wrong; return the expected vertex count.

    PLY: the header's vertex count (checked against what pymeshlab reads, since it drops
    non-finite vertices). Text formats: NaN/inf tokens. Point lists: binary content, and
    the number of lines that start with three numbers.
    """
    if ext == ".ply":
        return _ply_vertex_count(p)
    if ext not in _TEXT_EXTENSIONS:
        return None
    data = p.read_bytes()
    if ext in POINT_LIST_EXTENSIONS and not _looks_like_text(data):
        raise InputError(f"{p}: not a text point list (binary or garbage content)")
    match = _NONFINITE.search(data)
    if match is not None:
        line = data.count(b"\n", 0, match.start()) + 1
        raise InputError(f"{p}: non-finite coordinate (NaN or inf) on line {line}")
    if ext == ".off":
        _check_off_faces(p, data)
    if ext in POINT_LIST_EXTENSIONS:
        count = len(_POINT_LINE.findall(data))
        if count == 0:
            raise InputError(f"{p}: not a text point list (no line starts with x y z numbers)")
        return count
    return None


def _check_off_faces(p: Path, data: bytes) -> None:
    """Reject an ASCII OFF whose faces index missing vertices.

    pymeshlab loads such a file anyway, with dangling indices that later crash the
    interpreter, so the face block is checked before pymeshlab sees the file.
    """
    lines = (ln.split(b"#", 1)[0].split() for ln in data.splitlines())
    tokens = [t for t in lines if t]
    if not tokens or not tokens[0][0].endswith(b"OFF"):
        raise InputError(f"{p}: not an OFF file (no OFF keyword)")
    if tokens[0][0] != tokens[0][-1] or len(tokens) < 2:
        return  # binary or unusual variant: left to pymeshlab
    head = tokens[0][1:] if len(tokens[0]) > 1 else tokens[1]
    body = tokens[1:] if len(tokens[0]) > 1 else tokens[2:]
    try:
        nv, nf = int(head[0]), int(head[1])
        faces = body[nv : nv + nf]
        bad = [f for f in faces if any(not 0 <= int(i) < nv for i in f[1 : 1 + int(f[0])])]
    except (ValueError, IndexError):
        raise InputError(f"{p}: malformed OFF file") from None
    if len(faces) < nf:
        raise InputError(f"{p}: truncated OFF file ({len(faces)} of {nf} faces)")
    if bad:
        raise InputError(f"{p}: {len(bad)} faces have face indices outside 0..{nv - 1}")


def _obj_triangle_count(data: bytes) -> int:
    """Triangles an OBJ's ``f`` lines make once fanned (a face of m corners makes m - 2)."""
    return sum(max(len(ln.split()) - 3, 0) for ln in data.splitlines() if ln.startswith(b"f "))


def _load_options(p: Path, ext: str) -> dict[str, str | bool]:
    """Extra pymeshlab load parameters: an ``.asc`` list stays a point cloud (pymeshlab
    would triangulate it as a range grid), a ``.txt`` list gets its column separator."""
    if ext == ".asc":
        return {"triangulate": False}
    if ext != ".txt":
        return {}
    with p.open("rb") as fh:
        head = fh.read(4096)
    first = _POINT_LINE.search(head)
    line = first.group(0) if first else b""
    if b";" in line:
        return {"separator": ";"}
    if b"," in line:
        return {"separator": ","}
    return {"separator": "SPACE"}


def _looks_like_text(data: bytes) -> bool:
    """True when ``data`` is printable ASCII text with digits in it."""
    if b"\x00" in data:
        return False
    try:
        text = data[:65536].decode("ascii")
    except UnicodeDecodeError:
        return False
    printable = sum(c.isprintable() or c in "\r\n\t" for c in text)
    return printable == len(text) and re.search(r"\d", text) is not None


def _ply_vertex_count(p: Path) -> int | None:
    """The vertex count declared in a PLY header (None when it declares none)."""
    count = None
    with p.open("rb") as fh:
        if fh.readline().strip() != b"ply":
            raise InputError(f"{p}: not a PLY file (no 'ply' magic line)")
        for line in fh:
            line = line.strip()
            if line == b"end_header":
                return count
            m = _PLY_ELEMENT.match(line)
            if m and m.group(1) == b"vertex":
                count = int(m.group(2))
    raise InputError(f"{p}: truncated PLY header (no end_header)")
