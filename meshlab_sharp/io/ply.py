"""PLY (ASCII, binary little and big endian), read with numpy.

The header is read with a bounded read and checked before any data: every element's
count is checked against the size of the file, so a huge count is refused at once. The
vertex element must have scalar ``x``, ``y``, ``z`` properties; a ``face`` element's
``vertex_indices`` (or ``vertex_index``) list gives polygons, which become triangle
fans; a ``tristrips`` element's lists give triangle strips, read as MeshLab reads them.
Every element is read (other elements are skipped), and the data must end where the
header says: a count smaller or larger than the data is an error. A face with fewer
than 3 indices is an error: it has no area and MeshLab would read it as a bogus
triangle. An element, or a property of one element, declared twice is an error (which
one would be meant?).
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
#: Elements whose vertex_indices lists give faces: polygons, and triangle strips.
_FACE_ELEMENTS = ("face", "tristrips")
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
    _vertex_element(header, name)
    _check_size(path, header, name)
    read = _read_ascii if header.order == "" else _read_binary
    columns = read(path, header, name)
    xyz = np.stack([columns["vertex"][a] for a in "xyz"], axis=1).astype(np.float64)
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.all():
        raise InputError(
            f"{name}: vertex {int(np.argmin(finite))} has a non-finite coordinate (NaN or inf)"
        )
    parts = []
    for element in header.elements:
        found: _Faces | None = columns.get(element.name)
        if element.name == "face" and found is not None and len(found.sizes):
            parts.append(_polygon_triangles(found, len(xyz), name))
        elif element.name == "tristrips" and found is not None and len(found.sizes):
            parts.append(_strip_triangles(found, len(xyz), name))
    triangles = np.concatenate(parts) if parts else np.empty((0, 3), np.int64)
    return xyz, triangles if len(triangles) else None


def _polygon_triangles(faces: _Faces, n: int, name: str) -> np.ndarray:
    """The ``face`` element's polygons as triangle fans, checked: at least 3 indices
    each, every index one of the ``n`` vertices."""
    few = faces.sizes < 3
    if few.any():
        k = int(np.argmax(few))
        raise InputError(
            f"{name}: {faces.where(k)} has {faces.sizes[k]} vertex indices; a face needs at least 3"
        )
    check_corner_limit(faces.sizes, lambda k: f"{name}: {faces.where(k)}")
    bad = (faces.corners < 0) | (faces.corners >= n)
    if bad.any():
        at = int(np.argmax(bad))
        k = int(np.searchsorted(np.cumsum(faces.sizes), at, side="right"))
        raise InputError(
            f"{name}: {faces.where(k)} has vertex index {faces.corners[at]}, outside the "
            f"{n} vertices"
        )
    return fan_triangles(faces.corners, faces.sizes)


def _strip_triangles(strips: _Faces, n: int, name: str) -> np.ndarray:
    """The ``tristrips`` element's triangles, as MeshLab reads them.

    Each list is one or more strips separated by -1: a strip of m indices gives m - 2
    triangles, every second one with its first two corners swapped so that all turn
    the same way. MeshLab's reader (vcglib's ``import_ply.h``) is followed step by
    step, including where it steps over a -1; where it would read outside its vertices
    (an index out of range, or a -1 inside a triangle) the file is refused.
    """
    triangles: list[tuple[int, int, int]] = []
    bounds = np.cumsum(strips.sizes)
    for item, (stop, size) in enumerate(zip(bounds.tolist(), strips.sizes.tolist(), strict=True)):
        v = strips.corners[stop - size : stop].tolist()
        k, remainder = 0, 0
        while k < size - 2:
            a, b, c = v[k : k + 3]
            corners = (a,) if c == -1 else (a, b, c)  # MeshLab checks a, and reads b, c
            bad = next((x for x in corners if not 0 <= x < n), None)
            if bad is not None:
                line = "" if strips.lines is None else f" (line {strips.lines[item]})"
                raise InputError(
                    f"{name}: tristrips item {item}{line} has vertex index {bad} where a "
                    f"triangle needs one of the {n} vertices"
                )
            if c == -1:  # the strip ends: step over the -1
                k += 2
                remainder = 0 if k % 2 else 1
            else:
                triangles.append((b, a, c) if (k + remainder) % 2 else (a, b, c))
            k += 1
    return np.array(triangles, dtype=np.int64).reshape(-1, 3)


def binary_vertex_layout(path: Path, name: str) -> tuple[int, np.dtype, int, int] | None:
    """Where a binary PLY's vertices are, to map them without reading the file:
    (offset of the vertex data, record dtype, vertices, faces).

    None for an ASCII PLY, or when the vertex element is not first or has a list
    property (then :func:`read_ply` reads the file). The header and the size of the
    data are checked as :func:`read_ply` checks them, with the same errors: the elements
    after the vertices are walked (not read) to find where the data ends.

    Raises
    ------
    InputError
        A malformed header, or counts that do not match the data.
    """
    header = _read_header(path, name)
    vertex = _vertex_element(header, name)
    _check_size(path, header, name)
    if header.order == "" or header.elements[0] is not vertex:
        return None
    if any(p.count_dtype is not None for p in vertex.properties):
        return None
    record = np.dtype([(p.name, p.dtype) for p in vertex.properties])
    size = path.stat().st_size - header.size
    offset = vertex.count * record.itemsize
    rest = header.elements[1:]
    if any(p.count_dtype is not None for e in rest for p in e.properties if e.count):
        buf = np.memmap(path, dtype=np.uint8, mode="r", offset=header.size, shape=(size,))
        for element in rest:
            if element.count and any(p.count_dtype is not None for p in element.properties):
                offset = _walk_lists(buf, offset, element, [], name)[2]
            else:
                offset += element.count * element.min_bytes()
        del buf
    else:
        offset += sum(e.count * e.min_bytes() for e in rest)
    if offset > size:
        raise _truncated(name, header.elements[-1])
    _no_trailing_bytes(size - offset, name)
    faces = sum(e.count for e in header.elements if e.name in _FACE_ELEMENTS)
    return header.size, record, vertex.count, faces


def _vertex_element(header: _Header, name: str) -> _Element:
    """The vertex element, with scalar ``x``, ``y``, ``z`` and at least one vertex."""
    vertex = next((e for e in header.elements if e.name == "vertex"), None)
    if vertex is None or vertex.count == 0:
        raise InputError(f"{name}: the file holds no points (no vertex element)")
    for axis in "xyz":
        prop = next((p for p in vertex.properties if p.name == axis), None)
        if prop is None or prop.count_dtype is not None:
            raise InputError(f"{name}: the vertex element has no scalar '{axis}' property")
    return vertex


def _no_trailing_bytes(extra: int, name: str) -> None:
    """Refuse binary data left after the last element."""
    if extra:
        raise InputError(
            f"{name}: {extra} bytes of data after the last element (the "
            "header's counts are smaller than the data)"
        )


def read_ply_properties(path: Path, name: str) -> dict[str, np.ndarray]:
    """Every scalar vertex property of a PLY file other than ``x``, ``y``, ``z``
    (normals, colours, quality, scalar fields), by name, in the file's order and types
    (native byte order); empty when there is none, without reading the data. The file
    is checked as :func:`read_ply` checks it."""
    header = _read_header(path, name)
    vertex = next((e for e in header.elements if e.name == "vertex"), None)
    wanted = [] if vertex is None else [
        p for p in vertex.properties if p.count_dtype is None and p.name not in ("x", "y", "z")
    ]  # fmt: skip
    if not wanted:
        return {}
    _check_size(path, header, name)
    if header.order == "":
        columns = _read_ascii(path, header, name, every_scalar=True)["vertex"]
    else:
        columns = _read_binary(path, header, name)["vertex"]
    return {p.name: np.asarray(columns[p.name], p.dtype.newbyteorder("=")) for p in wanted}


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
    _check_names(elements, name)
    for element in elements:
        for prop in element.properties:
            prop.dtype = prop.dtype.newbyteorder(order or "=")
            if prop.count_dtype is not None:
                prop.count_dtype = prop.count_dtype.newbyteorder(order or "=")
    return _Header(order, elements, end.end(), len(lines) + 1)


def _check_names(elements: list[_Element], name: str) -> None:
    """Refuse what would be read ambiguously: an element or a property of one element
    declared twice."""
    seen: set[str] = set()
    for element in elements:
        if element.name in seen:
            raise InputError(f"{name}: the PLY header declares element '{element.name}' twice")
        seen.add(element.name)
        props = [p.name for p in element.properties]
        twice = next((n for i, n in enumerate(props) if n in props[:i]), None)
        if twice is not None:
            raise InputError(
                f"{name}: the PLY header declares property '{twice}' of element "
                f"'{element.name}' twice"
            )


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
            if element.name in _FACE_ELEMENTS and element.count:
                _index_property(element, name)  # raises: a face element needs its list
            if element.name == "vertex":
                columns["vertex"] = {
                    p.name: items[f"p{i}"] for i, p in enumerate(element.properties)
                }
            continue
        props = element.properties
        if element.name in _FACE_ELEMENTS:
            wanted = [props.index(_index_property(element, name))]
        elif element.name == "vertex":
            wanted = [i for i, p in enumerate(props) if p.name in ("x", "y", "z")]
        else:
            wanted = []
        where, sizes, offset = _walk_lists(buf, offset, element, wanted, name)
        if element.name in _FACE_ELEMENTS:
            i = wanted[0]
            corners = _gather(buf, where[i], sizes[i], props[i].dtype).astype(np.int64)
            columns[element.name] = _Faces(corners, sizes[i], None)
        elif element.name == "vertex":
            columns["vertex"] = {
                props[i].name: _values(buf, where[i], props[i].dtype) for i in wanted
            }
    _no_trailing_bytes(len(buf) - offset, name)
    return columns


def _index_property(element: _Element, name: str) -> _Property:
    prop = next((p for p in element.properties if p.name in _INDEX_NAMES and p.count_dtype), None)
    if prop is None or prop.dtype.kind not in "iu":
        raise InputError(f"{name}: the {element.name} element has no integer vertex_indices list")
    return prop


def _walk_lists(
    buf: np.ndarray, offset: int, element: _Element, wanted: list[int], name: str
) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], int]:
    """Walk the binary items of an element with list properties.

    Returns, for each property index in ``wanted``, the byte offset in every item of
    its value (a scalar) or of its first list item, and the list lengths (lists only),
    then the offset after the element. When the element has one list and every item
    has the first item's list length (all triangles, say) this is one numpy step;
    otherwise a loop over the items.
    """
    props = element.properties
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
                    step = offset + dtype.itemsize * np.arange(element.count)
                    where = {
                        j: step + dtype.fields["items" if j == i else f"p{j}"][1] for j in wanted
                    }
                    sizes = {i: np.full(element.count, n, dtype=np.int64)} if i in wanted else {}
                    return where, sizes, end
    return _walk_items(buf, offset, element, wanted, name)


def _walk_items(
    buf: np.ndarray, offset: int, element: _Element, wanted: list[int], name: str
) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray], int]:
    """The general case of :func:`_walk_lists`: one item at a time."""
    raw = buf.data
    layout = [
        (p.dtype.itemsize, None if p.count_dtype is None else struct.Struct(_struct(p.count_dtype)))
        for p in element.properties
    ]
    where = {i: np.empty(element.count, dtype=np.int64) for i in wanted}
    sizes = {i: np.empty(element.count, dtype=np.int64) for i in wanted if layout[i][1]}
    pos, end = offset, len(buf)
    for item in range(element.count):
        for i, (size, count) in enumerate(layout):
            if count is None:
                if i in where:
                    where[i][item] = pos
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
            if i in where:
                where[i][item], sizes[i][item] = pos, n
            pos += n * size
        if pos > end:
            raise _truncated(name, element)
    return where, sizes, pos


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
    return _values(buf, item, dtype)


def _values(buf: np.ndarray, where: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """The ``dtype`` values at byte offsets ``where``."""
    return buf[where[:, None] + np.arange(dtype.itemsize)].view(dtype).ravel()


def _truncated(name: str, element: _Element) -> InputError:
    return InputError(
        f"{name}: truncated PLY file: the data ends inside element '{element.name}' "
        f"({element.count} items declared)"
    )


def _read_ascii(path: Path, header: _Header, name: str, *, every_scalar: bool = False) -> dict:
    """The columns the reader needs (with ``every_scalar``, every scalar vertex
    property), from ASCII data: one line per item."""
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
        found = _ascii_element(tokens, first[lines], count[lines], element, name, every_scalar)
        if element.name in ("vertex", *_FACE_ELEMENTS):
            columns[element.name] = found
        row += element.count
    if row != len(first):
        raise InputError(
            f"{name}: line {tokens.line[first[row]]}: {len(first) - row} lines of data after "
            "the last element (the header's counts are smaller than the data)"
        )
    return columns


def _ascii_element(
    tokens: Tokens,
    first: np.ndarray,
    count: np.ndarray,
    element: _Element,
    name: str,
    every_scalar: bool = False,
) -> dict[str, np.ndarray] | _Faces:
    """Read the lines of one element, property by property across all its lines.

    Returns the vertex columns (name -> values of the declared type: ``x``, ``y``,
    ``z``, or with ``every_scalar`` every scalar property), or the faces.
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
        if element.name in _FACE_ELEMENTS and p.name in _INDEX_NAMES:
            lists = (pos + 1, n)
        pos = pos + 1 + n
        over = pos > end
        if over.any():
            raise _line_length(tokens, first, over, element, name)
    wrong = pos != end
    if wrong.any():
        raise _line_length(tokens, first, wrong, element, name)
    if element.name not in _FACE_ELEMENTS:
        if element.name != "vertex":
            return {}
        names = list(scalars) if every_scalar else ["x", "y", "z"]
        values = numbers(tokens, np.stack([scalars[a] for a in names], axis=1), np.float64, name)
        types = {p.name: p.dtype for p in element.properties}
        return {
            a: _as_type(values[:, k], types[a], first, tokens, name, a) for k, a in enumerate(names)
        }
    _index_property(element, name)
    assert lists is not None  # _index_property found the list
    starts, sizes = lists
    total = int(sizes.sum())
    at = np.repeat(starts, sizes) + np.arange(total) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    corners = numbers(tokens, at, np.int64, name)
    return _Faces(corners, sizes, tokens.line[first])


def _as_type(
    values: np.ndarray,
    dtype: np.dtype,
    first: np.ndarray,
    tokens: Tokens,
    name: str,
    prop: str,
) -> np.ndarray:
    """(n,) float64 ``values`` of the property ``prop`` read from the lines at ``first``,
    as the declared ``dtype`` (a float overflow becomes inf, refused later; an integer
    must fit its type)."""
    if dtype.kind == "f":
        with np.errstate(over="ignore"):
            return values.astype(dtype)
    info = np.iinfo(dtype)
    bad = (values != np.floor(values)) | (values < info.min) | (values > info.max)
    if bad.any():
        line = tokens.line[first[np.argmax(bad)]]
        what = "a coordinate" if prop in ("x", "y", "z") else f"the vertex property {prop!r}"
        raise InputError(f"{name}: line {line}: {what} is not a {dtype.name} value")
    return values.astype(dtype)


def _line_length(
    tokens: Tokens, first: np.ndarray, wrong: np.ndarray, element: _Element, name: str
) -> InputError:
    line = tokens.line[first[np.argmax(wrong)]]
    return InputError(
        f"{name}: line {line}: the numbers on the line do not match the header's "
        f"properties of element '{element.name}'"
    )
