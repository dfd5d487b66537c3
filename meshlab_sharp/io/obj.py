"""Wavefront OBJ: the ``v`` and ``f`` lines, read with numpy.

Vertices take the first three numbers of a ``v`` line (a fourth weight or colour columns
are ignored). Face corners are ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn``; a negative
index counts back from the last vertex defined before the face (OBJ's relative
indices). Polygons become triangle fans. Other statements (``vn``, ``vt``, ``g``,
``usemtl``, ``l``...) are ignored.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from .polygons import check_corner_limit, fan_triangles
from .text import Tokens, line_table, numbers, read_text, tokenize

_CONTINUATION = re.compile(rb"\\\r?\n")


def read_obj(path: Path, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Read an OBJ file.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64 or None

    Raises
    ------
    InputError
        Binary content, a ``v`` line without x y z, a token that is not a number, a face
        with fewer than 3 corners, a face index 0 or pointing to a missing vertex, no
        vertices.
    """
    data = read_text(path, name, "OBJ file")
    if b"\\" in data:
        data = _CONTINUATION.sub(b" ", data)
    tokens = tokenize(data)
    first, count = line_table(tokens)
    heads = tokens.take(first)
    is_v, is_f = heads.equals(b"v"), heads.equals(b"f")
    v_first, v_count = first[is_v], count[is_v]
    if len(v_first) == 0:
        raise InputError(f"{name}: the file holds no points (no 'v' lines)")
    short = v_count < 4
    if short.any():
        line = tokens.line[v_first[np.argmax(short)]]
        raise InputError(f"{name}: line {line}: a vertex needs x y z")
    vertices = numbers(tokens, v_first[:, None] + np.arange(1, 4), np.float64, name)
    v_lines = tokens.line[v_first]
    faces = _faces(tokens, first[is_f], count[is_f] - 1, v_lines, name)
    return vertices, faces


def _faces(
    tokens: Tokens, f_first: np.ndarray, sizes: np.ndarray, v_lines: np.ndarray, name: str
) -> np.ndarray | None:
    """Triangles from the ``f`` lines starting at tokens ``f_first`` with ``sizes``
    corners each; ``v_lines`` are the (ascending) lines of the ``v`` statements."""
    if len(f_first) == 0:
        return None
    few = sizes < 3
    if few.any():
        k = int(np.argmax(few))
        raise InputError(
            f"{name}: line {tokens.line[f_first[k]]}: a face needs at least 3 vertices, "
            f"this one has {sizes[k]}"
        )
    check_corner_limit(sizes, lambda k: f"{name}: line {tokens.line[f_first[k]]}")
    offsets = np.cumsum(sizes) - sizes
    pos = np.repeat(f_first + 1, sizes) + np.arange(int(sizes.sum())) - np.repeat(offsets, sizes)
    corners = _vertex_part(tokens.take(pos))
    index = numbers(corners, np.arange(len(pos)), np.int64, name)
    before = np.searchsorted(v_lines, corners.line)  # vertices defined above each corner
    resolved = np.where(index > 0, index - 1, before + index)
    bad = (index == 0) | (resolved < 0) | (resolved >= len(v_lines))
    if bad.any():
        k = int(np.argmax(bad))
        where = f"{name}: line {corners.line[k]}: face index {index[k]}"
        if index[k] == 0:
            raise InputError(f"{where} is invalid (OBJ counts vertices from 1)")
        if index[k] < 0:
            raise InputError(
                f"{where} counts back past the first vertex ({before[k]} are defined above)"
            )
        raise InputError(
            f"{where} points to a missing vertex (the file has {len(v_lines)} vertices)"
        )
    return fan_triangles(resolved, sizes)


def _vertex_part(corners: Tokens) -> Tokens:
    """Each ``v/vt/vn`` corner token cut at its first ``/``."""
    slashes = np.flatnonzero(corners.buf == ord("/"))
    if len(slashes) == 0:
        return corners
    k = np.minimum(np.searchsorted(slashes, corners.start), len(slashes) - 1)
    cut = np.where(
        (slashes[k] >= corners.start) & (slashes[k] < corners.end), slashes[k], corners.end
    )
    return Tokens(corners.buf, corners.start, cut, corners.line)
