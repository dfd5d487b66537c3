"""STL, binary and ASCII, read with numpy.

A binary STL is an 80-byte header, a triangle count and 50 bytes per triangle; its size
must match the count exactly. An ASCII STL starts with ``solid``; each ``facet`` holds
three ``vertex x y z`` lines. STL repeats each corner in every triangle: identical corners
are merged into one vertex (in order of first appearance), as MeshLab does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .text import line_table, numbers, read_text, tokenize

_HEADER = 84
_TRIANGLE = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


def read_stl(path: Path, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Read an STL file.

    Returns
    -------
    vertices : (n, 3) float64
        The distinct corners.
    faces : (m, 3) int64

    Raises
    ------
    InputError
        A binary file whose size does not match its triangle count, a corner with a
        non-finite coordinate, a malformed ASCII facet, no triangles.
    """
    size = path.stat().st_size
    with path.open("rb") as fh:
        head = fh.read(_HEADER)
    count = int(np.frombuffer(head[80:84], "<u4")[0]) if len(head) == _HEADER else -1
    if count >= 0 and size == _HEADER + _TRIANGLE.itemsize * count:
        corners = np.fromfile(path, dtype=_TRIANGLE, count=count, offset=_HEADER)["corners"]
        finite = np.isfinite(corners).all(axis=(1, 2))
        if not finite.all():
            raise InputError(
                f"{name}: triangle {int(np.argmin(finite))} has a non-finite coordinate "
                "(NaN or inf)"
            )
    elif head.lstrip()[:5].lower() == b"solid":
        corners = _ascii_corners(path, name)
    elif count >= 0:
        raise InputError(
            f"{name}: not a valid STL file: a binary STL with {count} triangles has "
            f"{_HEADER + _TRIANGLE.itemsize * count} bytes, this file has {size}"
        )
    else:
        raise InputError(f"{name}: not an STL file (too short for binary, no 'solid')")
    if len(corners) == 0:
        raise InputError(f"{name}: the file holds no triangles")
    return _merge_corners(corners.reshape(-1, 3))


def _ascii_corners(path: Path, name: str) -> np.ndarray:
    """(t, 3, 3) float32 corners of the facets of an ASCII STL."""
    data = read_text(path, name, "STL file")
    tokens = tokenize(data, comments=())
    first, count = line_table(tokens)
    heads = tokens.take(first)
    facets, vertex = first[heads.equals(b"facet")], heads.equals(b"vertex")
    v_first, v_count = first[vertex], count[vertex]
    wrong = v_count != 4
    if wrong.any():
        line = tokens.line[v_first[np.argmax(wrong)]]
        raise InputError(f"{name}: line {line}: a vertex line needs exactly x y z")
    owner = np.searchsorted(tokens.line[facets], tokens.line[v_first]) - 1
    per_facet = np.bincount(owner[owner >= 0], minlength=len(facets))
    if (owner < 0).any() or (per_facet != 3).any():
        k = int(np.argmax(per_facet != 3)) if (per_facet != 3).any() else 0
        line = tokens.line[facets[k]] if len(facets) else tokens.line[v_first[0]]
        raise InputError(f"{name}: line {line}: a facet needs exactly 3 vertices")
    xyz = numbers(tokens, v_first[:, None] + np.arange(1, 4), np.float64, name)
    with np.errstate(over="ignore"):
        single = xyz.astype(np.float32)
    finite = np.isfinite(single).all(axis=1)
    if not finite.all():
        line = tokens.line[v_first[np.argmin(finite)]]
        raise InputError(f"{name}: line {line}: coordinate outside the float32 range of STL")
    return single.reshape(-1, 3, 3)


def _merge_corners(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of (3t, 3) float32 ``corners`` in order of first appearance, and
    the (t, 3) triangles indexing them."""
    exact = np.ascontiguousarray(corners + np.float32(0))  # -0.0 and 0.0 are one point
    keys = exact.view(np.dtype((np.void, exact.dtype.itemsize * 3))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    vertices = exact[first[order]].astype(np.float64)
    return vertices, rank[inverse.ravel()].reshape(-1, 3).astype(np.int64)
