"""LAS and LAZ point clouds through laspy (``pip install 'meshlab-sharp[las]'``, which
brings ``lazrs`` for LAZ), read in blocks: the coordinates are the scaled ones
(``X * scale + offset``), in the file's point order. The header's point count must match
the records: fewer records is an error when read (:class:`~meshlab_sharp.io.stream.
PointSource`), more (uncompressed LAS) is an error before."""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..extras import require
from .scanner import guarded, library_message
from .stream import PointSource

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
    """A LAS/LAZ file's points as a :class:`~meshlab_sharp.io.stream.PointSource`."""
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
