"""Writing small test files in the formats users bring, including broken ones."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np


def write_ply(path: Path, vertices, faces=None, *, binary: bool = False) -> Path:
    """A minimal PLY (float32 x y z, optional triangles), NaN/inf written as given."""
    v = np.asarray(vertices, dtype=np.float32)
    f = np.zeros((0, 3), dtype=np.int32) if faces is None else np.asarray(faces, dtype=np.int32)
    fmt = "binary_little_endian" if binary else "ascii"
    header = (
        f"ply\nformat {fmt} 1.0\nelement vertex {len(v)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        if binary:
            fh.write(v.astype("<f4").tobytes())
            for tri in f:
                fh.write(struct.pack("<B3i", 3, *tri))
        else:
            for p in v:
                fh.write(f"{float(p[0])!r} {float(p[1])!r} {float(p[2])!r}\n".encode())
            for tri in f:
                fh.write(f"3 {tri[0]} {tri[1]} {tri[2]}\n".encode())
    return path


def write_xyz(path: Path, points) -> Path:
    """One 'x y z' line per point."""
    with open(path, "w", encoding="ascii") as fh:
        for p in np.asarray(points, dtype=float):
            fh.write(f"{float(p[0])!r} {float(p[1])!r} {float(p[2])!r}\n")
    return path
