"""LAS and LAZ point clouds through laspy (``pip install 'meshlab-sharp[las]'``, which
brings ``lazrs`` for LAZ), read in blocks: the coordinates are the scaled ones
(``X * scale + offset``), in the file's point order. The header's point count must match
the records: fewer records is an error when read (:class:`~meshlab_sharp.io.stream.
PointSource`), more (uncompressed LAS) is an error before.

The detection's result is written back as LAS or LAZ by :func:`save_features_las`:
every point with every attribute of a LAS/LAZ input, the features classified
:data:`FEATURE_CLASS`, the strength in the extra-bytes dimension ``sharp_strength``."""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..extras import require
from ..outputs import OutputSet, atomic_write
from .scanner import guarded, library_message
from .source import PointSource

#: Bytes of a variable-length record's header: a LAS file with more VLRs than fit
#: before its points is refused before laspy reads them one by one.
VLR_HEADER_BYTES = 54
#: Bytes of the LAS 1.0-1.3 public header, which every version begins with.
_LAS_HEADER_BYTES = 227


def check_las_header(path: Path, name: str) -> None:
    """Check a LAS/LAZ public header against the file's size before laspy reads it.

    Raises
    ------
    InputError
        The offset to the points is beyond the file or inside the header, more
        variable-length records than fit before the points, a scale or offset that is
        zero or not finite, or (uncompressed LAS) fewer bytes of points than the
        header's count.
    """
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(375)
    if len(head) < _LAS_HEADER_BYTES or head[:4] != b"LASF":
        raise InputError(f"{name}: not a LAS/LAZ file (no LASF signature)")
    header_size, offset, n_vlrs = struct.unpack_from("<HII", head, 94)
    point_format, record, legacy = struct.unpack_from("<BHI", head, 104)
    scales_offsets = struct.unpack_from("<6d", head, 131)
    n = legacy
    if head[24:26] >= b"\x01\x04" and len(head) >= 255:
        n = max(n, struct.unpack_from("<Q", head, 247)[0])
    if not header_size <= offset <= size:
        raise InputError(
            f"{name}: the offset to the points ({offset}) is outside the file ({size} bytes)"
        )
    if n_vlrs * VLR_HEADER_BYTES > offset - header_size:
        raise InputError(
            f"{name}: the header announces {n_vlrs} variable-length records, more than "
            f"fit in the {offset - header_size} bytes before the points"
        )
    if not all(np.isfinite(scales_offsets)) or 0.0 in scales_offsets[:3]:
        raise InputError(f"{name}: a scale or offset of the header is zero or not finite")
    compressed = point_format & 0xC0 or path.suffix.lower() == ".laz"
    if not compressed and offset + n * record > size:
        raise InputError(
            f"{name}: the file is truncated: the header announces {n} points of {record} "
            f"bytes, {max(size - offset, 0) // max(record, 1)} are in the file"
        )


def las_points(path: str | os.PathLike[str]) -> PointSource:
    """A LAS/LAZ file's points as a :class:`~meshlab_sharp.io.source.PointSource`."""
    laspy = require("laspy", "reading LAS/LAZ", "las")
    p = Path(path)
    name = str(p) if str(p).isprintable() else ascii(str(p))
    check_las_header(p, name)
    try:
        with laspy.open(p) as reader:
            header = reader.header
            n = int(header.point_count)
            records = (int(header.offset_to_point_data), int(header.point_format.size))
            evlrs = int(header.start_of_first_evlr) if header.number_of_evlrs else 0
    except Exception as exc:  # laspy raises its own and OS errors
        raise InputError(f"{name}: cannot read the LAS/LAZ file: {library_message(exc)}") from None
    if p.suffix.lower() == ".las":  # uncompressed: the records' size is known
        start, size = records
        extra = (evlrs or p.stat().st_size) - (start + n * size)
        if extra > 0:
            raise InputError(
                f"{name}: {extra} bytes of point records after the {n} points the header "
                "counts (the header's count is smaller than the data)"
            )

    def blocks(size: int) -> Iterator[np.ndarray]:
        with laspy.open(p) as reader:
            for chunk in reader.chunk_iterator(size):
                yield np.column_stack(
                    [np.asarray(chunk.x), np.asarray(chunk.y), np.asarray(chunk.z)]
                )

    return PointSource(n, guarded(blocks, name, "LAS/LAZ"), name)


def read_las(path: str | os.PathLike[str]) -> np.ndarray:
    """All points of a LAS/LAZ file, (n, 3) float64 in the file's order."""
    source = las_points(path)
    parts = list(source.blocks(1 << 20))
    return np.concatenate(parts) if parts else np.zeros((0, 3))


def write_las(path: str | os.PathLike[str], points: np.ndarray, *, scale: float = 1e-4) -> None:
    """Write (n, 3) points to a LAS (``.las``) or LAZ (``.laz``) file, point format 0,
    coordinates rounded to ``scale`` (tests, examples)."""
    laspy = require("laspy", "reading LAS/LAZ", "las")
    pts = np.asarray(points, np.float64)
    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.array([scale] * 3)
    header.offsets = pts.min(axis=0) if len(pts) else np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.write(str(path))


