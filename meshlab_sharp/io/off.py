"""Object File Format (ASCII OFF and its ``C``/``N``/``ST`` variants), read with numpy.

After the keyword line, a line gives the vertex, face (and edge) counts. Each vertex is
one line; its first three numbers are x y z (colours, normals, texture coordinates
after them are ignored). Each face is ``n i1 ... in`` and may continue on the following
lines, as the format allows; up to four colour numbers may follow its last index on
that line. Polygons become triangle fans. Anything after the last face is an error.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from .polygons import MAX_FACE_CORNERS, check_corner_limit, fan_triangles, too_many_corners
from .text import Tokens, line_table, numbers, read_text, tokenize

_KEYWORD = re.compile(rb"(?:ST|C|N)*(4?)(n?)OFF")
_MAX_COLOUR = 4


def read_off(path: Path, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Read an ASCII OFF file.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64 or None

    Raises
    ------
    InputError
        Binary content or binary OFF, no OFF keyword, counts that do not match the data,
        a token that is not a number, a face with fewer than 3 or more than
        :data:`~meshlab_sharp.io.polygons.MAX_FACE_CORNERS` corners or an index
        outside the vertices.
    """
    tokens = tokenize(read_text(path, name, "OFF file"))
    first, count = line_table(tokens)
    if len(first) == 0:
        raise InputError(f"{name}: not an OFF file (no OFF keyword)")
    keyword = _KEYWORD.fullmatch(tokens.buf[tokens.start[0] : tokens.end[0]].tobytes())
    if keyword is None:
        raise InputError(f"{name}: not an OFF file (no OFF keyword)")
    if keyword.group(1) or keyword.group(2):
        raise InputError(f"{name}: only 3D OFF files are supported")
    if count[0] > 1 and tokens.take([1]).equals(b"BINARY")[0]:
        raise InputError(f"{name}: binary OFF files are not supported")
    # The counts follow the keyword on its line, or fill the next line.
    if count[0] > 1:
        head, body = np.arange(1, count[0]), 1
    elif len(first) > 1:
        head, body = first[1] + np.arange(count[1]), 2
    else:
        raise InputError(f"{name}: truncated OFF file (no vertex and face counts)")
    if len(head) not in (2, 3):
        raise InputError(
            f"{name}: line {tokens.line[head[0]]}: expected the vertex, face and edge counts"
        )
    n_vertices, n_faces = (int(c) for c in numbers(tokens, head[:2], np.int64, name))
    if n_vertices < 0 or n_faces < 0:
        raise InputError(f"{name}: line {tokens.line[head[0]]}: negative counts")
    v_first, v_count = first[body : body + n_vertices], count[body : body + n_vertices]
    if len(v_first) < n_vertices:
        raise InputError(
            f"{name}: truncated OFF file: the header says {n_vertices} vertices, "
            f"{len(v_first)} lines follow"
        )
    if n_vertices == 0:
        raise InputError(f"{name}: the file holds no points")
    short = v_count < 3
    if short.any():
        line = tokens.line[v_first[np.argmax(short)]]
        raise InputError(f"{name}: line {line}: a vertex needs x y z")
    vertices = numbers(tokens, v_first[:, None] + np.arange(3), np.float64, name)
    rest = body + n_vertices
    face_start = int(first[rest]) if rest < len(first) else len(tokens)
    faces = _faces(tokens, face_start, n_faces, n_vertices, name)
    return vertices, faces


def _faces(
    tokens: Tokens, start: int, n_faces: int, n_vertices: int, name: str
) -> np.ndarray | None:
    """The ``n_faces`` faces whose tokens begin at ``start``, fanned into triangles."""
    if n_faces == 0:
        if start < len(tokens):
            raise _extra(tokens, start, name)
        return None
    face_tokens = tokens.take(np.arange(start, len(tokens)))
    first, count = line_table(face_tokens)
    simple = len(first) == n_faces
    if simple:
        sizes = numbers(face_tokens, first, np.int64, name)
        simple = ((count >= sizes + 1) & (count <= sizes + 1 + _MAX_COLOUR)).all()
    if simple:
        check_corner_limit(sizes, lambda k: f"{name}: line {face_tokens.line[first[k]]}")
        corners_at, line_of_face = _corner_positions(first, sizes), first
    else:
        corners_at, line_of_face, sizes = _walk_faces(face_tokens, n_faces, name)
    few = sizes < 3
    if few.any():
        k = int(np.argmax(few))
        raise InputError(
            f"{name}: line {face_tokens.line[line_of_face[k]]}: a face needs at least 3 "
            f"vertices, this one declares {sizes[k]}"
        )
    corners = numbers(face_tokens, corners_at, np.int64, name)
    bad = (corners < 0) | (corners >= n_vertices)
    if bad.any():
        k = int(np.argmax(bad))
        raise InputError(
            f"{name}: line {face_tokens.line[corners_at[k]]}: face index {corners[k]} is "
            f"outside the {n_vertices} vertices (0..{n_vertices - 1})"
        )
    return fan_triangles(corners, sizes)


def _corner_positions(first: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Token positions of the corners of faces written ``n i1 ... in`` from ``first``."""
    offsets = np.cumsum(sizes) - sizes
    return np.repeat(first + 1, sizes) + np.arange(int(sizes.sum())) - np.repeat(offsets, sizes)


def _walk_faces(
    tokens: Tokens, n_faces: int, name: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Faces read one by one, for a file whose faces continue across lines.

    Returns the corners' token positions, each face's first token and its size.
    """
    line = tokens.line
    line_end = np.searchsorted(line, line, side="right")  # first token of the next line
    corners: list[np.ndarray] = []
    heads, sizes = [], []
    pos = 0
    for _ in range(n_faces):
        if pos >= len(tokens):
            raise InputError(
                f"{name}: truncated OFF file: {len(heads)} of {n_faces} faces are complete"
            )
        word = tokens.buf[tokens.start[pos] : tokens.end[pos]].tobytes()
        if not word.isdigit():
            raise InputError(f"{name}: line {line[pos]}: {word[:24]!r} is not a face size")
        if len(word) > len(str(MAX_FACE_CORNERS)) or int(word) > MAX_FACE_CORNERS:
            shown = word.decode()
            if len(word) > 24:
                shown = f"{shown[:24]}... ({len(word)} digits)"
            raise too_many_corners(f"{name}: line {line[pos]}", shown)
        size = int(word)
        if size < 3:
            raise InputError(
                f"{name}: line {line[pos]}: a face needs at least 3 vertices, this one "
                f"declares {size}"
            )
        last = pos + size
        if last >= len(tokens):
            raise InputError(
                f"{name}: truncated OFF file: the face on line {line[pos]} declares {size} vertices"
            )
        if line_end[last] - last - 1 > _MAX_COLOUR:
            raise InputError(
                f"{name}: line {line[last]}: the face declares {size} vertices but the line "
                f"holds {line_end[last] - pos - 1} numbers after the count"
            )
        corners.append(np.arange(pos + 1, last + 1))
        heads.append(pos)
        sizes.append(size)
        pos = int(line_end[last])
    if pos < len(tokens):
        raise _extra(tokens, pos, name)
    return np.concatenate(corners), np.array(heads), np.array(sizes, dtype=np.int64)


def _extra(tokens: Tokens, pos: int, name: str) -> InputError:
    return InputError(
        f"{name}: line {tokens.line[pos]}: data after the last face (the header's counts "
        "are smaller than the data)"
    )
