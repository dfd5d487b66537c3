"""Plain-text point lists (``.xyz``, ``.pts``, ``.asc``, ``.txt``): one point per line.

A point line holds ``x y z`` and optionally more columns (normals, intensity, colour),
separated by spaces, tabs, commas or semicolons; only the first three are read, the
others must still be numbers. Lines starting with ``#`` or ``//`` are comments. A line
holding a single integer is a point count (Leica ``.pts``): it must equal the number of
point lines that follow it, up to the next count line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .text import Tokens, line_table, numbers, read_text, tokenize


def read_point_list(path: Path, name: str) -> tuple[np.ndarray, None]:
    """Read a point list.

    Returns
    -------
    vertices : (n, 3) float64
    faces : None

    Raises
    ------
    InputError
        Binary content, a line with one or two numbers that is not a count, a token that
        is not a decimal number, a count that does not match its points, no points.
    """
    tokens = tokenize(read_text(path, name, "point list"), separators=b",;", comments=(b"#", b"//"))
    first, count = line_table(tokens)
    short = count == 2
    if short.any():
        line = tokens.line[first[np.argmax(short)]]
        raise InputError(f"{name}: line {line}: two values; a point needs x y z")
    point = count >= 3
    if not point.any():
        raise InputError(f"{name}: the file holds no points (no line has x y z)")
    _check_counts(tokens, first, count, name)
    values = numbers(tokens, np.flatnonzero(np.repeat(point, count)), np.float64, name)
    x_at = np.cumsum(count[point]) - count[point]  # each point's x among the values
    return values[x_at[:, None] + np.arange(3)], None


def _check_counts(tokens: Tokens, first: np.ndarray, count: np.ndarray, name: str) -> None:
    """Each single-integer line must give the number of point lines after it."""
    heads = np.flatnonzero(count == 1)
    if len(heads) == 0:
        return
    if heads[0] != 0:
        line = tokens.line[first[heads[0]]]
        raise InputError(f"{name}: line {line}: a lone number among the points")
    declared = numbers(tokens, first[heads], np.int64, name)
    found = np.diff(heads, append=len(first)) - 1
    wrong = declared != found
    if wrong.any():
        k = int(np.argmax(wrong))
        raise InputError(
            f"{name}: line {tokens.line[first[heads[k]]]}: the point count says "
            f"{declared[k]} but {found[k]} point lines follow"
        )
