"""Plain-text point lists (``.xyz``, ``.pts``, ``.asc``, ``.txt``): one point per line.

A point line holds ``x y z`` and optionally more columns (normals, intensity, colour),
separated by spaces, tabs, commas or semicolons; only the first three are read, the
others must still be numbers. Lines starting with ``#`` or ``//`` are comments. A line
holding a single integer is a point count (Leica ``.pts``): it must equal the number of
point lines that follow it, up to the next count line. Numbers written with decimal
commas (``6,370;2,698;0,410``) or thousands separators (``1,000.0``) are read as more
columns than meant: the first 64 KiB are searched for them, with an
:class:`~meshlab_sharp.errors.InputWarning` when found.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError, InputWarning
from .text import HEAD_BYTES, Tokens, line_table, numbers, read_text, tokenize


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
    data = read_text(path, name, "point list")
    _warn_about_commas(data[:HEAD_BYTES], name)
    tokens = tokenize(data, separators=b",;", comments=(b"#", b"//"))
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


#: A line of three or more numbers written with decimal commas, separated by white space
#: or semicolons.
_DECIMAL_COMMAS = re.compile(rb"(?m)^[ \t]*[+-]?\d+,\d+(?:[ \t;]+[+-]?\d+,\d+){2,}[ \t;]*\r?$")
#: A number with thousands separators and a decimal point, alone between separators.
_THOUSANDS = re.compile(rb"(?m)(?:^|[ \t;])([+-]?\d{1,3}(?:,\d{3})+\.\d*)(?=[ \t;\r]|$)")


def _warn_about_commas(head: bytes, name: str) -> None:
    """Warn when ``head`` (the start of a point list) has a line of decimal-comma
    numbers or a number with thousands separators: commas separate columns here."""
    found = _DECIMAL_COMMAS.search(head)
    if found is not None:
        line = head.count(b"\n", 0, found.start()) + 1
        text = found.group().strip().decode("ascii")[:40]
        warnings.warn(
            f"{name}: line {line}: {text!r} looks like numbers with decimal commas, but "
            "commas separate columns (6,370 is read as 6 and 370); write decimal points",
            InputWarning,
            stacklevel=3,
        )
    found = _THOUSANDS.search(head)
    if found is not None:
        line = head.count(b"\n", 0, found.start(1)) + 1
        text = found.group(1).decode("ascii")[:40]
        warnings.warn(
            f"{name}: line {line}: {text!r} looks like a number with thousands "
            "separators, but commas separate columns (1,000.0 is read as 1 and 0.0); "
            "remove the separators",
            InputWarning,
            stacklevel=3,
        )
