"""E57 point clouds through pye57 (``pip install 'meshlab-sharp[e57]'``), one scan at a
time (pye57 reads a scan whole): the Cartesian coordinates of every scan, with each
scan's pose applied, scans in file order."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..extras import require
from .scanner import guarded, library_message, require_utf8_name
from .source import PointSource


def e57_points(path: str | os.PathLike[str]) -> PointSource:
    """An E57 file's points as a :class:`~meshlab_sharp.io.source.PointSource`."""
    pye57 = require("pye57", "reading E57", "e57")
    p = Path(path)
    require_utf8_name(str(p), "E57")
    try:
        e57 = pye57.E57(str(p))
        counts = [int(e57.get_header(i).point_count) for i in range(e57.scan_count)]
    except Exception as exc:  # pye57 raises its own and OS errors
        raise InputError(f"{p}: cannot read the E57 file: {library_message(exc)}") from None

    def blocks(size: int) -> Iterator[np.ndarray]:
        reader = pye57.E57(str(p))
        for i in range(reader.scan_count):
            scan = reader.read_scan(i, ignore_missing_fields=True)
            xyz = np.column_stack([np.asarray(scan[f"cartesian{a}"], np.float64) for a in "XYZ"])
            for s in range(0, len(xyz), size):
                yield xyz[s : s + size]

    return PointSource(sum(counts), guarded(blocks, str(p), "E57"), str(p))


def read_e57(path: str | os.PathLike[str]) -> np.ndarray:
    """All points of an E57 file, (n, 3) float64."""
    parts = list(e57_points(path).blocks(1 << 20))
    return np.concatenate(parts) if parts else np.zeros((0, 3))


def write_e57(path: str | os.PathLike[str], points: np.ndarray) -> None:
    """Write (n, 3) points as one E57 scan (tests, examples)."""
    pye57 = require("pye57", "reading E57", "e57")
    pts = np.asarray(points, np.float64)
    writer = pye57.E57(str(path), mode="w")
    writer.write_scan_raw(
        {"cartesianX": pts[:, 0], "cartesianY": pts[:, 1], "cartesianZ": pts[:, 2]}
    )
    writer.close()
