"""Writing feature curves: PLY edge mesh, OBJ lines, DXF 3D polylines (atomically).

- ``.ply``: binary little-endian; a ``vertex`` element (x, y, z as double) and an
  ``edge`` element (``vertex1``, ``vertex2`` as int), which MeshLab opens as an edge
  mesh; each curve's vertices are written once (a corner shared by several curves once
  per curve).
- ``.obj``: ``v`` lines, then per curve a group ``g curve_<i>_<kind>`` and one ``l a b``
  line per segment (MeshLab reads only two vertices of an ``l`` line).
- ``.dxf``: one ``POLYLINE`` (3D polyline, closed for loops) per curve on layer
  ``SHARP_<KIND>``, through ezdxf (the ``dxf`` extra: ``pip install 'meshlab-sharp[dxf]'``).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..extras import require
from ..outputs import OutputSet, atomic_write

__all__ = ["CURVE_FORMATS", "check_curves_path", "curve_arrays", "require_ezdxf", "save_curves"]

#: Extensions :func:`save_curves` writes.
CURVE_FORMATS = (".ply", ".obj", ".dxf")


def require_ezdxf() -> Any:
    """Import ezdxf, or raise a one-line error saying how to install it."""
    return require("ezdxf", "writing DXF", "dxf")


def check_curves_path(path: str | os.PathLike[str]) -> Path:
    """The destination, checked: a known extension (and ezdxf for ``.dxf``).

    Raises
    ------
    MeshlabSharpError
        Unknown extension, or ``.dxf`` without ezdxf.
    """
    dest = Path(path)
    ext = dest.suffix.lower()
    if ext not in CURVE_FORMATS:
        raise InputError(
            f"{dest}: the curves file must end in {', '.join(CURVE_FORMATS)} (got {ext or 'none'})"
        )
    if ext == ".dxf":
        require_ezdxf()
    return dest


def curve_arrays(curves: Sequence[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All curves as one edge mesh.

    Parameters
    ----------
    curves : sequence of Curve

    Returns
    -------
    vertices : (v, 3) float64
        Every curve's vertices, curve after curve.
    edges : (e, 2) int32
        Segments, indices into ``vertices`` (loops closed).
    curve : (e,) int64
        The curve of each segment.
    """
    if not curves:
        return np.zeros((0, 3)), np.zeros((0, 2), np.int32), np.zeros(0, np.int64)
    starts = np.cumsum([0] + [len(c.points) for c in curves[:-1]])
    edges = [c.segments + s for c, s in zip(curves, starts, strict=True)]
    which = [np.full(len(e), i, np.int64) for i, e in enumerate(edges)]
    return (
        np.concatenate([c.points for c in curves]).astype(np.float64),
        np.concatenate(edges).astype(np.int32),
        np.concatenate(which),
    )


def save_curves(
    path: str | os.PathLike[str], curves: Sequence[Any], *, into: OutputSet | None = None
) -> Path:
    """Write curves as PLY, OBJ or DXF, by the extension (see the module docstring).

    Parameters
    ----------
    path : path-like
        Destination ``.ply``, ``.obj`` or ``.dxf``.
    curves : sequence of Curve
        ``DetectionResult.curves``.
    into : OutputSet, optional
        Only stage the file in this set (see :func:`meshlab_sharp.io.atomic_write`).

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Unknown extension.
    MeshlabSharpError
        ``.dxf`` without ezdxf.
    OutputError
        The file cannot be written.
    """
    dest = check_curves_path(path)
    ext = dest.suffix.lower()
    writer = {".ply": _write_ply, ".obj": _write_obj, ".dxf": _write_dxf}[ext]
    return atomic_write(dest, lambda tmp: writer(tmp, curves), into=into)


def _write_ply(tmp: str, curves: Sequence[Any]) -> None:
    vertices, edges, _ = curve_arrays(curves)
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment meshlab-sharp feature curves\n"
        f"element vertex {len(vertices)}\nproperty double x\nproperty double y\n"
        f"property double z\nelement edge {len(edges)}\nproperty int vertex1\n"
        "property int vertex2\nend_header\n"
    )
    with open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(np.ascontiguousarray(vertices, "<f8").tobytes())
        fh.write(np.ascontiguousarray(edges, "<i4").tobytes())


def _write_obj(tmp: str, curves: Sequence[Any]) -> None:
    vertices, edges, which = curve_arrays(curves)
    with open(tmp, "w", encoding="ascii") as fh:
        fh.write("# meshlab-sharp feature curves\n")
        fh.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in vertices.tolist())
        for i, c in enumerate(curves):
            fh.write(f"g curve_{i}_{c.kind}\n")
            fh.writelines(f"l {a + 1} {b + 1}\n" for a, b in edges[which == i].tolist())


def _write_dxf(tmp: str, curves: Sequence[Any]) -> None:
    ezdxf = require_ezdxf()
    doc = ezdxf.new("R2010")
    msp = doc.modelspace()
    for c in curves:
        layer = f"SHARP_{c.kind.upper()}"
        if layer not in doc.layers:
            doc.layers.add(layer)
        msp.add_polyline3d(c.points.tolist(), close=c.closed, dxfattribs={"layer": layer})
    doc.saveas(tmp)
