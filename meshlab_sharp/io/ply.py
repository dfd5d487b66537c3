"""PLY (ASCII, binary little and big endian), read with numpy.

The header is read with a bounded read and checked before any data: every element's
count is checked against the size of the file, so a huge count is refused at once. The
vertex element must have scalar ``x``, ``y``, ``z`` properties; a ``face`` element's
``vertex_indices`` (or ``vertex_index``) list gives polygons, which become triangle
fans. Every element is read (other elements are skipped), and the data must end where
the header says: a count smaller or larger than the data is an error. A face with fewer
than 3 indices is an error: it has no area and MeshLab would read it as a bogus
triangle.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import InputError
from .polygons import check_corner_limit, fan_triangles
from .text import Tokens, check_text, line_table, numbers, read_text, tokenize

_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
_MAX_HEADER = 1 << 20
_INDEX_NAMES = ("vertex_indices", "vertex_index")
_ELEMENT = re.compile(r"element\s+(\S+)\s+(\d+)")
_SCALAR = re.compile(r"property\s+(\S+)\s+(\S+)")
_NUMERIC = np.zeros(256, dtype=bool)
_NUMERIC[list(b"0123456789eE.+- \t\r\n\x0b\x0c")] = True
_LIST = re.compile(r"property\s+list\s+(\S+)\s+(\S+)\s+(\S+)")


@dataclass
class _Property:
    name: str
    dtype: np.dtype  # of the value, or of the list items
    count_dtype: np.dtype | None = None  # of a list's length; None for a scalar


@dataclass
class _Element:
    name: str
    count: int
    properties: list[_Property]

    def min_bytes(self) -> int:
        """Bytes of one binary item when every list is empty."""
        return sum((p.count_dtype or p.dtype).itemsize for p in self.properties)

    def max_bytes(self) -> int:
        """Bytes of one binary item when every list is as long as its length type allows."""
        return sum(
            p.dtype.itemsize
            if p.count_dtype is None
            else p.count_dtype.itemsize + int(np.iinfo(p.count_dtype).max) * p.dtype.itemsize
            for p in self.properties
        )


class _Faces(NamedTuple):
    corners: np.ndarray  # (s,) int64, the lists one after another
    sizes: np.ndarray  # (f,) int64, length of each list
    lines: np.ndarray | None  # (f,) line of each face (ASCII) or None (binary)

    def where(self, k: int) -> str:
        """Face ``k``, with its line when known, for messages."""
        return f"face {k}" if self.lines is None else f"face {k} (line {self.lines[k]})"


@dataclass
class _Header:
    order: str  # "" for ASCII, "<" or ">" for binary
    elements: list[_Element]
    size: int  # bytes
    lines: int


def read_ply(path: Path, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a PLY file.

    Returns
    -------
    vertices : (n, 3) float64
    faces : (m, 3) int64 or None

    Raises
    ------
    InputError
        A malformed or truncated header, counts that do not match the data, a vertex
        with a non-finite coordinate, a face with fewer than 3 indices or an index
        outside the vertices, no vertices.
    """
    header = _read_header(path, name)
    vertex = next((e for e in header.elements if e.name == "vertex"), None)
    if vertex is None or vertex.count == 0:
        raise InputError(f"{name}: the file holds no points (no vertex element)")
    for axis in "xyz":
        prop = next((p for p in vertex.properties if p.name == axis), None)
        if prop is None or prop.count_dtype is not None:
            raise InputError(f"{name}: the vertex element has no scalar '{axis}' property")
    _check_size(path, header, name)
    read = _read_ascii if header.order == "" else _read_binary
    columns = read(path, header, name)
    xyz = np.stack([columns["vertex"][a] for a in "xyz"], axis=1).astype(np.float64)
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.all():
        raise InputError(
            f"{name}: vertex {int(np.argmin(finite))} has a non-finite coordinate (NaN or inf)"
        )
    faces: _Faces | None = columns.get("face")
    if faces is None or len(faces.sizes) == 0:
        return xyz, None
    few = faces.sizes < 3
    if few.any():
        k = int(np.argmax(few))
        raise InputError(
            f"{name}: {faces.where(k)} has {faces.sizes[k]} vertex indices; a face needs at least 3"
        )
    check_corner_limit(faces.sizes, lambda k: f"{name}: {faces.where(k)}")
    bad = (faces.corners < 0) | (faces.corners >= len(xyz))
    if bad.any():
        at = int(np.argmax(bad))
        k = int(np.searchsorted(np.cumsum(faces.sizes), at, side="right"))
        raise InputError(
            f"{name}: {faces.where(k)} has vertex index {faces.corners[at]}, outside the "
            f"{len(xyz)} vertices"
        )
    return xyz, fan_triangles(faces.corners, faces.sizes)


