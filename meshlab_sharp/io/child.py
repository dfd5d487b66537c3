"""Other formats: pymeshlab's reader, run in a child process.

The formats meshlab-sharp parses itself (:mod:`meshlab_sharp.io.readers`) cover what
scanners and CAD exporters write. For the rest of what MeshLab reads (COLLADA, glTF,
VRML, X3D, 3DS, CTM, PTX...) pymeshlab's reader runs in a child Python process, so a
native crash on a malformed file becomes a one-line error here instead of killing the
caller. What pymeshlab does silently in those formats (vertices with non-finite
coordinates dropped) cannot be checked from outside; the README says so. A 3DS file's
chunks are checked first (:func:`check_3ds`): its reader loads a truncated file silently,
with the part of the mesh before the cut.
"""

from __future__ import annotations

import signal
import struct
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..errors import InputError

#: Extensions loaded through pymeshlab in a child process.
CHILD_EXTENSIONS = frozenset(
    {".3ds", ".apts", ".bre", ".ctm", ".dae", ".gltf", ".glb", ".ptx", ".tri", ".vmi"}
    | {".wrl", ".x3d", ".x3dv"}
)

_CHILD = """
import sys
import numpy as np
import pymeshlab
ms = pymeshlab.MeshSet()
try:
    ms.load_new_mesh(sys.argv[1])
except Exception as exc:
    lines = str(exc).strip().splitlines() or [type(exc).__name__]
    sys.stderr.write(lines[-1].strip() + "\\n")
    sys.exit(3)
m = ms.current_mesh()
faces = m.face_matrix() if m.face_number() > 0 else np.zeros((0, 3), np.int32)
np.savez(sys.argv[2], vertices=m.vertex_matrix(), faces=faces)
"""


def read_with_pymeshlab(path: Path, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Load ``path`` with pymeshlab in a child process.

    Parameters
    ----------
    path : Path
        A file with one of :data:`CHILD_EXTENSIONS`.
    name : str
        The file's name for messages.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64 or None

    Raises
    ------
    InputError
        pymeshlab refused the file, or its reader crashed.
    """
    if path.suffix.lower() == ".3ds":
        check_3ds(path, name)
    with tempfile.TemporaryDirectory(prefix="meshlab-sharp-") as tmp:
        out = Path(tmp) / "mesh.npz"
        # pymeshlab takes UTF-8 names: the file is read through a link with a plain one
        link = Path(tmp) / f"input{path.suffix}"
        link.symlink_to(path.resolve())
        proc = subprocess.run(
            [sys.executable, "-c", _CHILD, str(link), str(out)],
            capture_output=True,
            text=True,
            errors="replace",
            check=False,
        )
        if proc.returncode < 0:
            sig = signal.Signals(-proc.returncode).name
            raise InputError(f"{name}: pymeshlab's reader crashed on this file ({sig})")
        if proc.returncode != 0 or not out.is_file():
            lines = proc.stderr.strip().splitlines()
            detail = lines[-1].strip() if lines else f"exit status {proc.returncode}"
            raise InputError(f"{name}: cannot read the file: {detail}")
        with np.load(out) as data:
            vertices = np.asarray(data["vertices"], np.float64)
            faces = np.asarray(data["faces"], np.int64)
    return vertices, faces if len(faces) else None


#: 3DS chunks holding other chunks (main, editor, object, triangle mesh, face list),
#: with the bytes of their own data before the first inner chunk (-1: a NUL-ended name;
#: -2: a 2-byte count of 8-byte faces).
_3DS_CONTAINERS = {0x4D4D: 0, 0x3D3D: 0, 0x4000: -1, 0x4100: 0, 0x4120: -2}
#: 3DS chunks of a count and fixed-size items: vertices (3 floats), texture coordinates.
_3DS_ARRAYS = {0x4110: 12, 0x4140: 8}


def check_3ds(path: Path, name: str) -> None:
    """Refuse a 3DS file whose chunks do not fit: a chunk that runs past its parent or
    the end of the file (a truncated file), or a vertex or face list longer than its
    chunk. Only the 6-byte chunk headers and the counts are read.

    Raises
    ------
    InputError
        Naming the chunk and its offset.
    """
    size = path.stat().st_size
    with path.open("rb") as fh:
        _check_3ds_chunks(fh, 0, size, size, name)


#: Deepest nesting of 3DS chunks accepted (files have 5 levels).
_3DS_DEPTH = 16


def _check_3ds_chunks(
    fh: BinaryIO, start: int, stop: int, size: int, name: str, depth: int = 0
) -> None:
    """The chunks from byte ``start`` to ``stop`` (``size``: the file's)."""
    if depth > _3DS_DEPTH:
        raise InputError(f"{name}: malformed 3DS file: chunks nested deeper than {_3DS_DEPTH}")
    pos = start
    while pos < stop:
        fh.seek(pos)
        head = fh.read(6)
        if len(head) < 6 or pos + 6 > stop:
            raise InputError(f"{name}: truncated 3DS file: a chunk header is cut at byte {pos}")
        tag, length = struct.unpack("<HI", head)
        end = pos + length
        if length < 6 or end > stop:
            where = "the end of the file" if end > size else "the chunk that holds it"
            raise InputError(
                f"{name}: truncated 3DS file: chunk 0x{tag:04X} at byte {pos} declares "
                f"{length} bytes and runs past {where}"
            )
        data = pos + 6
        if tag in _3DS_ARRAYS or _3DS_CONTAINERS.get(tag) == -2:
            count = struct.unpack("<H", fh.read(2))[0] if length >= 8 else -1
            item = _3DS_ARRAYS.get(tag, 8)
            if count < 0 or data + 2 + count * item > end:
                raise InputError(
                    f"{name}: truncated 3DS file: chunk 0x{tag:04X} at byte {pos} holds "
                    f"fewer items than its count"
                )
            data += 2 + count * item
        if tag in _3DS_CONTAINERS:
            if _3DS_CONTAINERS[tag] == -1:
                fh.seek(data)
                label = fh.read(min(end - data, 256)).split(b"\0", 1)
                if len(label) < 2:
                    raise InputError(
                        f"{name}: malformed 3DS file: the object name at byte {data} "
                        "does not end in its chunk"
                    )
                data += len(label[0]) + 1
            _check_3ds_chunks(fh, data, end, size, name, depth + 1)
        pos = end
