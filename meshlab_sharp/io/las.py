"""LAS and LAZ point clouds through laspy (``pip install 'meshlab-sharp[las]'``, which
brings ``lazrs`` for LAZ), read in blocks: the coordinates are the scaled ones
(``X * scale + offset``), in the file's point order. The header's point count must match
the records: fewer records is an error when read (:class:`~meshlab_sharp.io.stream.
PointSource`), more (uncompressed LAS) is an error before."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..extras import require
from .stream import PointSource


def las_points(path: str | os.PathLike[str]) -> PointSource:
    """A LAS/LAZ file's points as a :class:`~meshlab_sharp.io.stream.PointSource`."""
    laspy = require("laspy", "reading LAS/LAZ", "las")
    p = Path(path)
    try:
        with laspy.open(p) as reader:
            header = reader.header
            n = int(header.point_count)
            records = (int(header.offset_to_point_data), int(header.point_format.size))
            evlrs = int(header.start_of_first_evlr) if header.number_of_evlrs else 0
    except Exception as exc:  # laspy raises its own and OS errors
        raise InputError(f"{p}: cannot read the LAS/LAZ file: {exc}") from None
    if p.suffix.lower() == ".las":  # uncompressed: the records' size is known
        start, size = records
        extra = (evlrs or p.stat().st_size) - (start + n * size)
        if extra > 0:
            raise InputError(
                f"{p}: {extra} bytes of point records after the {n} points the header "
                "counts (the header's count is smaller than the data)"
            )

    def blocks(size: int) -> Iterator[np.ndarray]:
        with laspy.open(p) as reader:
            for chunk in reader.chunk_iterator(size):
                yield np.column_stack(
                    [np.asarray(chunk.x), np.asarray(chunk.y), np.asarray(chunk.z)]
                )

    return PointSource(n, blocks, str(p))


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