def _read_header(path: Path, name: str) -> _Header:
    with path.open("rb") as fh:
        raw = fh.read(_MAX_HEADER)
    if not raw.startswith(b"ply") or raw[3:4] not in (b"\n", b"\r"):
        raise InputError(f"{name}: not a PLY file (no 'ply' magic line)")
    end = re.search(rb"(?m)^end_header[ \t]*\r?\n", raw)
    if end is None:
        if len(raw) == _MAX_HEADER:
            raise InputError(f"{name}: no end_header in the first {_MAX_HEADER} bytes")
        raise InputError(f"{name}: truncated PLY header (no end_header)")
    text = raw[: end.start()]
    check_text(text, name, "PLY header")
    lines = text.decode("ascii", "replace").splitlines()
    order = None
    elements: list[_Element] = []
    for number, line in enumerate(lines[1:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3 and order is None:
            if words[1] not in _FORMATS:
                raise InputError(f"{name}: header line {number}: unknown format {words[1]!r}")
            order = _FORMATS[words[1]]
        elif (m := _ELEMENT.fullmatch(line.strip())) is not None:
            elements.append(_Element(m.group(1), int(m.group(2)), []))
        elif (m := _LIST.fullmatch(line.strip())) is not None and elements:
            count_type, item_type = (
                _dtype(m.group(1), name, number),
                _dtype(m.group(2), name, number),
            )
            if count_type.kind not in "iu":
                raise InputError(f"{name}: header line {number}: a list length must be integer")
            elements[-1].properties.append(_Property(m.group(3), item_type, count_type))
        elif (m := _SCALAR.fullmatch(line.strip())) is not None and elements:
            elements[-1].properties.append(_Property(m.group(2), _dtype(m.group(1), name, number)))
        else:
            raise InputError(f"{name}: header line {number}: cannot read {line.strip()[:40]!r}")
    if order is None:
        raise InputError(f"{name}: the PLY header has no format line")
    for element in elements:
        for prop in element.properties:
            prop.dtype = prop.dtype.newbyteorder(order or "=")
            if prop.count_dtype is not None:
                prop.count_dtype = prop.count_dtype.newbyteorder(order or "=")
    return _Header(order, elements, end.end(), len(lines) + 1)


def _dtype(word: str, name: str, number: int) -> np.dtype:
    if word not in _TYPES:
        raise InputError(f"{name}: header line {number}: unknown property type {word!r}")
    return np.dtype(_TYPES[word])


def _check_size(path: Path, header: _Header, name: str) -> None:
    """Refuse counts the file is too small (or, binary, too large) for, before reading
    any data."""
    data = path.stat().st_size - header.size
    if header.order == "":
        need = sum(e.count for e in header.elements if e.properties)  # a line per item
        per = "line"
    else:
        need = sum(e.count * e.min_bytes() for e in header.elements)
        per = "byte"
    if need > data:
        raise InputError(
            f"{name}: truncated PLY file: the header's counts need at least {need} "
            f"{per}s of data, the file has {data} bytes"
        )
    most = sum(e.count * e.max_bytes() for e in header.elements)
    if header.order != "" and data > most:
        raise InputError(
            f"{name}: {data - most} bytes of data after the last element (the header's "
            f"counts allow at most {most} bytes)"
        )


def _read_binary(path: Path, header: _Header, name: str) -> dict:
    """The columns the reader needs, from binary data."""
    buf = np.fromfile(path, dtype=np.uint8, offset=header.size)
    columns: dict = {}
    offset = 0
    for element in header.elements:
        if all(p.count_dtype is None for p in element.properties):
            dtype = np.dtype([(f"p{i}", p.dtype) for i, p in enumerate(element.properties)])
            need = element.count * dtype.itemsize
            if offset + need > len(buf):
                raise _truncated(name, element)
            items = np.frombuffer(buf, dtype=dtype, count=element.count, offset=offset)
            offset += need
            if element.name == "face" and element.count:
                _index_property(element, name)  # raises: a face element needs its list
            if element.name == "vertex":
                columns["vertex"] = {
                    p.name: items[f"p{i}"] for i, p in enumerate(element.properties)
                }
            continue
        starts, sizes, offset = _walk_lists(buf, offset, element, name)
        if element.name == "face":
            prop = _index_property(element, name)
            columns["face"] = _Faces(_gather(buf, starts, sizes, prop.dtype), sizes, None)
    if offset != len(buf):
        raise InputError(
            f"{name}: {len(buf) - offset} bytes of data after the last element (the "
            "header's counts are smaller than the data)"
        )
    return columns


def _index_property(element: _Element, name: str) -> _Property:
    prop = next((p for p in element.properties if p.name in _INDEX_NAMES and p.count_dtype), None)
    if prop is None or prop.dtype.kind not in "iu":
        raise InputError(f"{name}: the face element has no integer vertex_indices list")
    return prop


def _walk_lists(
    buf: np.ndarray, offset: int, element: _Element, name: str
) -> tuple[np.ndarray, np.ndarray, int]:
    """Walk the binary items of an element with list properties.

    Returns the byte offsets and lengths of its ``vertex_indices`` lists (empty arrays
    for another element) and the offset after the element. When the element has one
    list and every item has the first item's list length (all triangles, say) this is
    one numpy step; otherwise a loop over the items.
    """
    props = element.properties
    wanted = next((i for i, p in enumerate(props) if p.name in _INDEX_NAMES), -1)
    lists = [i for i, p in enumerate(props) if p.count_dtype is not None]
    if len(lists) == 1 and element.count > 0:
        i, p = lists[0], props[lists[0]]
        at = offset + sum(q.dtype.itemsize for q in props[:i])
        fits = at + p.count_dtype.itemsize <= len(buf)
        n = int(np.frombuffer(buf, p.count_dtype, 1, at)[0]) if fits else -1
        if n >= 0 and at + p.count_dtype.itemsize + n * p.dtype.itemsize <= len(buf):
            fields = [(f"p{j}", q.dtype) for j, q in enumerate(props)]
            fields[i : i + 1] = [("n", p.count_dtype), ("items", p.dtype, (n,))]
            dtype = np.dtype(fields)
            end = offset + element.count * dtype.itemsize
            if end <= len(buf):
                counts = np.frombuffer(buf, dtype, element.count, offset)["n"]
                if (counts == n).all():
                    if wanted != i:
                        return np.empty(0, np.int64), np.empty(0, np.int64), end
                    step = dtype.itemsize * np.arange(element.count)
                    starts = offset + dtype.fields["items"][1] + step
                    return starts, np.full(element.count, n, dtype=np.int64), end
    return _walk_items(buf, offset, element, wanted, name)


def _walk_items(
    buf: np.ndarray, offset: int, element: _Element, wanted: int, name: str
) -> tuple[np.ndarray, np.ndarray, int]:
    """The general case of :func:`_walk_lists`: one item at a time."""
    raw = buf.data
    layout = [
        (p.dtype.itemsize, None if p.count_dtype is None else struct.Struct(_struct(p.count_dtype)))
        for p in element.properties
    ]
    starts = np.empty(element.count if wanted >= 0 else 0, dtype=np.int64)
    sizes = np.empty_like(starts)
    pos, end = offset, len(buf)
    for item in range(element.count):
        for i, (size, count) in enumerate(layout):
            if count is None:
                pos += size
                continue
            if pos + count.size > end:
                raise _truncated(name, element)
            n = count.unpack_from(raw, pos)[0]
            if n < 0:
                raise InputError(
                    f"{name}: item {item} of element '{element.name}': negative list length"
                )
            pos += count.size
            if i == wanted:
                starts[item], sizes[item] = pos, n
            pos += n * size
        if pos > end:
            raise _truncated(name, element)
    return starts, sizes, pos


def _struct(dtype: np.dtype) -> str:
    """The struct format of an integer numpy dtype."""
    code = {1: "b", 2: "h", 4: "i", 8: "q"}[dtype.itemsize]
    return ("<" if dtype.byteorder in "<=|" else ">") + (
        code.upper() if dtype.kind == "u" else code
    )


def _gather(buf: np.ndarray, starts: np.ndarray, sizes: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """The concatenated lists of ``dtype`` items at byte offsets ``starts``."""
    total = int(sizes.sum())
    item = np.repeat(starts, sizes) + dtype.itemsize * (
        np.arange(total) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    )
    raw = buf[item[:, None] + np.arange(dtype.itemsize)]
    return raw.view(dtype).ravel().astype(np.int64)


def _truncated(name: str, element: _Element) -> InputError:
    return InputError(
        f"{name}: truncated PLY file: the data ends inside element '{element.name}' "
        f"({element.count} items declared)"
    )


def _read_ascii(path: Path, header: _Header, name: str) -> dict:
    """The columns the reader needs, from ASCII data: one line per item."""
    data = read_text(path, name, "ASCII PLY", offset=header.size)
    junk = ~_NUMERIC[np.frombuffer(data, dtype=np.uint8)]
    if junk.any():
        at = int(np.argmax(junk))
        start = max(data.rfind(c, 0, at) for c in (b" ", b"\t", b"\n")) + 1
        word = data[start:].split(maxsplit=1)[0][:24].decode("ascii", "replace")
        line = header.lines + 1 + data.count(b"\n", 0, start)
        if word.lower().lstrip("+-")[:3] in ("nan", "inf"):
            raise InputError(f"{name}: line {line}: non-finite coordinate (NaN or inf): {word}")
        raise InputError(f"{name}: line {line}: {word!r} is not a number")
    tokens = tokenize(data, comments=())
    tokens = Tokens(tokens.buf, tokens.start, tokens.end, tokens.line + header.lines)
    first, count = line_table(tokens)
    columns: dict = {}
    row = 0
    for element in header.elements:
        if not element.properties:
            continue
        lines = slice(row, row + element.count)
        if lines.stop > len(first):
            raise InputError(
                f"{name}: truncated PLY file: element '{element.name}' declares "
                f"{element.count} lines, {max(len(first) - row, 0)} remain"
            )
        found = _ascii_element(tokens, first[lines], count[lines], element, name)
        if element.name in ("vertex", "face"):
            columns[element.name] = found
        row += element.count
    if row != len(first):
        raise InputError(
            f"{name}: line {tokens.line[first[row]]}: {len(first) - row} lines of data after "
            "the last element (the header's counts are smaller than the data)"
        )
    return columns


def _ascii_element(
    tokens: Tokens, first: np.ndarray, count: np.ndarray, element: _Element, name: str
) -> dict[str, np.ndarray] | _Faces:
    """Read the lines of one element, property by property across all its lines.

    Returns the vertex columns (name -> values of the declared type), or the faces.
    """
    pos = first.copy()
    end = first + count
    scalars = {}
    lists = None
    for p in element.properties:
        short = pos >= end
        if short.any():
            raise _line_length(tokens, first, short, element, name)
        if p.count_dtype is None:
            scalars[p.name] = pos
            pos = pos + 1
            continue
        n = numbers(tokens, pos, np.int64, name)
        if (n < 0).any():
            raise _line_length(tokens, first, n < 0, element, name)
        if element.name == "face" and p.name in _INDEX_NAMES:
            lists = (pos + 1, n)
        pos = pos + 1 + n
        over = pos > end
        if over.any():
            raise _line_length(tokens, first, over, element, name)
    wrong = pos != end
    if wrong.any():
        raise _line_length(tokens, first, wrong, element, name)
    if element.name != "face":
        if element.name != "vertex":
            return {}
        xyz = numbers(tokens, np.stack([scalars[a] for a in "xyz"], axis=1), np.float64, name)
        types = {p.name: p.dtype for p in element.properties}
        return {a: _as_type(xyz[:, k], types[a], first, tokens, name) for k, a in enumerate("xyz")}
    _index_property(element, name)
    if lists is None:
        raise InputError(f"{name}: the face element has no integer vertex_indices list")
    starts, sizes = lists
    total = int(sizes.sum())
    at = np.repeat(starts, sizes) + np.arange(total) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    corners = numbers(tokens, at, np.int64, name)
    return _Faces(corners, sizes, tokens.line[first])


def _as_type(
    values: np.ndarray, dtype: np.dtype, first: np.ndarray, tokens: Tokens, name: str
) -> np.ndarray:
    """(n,) float64 ``values`` read from the lines at ``first``, as the declared ``dtype``
    (a float overflow becomes inf, refused later; an integer must fit its type)."""
    if dtype.kind == "f":
        with np.errstate(over="ignore"):
            return values.astype(dtype)
    info = np.iinfo(dtype)
    bad = (values != np.floor(values)) | (values < info.min) | (values > info.max)
    if bad.any():
        line = tokens.line[first[np.argmax(bad)]]
        raise InputError(f"{name}: line {line}: a coordinate is not a {dtype.name} value")
    return values.astype(dtype)


def _line_length(
    tokens: Tokens, first: np.ndarray, wrong: np.ndarray, element: _Element, name: str
) -> InputError:
    line = tokens.line[first[np.argmax(wrong)]]
    return InputError(
        f"{name}: line {line}: the numbers on the line do not match the header's "
        f"properties of element '{element.name}'"
    )
