"""Reading geometry through pymeshlab and writing results atomically.

pymeshlab reads the files; this module guards against what it does silently (see
``PYMESHLAB_NOTES.md``): vertices with NaN/inf coordinates are dropped on load (the
indices shift), a text point list full of garbage loads as junk points, an OFF with an
out-of-range face index loads anyway. Each of those becomes a clear :class:`InputError`.

Every file written here goes to a temporary file in the destination's folder first and
is renamed into place, so an interrupted run never leaves half a file behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pymeshlab

from .errors import InputError

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
    expected_vertices = _check_before_load(p, ext)

    ms = pymeshlab.MeshSet()
    options = _load_options(p, ext)
    with _quiet_stdout():
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


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence what pymeshlab's C++ code prints on file descriptor 1."""
    try:
        fd = os.dup(1)
    except OSError:  # no stdout at all
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 1)
            try:
                yield
            finally:
                os.dup2(fd, 1)
    finally:
        os.close(fd)


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
        with _quiet_stdout():
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