#: ASPRS classification of the features in LAS/LAZ output: 64, the first value LAS 1.4
#: leaves to users (point formats 6-10, which the output always uses).
FEATURE_CLASS = 64
#: Name of the extra-bytes dimension (float32) holding the feature strength.
STRENGTH_DIMENSION = "sharp_strength"
#: LAS 1.4 point format with the fields of each legacy one (0-5), for 8-bit classes.
_WIDE_FORMAT = {0: 6, 1: 6, 2: 7, 3: 7, 4: 9, 5: 10}


#: LAS colour channels: 16 bits, written to a PLY as MeshLab's 8-bit colours.
_COLOURS = ("red", "green", "blue")


def las_attributes(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Every per-point attribute of a LAS/LAZ file but the coordinates (intensity,
    returns, classification and its flags, scan angle, user data, point source, GPS
    time, colour, scalar extra bytes), by laspy's dimension name, in the file's order:
    what a PLY output keeps. The colour becomes 8 bits (the high byte; as it is when no
    channel exceeds 255, the 8-bit values many writers store)."""
    laspy = require("laspy", "reading LAS/LAZ", "las")
    las = _read_whole(laspy, Path(path))
    out = {}
    for name in las.point_format.dimension_names:
        values = np.asarray(las[name])
        if name not in ("X", "Y", "Z") and values.ndim == 1:
            out[name] = values
    colours = [out[c] for c in _COLOURS if c in out]
    if colours:
        shift = 8 if max(int(c.max(initial=0)) for c in colours) > 255 else 0
        out.update({c: (out[c] >> shift).astype(np.uint8) for c in _COLOURS if c in out})
    return out


def check_las_output(path: str | os.PathLike[str]) -> None:
    """Before any work: laspy is there to write ``path``, and for ``.laz`` a LAZ backend
    (lazrs, which the ``las`` extra brings); else a one-line InputError."""
    laspy = require("laspy", "writing LAS/LAZ", "las")
    if Path(path).suffix.lower() == ".laz" and not laspy.LazBackend.detect_available():
        raise InputError("writing LAZ needs lazrs: pip install 'meshlab-sharp[las]'")


def save_features_las(
    path: str | os.PathLike[str],
    vertices: np.ndarray,
    strength: np.ndarray,
    mask: np.ndarray,
    *,
    source: str | os.PathLike[str] | None = None,
    into: OutputSet | None = None,
) -> Path:
    """Write the detection's result as LAS (``.las``) or LAZ (``.laz``), LAS 1.4.

    Parameters
    ----------
    path : path-like
        Destination, ``.las`` or ``.laz``.
    vertices : (n, 3) float64
        Every input point, in input order.
    strength : (n,) float64
        Written as the float32 extra-bytes dimension ``sharp_strength``.
    mask : (n,) bool
        The features: classification :data:`FEATURE_CLASS`; the other points keep the
        input's class (0, never classified, for an input that is not LAS).
    source : path-like, optional
        A LAS/LAZ input: every point is written with all its attributes (intensity,
        returns, colour, GPS time, extra bytes...), scales, offsets and VLRs; point
        formats 0-5 become their LAS 1.4 counterparts 6-10 (8-bit classes).
        Otherwise the points are written in point format 6, offset 0, at a scale of
        1e-8 times the power of ten of their largest coordinate (nine digits).
    into : OutputSet, optional
        Only stage the file (see :func:`meshlab_sharp.io.atomic_write`).
    """
    laspy = require("laspy", "writing LAS/LAZ", "las")
    if source is not None:
        las = _read_whole(laspy, Path(source))
        if len(las.points) != len(vertices):
            raise InputError(f"{source}: {len(las.points)} points, the result has {len(vertices)}")
        if las.header.point_format.id in _WIDE_FORMAT:
            las = laspy.convert(
                las, point_format_id=_WIDE_FORMAT[las.header.point_format.id], file_version="1.4"
            )
    else:
        las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
        pts = np.asarray(vertices, np.float64)
        extent = float(np.abs(pts).max()) or 1.0
        las.header.scales = np.full(3, 10.0 ** (np.floor(np.log10(extent)) - 8))
        las.header.offsets = np.zeros(3)
        las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    if STRENGTH_DIMENSION not in las.point_format.extra_dimension_names:
        las.add_extra_dim(
            laspy.ExtraBytesParams(
                name=STRENGTH_DIMENSION, type=np.float32, description="meshlab-sharp strength"
            )
        )
    las[STRENGTH_DIMENSION] = np.asarray(strength, np.float32)
    classes = np.array(las.classification)
    classes[np.asarray(mask, bool)] = FEATURE_CLASS
    las.classification = classes

    def write(tmp: str) -> None:
        las.write(tmp)

    return atomic_write(path, write, into=into)


def _read_whole(laspy: Any, path: Path) -> Any:
    """The whole LAS/LAZ file as laspy's LasData; a read failure is an InputError."""
    name = str(path) if str(path).isprintable() else ascii(str(path))
    try:
        return laspy.read(path)
    except MemoryError:
        raise
    except Exception as exc:  # laspy, lazrs and OS errors
        raise InputError(f"{name}: cannot read the LAS/LAZ file: {library_message(exc)}") from None
