"""Other formats: pymeshlab's reader, run in a child process.

The formats meshlab-sharp parses itself (:mod:`meshlab_sharp.io.readers`) cover what
scanners and CAD exporters write. For the rest of what MeshLab reads (COLLADA, glTF,
VRML, X3D, 3DS, CTM, PTX...) pymeshlab's reader runs in a child Python process, so a
native crash on a malformed file becomes a one-line error here instead of killing the
caller. What pymeshlab does silently in those formats (vertices with non-finite
coordinates dropped) cannot be checked from outside; the README says so.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import tempfile
from pathlib import Path

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
