"""Malformed input files for every accepted format, generated from deterministic seeds.

Each :class:`Case` is a file's name and bytes and what the command line must do with it:
``"ok"`` (exit 0), ``"error"`` (exit 1 with one ``meshlab-sharp: error:`` line) or
``"either"`` (a random mutation that may or may not leave the file valid). Also
:func:`hostile_geometries`: finite but degenerate geometry, for any consumer that must
not crash on it (the readers, the pipeline, the MeshLab plugin).
"""

from __future__ import annotations

import re
import struct
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import shapes

#: Tokens a hostile user puts where a number belongs.
BAD_TOKENS = [b"nan", b"-inf", b"1e400", b"0x1F", b"1.2.3", b"--1", b"1_0", b"1e", b"+"]
#: Tokens that are numbers but may be bad indices.
ODD_NUMBERS = [b"-1", b"0", b"99999", b"4294967296", b"1e-320", b"-0"]


@dataclass(frozen=True)
class Case:
    """One file for the command line."""

    name: str
    suffix: str
    data: bytes
    expect: str  # "ok", "error" or "either"


# ---------------------------------------------------------------- valid files


def ply(
    v: np.ndarray, f: np.ndarray | None, fmt: str = "ascii", lists: list[list[int]] | None = None
) -> bytes:
    """A PLY of float x y z and (optionally) int vertex_indices lists (more columns of
    ``v`` are written as data; the caller declares them in the header)."""
    lists = [list(t) for t in f] if lists is None and f is not None else lists or []
    head = (
        f"ply\nformat {fmt} 1.0\ncomment fuzz\nelement vertex {len(v)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(lists)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    if fmt == "ascii":
        rows = [b" ".join(b"%r" % float(c) for c in p) for p in v.astype(np.float32)]
        rows += [b" ".join(b"%d" % x for x in [len(t), *t]) for t in lists]
        return head + b"\n".join(rows) + b"\n"
    e = "<" if fmt == "binary_little_endian" else ">"
    body = v.astype(e + "f4").tobytes()
    body += b"".join(struct.pack(f"{e}B{len(t)}i", len(t), *t) for t in lists)
    return head + body


def obj(v: np.ndarray, f: np.ndarray | None, corner: str = "{}") -> bytes:
    rows = [b"v %r %r %r" % tuple(map(float, p)) for p in v]
    if f is not None:
        rows += [("f " + " ".join(corner.format(i + 1) for i in t)).encode() for t in f.tolist()]
    return b"# fuzz\n" + b"\n".join(rows) + b"\n"


def off(v: np.ndarray, f: np.ndarray | None) -> bytes:
    f = np.zeros((0, 3), int) if f is None else f
    rows = [b"OFF", b"%d %d 0" % (len(v), len(f))]
    rows += [b"%r %r %r" % tuple(map(float, p)) for p in v]
    rows += [b"3 %d %d %d" % tuple(t) for t in f.tolist()]
    return b"\n".join(rows) + b"\n"


def stl_binary(v: np.ndarray, f: np.ndarray) -> bytes:
    tri = np.zeros(len(f), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    tri["v"] = v[f]
    return b"fuzz".ljust(80) + struct.pack("<I", len(f)) + tri.tobytes()


def stl_ascii(v: np.ndarray, f: np.ndarray) -> bytes:
    rows = [b"solid fuzz"]
    for t in f.tolist():
        rows += [b"facet normal 0 0 0", b"outer loop"]
        rows += [b"vertex %r %r %r" % tuple(map(float, v[i].astype(np.float32))) for i in t]
        rows += [b"endloop", b"endfacet"]
    return b"\n".join([*rows, b"endsolid fuzz"]) + b"\n"


def point_list(v: np.ndarray, sep: bytes = b" ", count: bool = False, extra: int = 0) -> bytes:
    cols = [b"10", b"200", b"100", b"50"][:extra]
    rows = [sep.join([*(b"%r" % float(x) for x in p), *cols]) for p in v]
    return b"\n".join([b"%d" % len(v)] * count + rows) + b"\n"


MESH = shapes.cube_grid_mesh(3)
CLOUD = shapes.cube_grid_points(9)

#: name -> (suffix, bytes) of a valid file of each format and variant.
VALID: dict[str, tuple[str, bytes]] = {
    "ply-ascii": (".ply", ply(*MESH)),
    "ply-le": (".ply", ply(*MESH, "binary_little_endian")),
    "ply-be": (".ply", ply(*MESH, "binary_big_endian")),
    "obj": (".obj", obj(*MESH, corner="{0}//{0}")),
    "off": (".off", off(*MESH)),
    "stl-ascii": (".stl", stl_ascii(*MESH)),
    "stl-binary": (".stl", stl_binary(*MESH)),
    "xyz": (".xyz", point_list(CLOUD)),
    "pts": (".pts", point_list(CLOUD, count=True, extra=4)),
    "asc": (".asc", point_list(CLOUD, extra=1)),
    "txt": (".txt", point_list(CLOUD, sep=b",")),
}
TEXT = {k for k, (_, data) in VALID.items() if b"\0" not in data and not k.endswith(("le", "be"))}


# ---------------------------------------------------------------- mutations


def _numeric_tokens(data: bytes) -> list[re.Match[bytes]]:
    return list(re.finditer(rb"(?<![\w.+-])[-+]?\d[\d.eE+-]*", data))


def _replace_token(data: bytes, rng: np.random.Generator, new: bytes) -> bytes:
    tokens = _numeric_tokens(data)
    m = tokens[int(rng.integers(len(tokens) // 3, len(tokens)))]  # past most headers
    return data[: m.start()] + new + data[m.end() :]


def _random_cases(key: str, suffix: str, data: bytes, seed: int) -> Iterator[Case]:
    """Mutations every format gets: a truncation, garbage, bad tokens, line edits."""
    rng = np.random.default_rng(seed)
    cut = int(rng.integers(1, len(data)))
    yield Case(f"{key}-truncated", suffix, data[:cut], "either")
    at = int(rng.integers(0, len(data) - 16))
    junk = rng.bytes(16)
    yield Case(f"{key}-garbage-inside", suffix, data[:at] + junk + data[at + 16 :], "either")
    yield Case(f"{key}-only-garbage", suffix, rng.bytes(2048), "error")
    if key not in TEXT:
        return
    bad = BAD_TOKENS[int(rng.integers(len(BAD_TOKENS)))]
    yield Case(f"{key}-token-{bad.decode()}", suffix, _replace_token(data, rng, bad), "either")
    odd = ODD_NUMBERS[int(rng.integers(len(ODD_NUMBERS)))]
    yield Case(f"{key}-number-{odd.decode()}", suffix, _replace_token(data, rng, odd), "either")
    crlf_tabs = data.replace(b"\n", b"\r\n").replace(b" ", b"\t")
    yield Case(f"{key}-crlf-tabs", suffix, crlf_tabs, "ok")
    lines = data.split(b"\n")
    row = int(rng.integers(len(lines) // 2, len(lines) - 1))
    twice, dropped = lines[: row + 1] + lines[row:], lines[:row] + lines[row + 1 :]
    edited = twice if rng.random() < 0.5 else dropped
    yield Case(f"{key}-line-edited", suffix, b"\n".join(edited), "either")


def _line(data: bytes, row: int, new: bytes) -> bytes:
    """``data`` with line ``row`` (0-based) replaced by ``new``."""
    lines = data.split(b"\n")
    return b"\n".join([*lines[:row], new, *lines[row + 1 :]])


def _ply_cases(v: np.ndarray, f: np.ndarray) -> Iterator[Case]:
    n, tri = len(v), [list(t) for t in f.tolist()]
    nan = v.copy()
    nan[7, 2] = np.nan
    for fmt in ("ascii", "binary_little_endian", "binary_big_endian"):
        short = fmt[:10]
        good = ply(v, f, fmt)
        yield Case(f"ply-{short}-2-index-face", ".ply", ply(v, None, fmt, [*tri, [0, 1]]), "error")
        far = ply(v, None, fmt, [*tri, [0, 1, 99999]])
        yield Case(f"ply-{short}-index-far", ".ply", far, "error")
        yield Case(f"ply-{short}-quads", ".ply", ply(v, None, fmt, [[0, 1, 2, 3], *tri]), "ok")
        yield Case(f"ply-{short}-nan", ".ply", ply(nan, f, fmt), "error")
        if fmt == "binary_big_endian":
            continue
        yield Case(f"ply-{short}-1-index-face", ".ply", ply(v, None, fmt, [[5], *tri]), "error")
        negative = ply(v, None, fmt, [[0, -1, 2], *tri])
        yield Case(f"ply-{short}-index-negative", ".ply", negative, "error")
        smaller = good.replace(b"face %d" % len(f), b"face %d" % (len(f) - 1))
        yield Case(f"ply-{short}-count-smaller", ".ply", smaller, "error")
        larger = good.replace(b"vertex %d" % n, b"vertex %d" % (n + 1))
        yield Case(f"ply-{short}-count-larger", ".ply", larger, "error")
        huge = good.replace(b"vertex %d" % n, b"vertex 99999999999999")
        yield Case(f"ply-{short}-count-huge", ".ply", huge, "error")
        yield Case(f"ply-{short}-trailing", ".ply", good + b"\n0 0 0\n", "error")
    good = ply(v, f, "binary_little_endian")
    end = good.index(b"end_header\n") + 11 + 12 * n  # the first face's list length
    for name, count_type, length in [("int", b"<i", 2**31 - 1), ("char", b"<b", -5)]:
        head = good[:end].replace(b"list uchar int", b"list " + name.encode() + b" int")
        body = struct.pack(count_type.decode(), length) + good[end + 1 :]
        yield Case(f"ply-list-length-{name}-{length}", ".ply", head + body, "error")
    ascii_head = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty %s x\nproperty float y\n"
    ascii_head += b"property float z\nend_header\n"
    yield Case("ply-float-overflow", ".ply", ascii_head % b"float" + b"0 1e39 0\n", "error")
    yield Case("ply-uchar-300", ".ply", ascii_head % b"uchar" + b"300 1 0\n", "error")
    no_end = b"ply\nformat ascii 1.0\nelement vertex 3\n" + b"0 0 0\n" * 3
    yield Case("ply-no-end-header", ".ply", no_end, "error")
    bad_type = ply(v, f).replace(b"property float x", b"property float128 x")
    yield Case("ply-bad-type", ".ply", bad_type, "error")
    for fmt in ("ascii", "binary_little_endian"):
        good = ply(v, f, fmt)
        twice = ply(np.c_[v, v[:, 0] + 1], f, fmt).replace(
            b"property float z\n", b"property float z\nproperty float x\n"
        )
        yield Case(f"ply-{fmt[:10]}-property-twice", ".ply", twice, "error")
        strips = good.replace(b"element face", b"element tristrips")
        yield Case(f"ply-{fmt[:10]}-tristrips", ".ply", strips, "ok")
        yield Case(f"ply-{fmt[:10]}-vertex-list", ".ply", vertex_list_ply(v, f, fmt), "ok")


def vertex_list_ply(v: np.ndarray, f: np.ndarray, fmt: str) -> bytes:
    """A PLY whose vertex element has a list property between y and z (lengths 0, 1,
    2, 0, ...), with double z: a reader must skip the lists to find z."""
    head = (
        f"ply\nformat {fmt} 1.0\nelement vertex {len(v)}\nproperty float x\n"
        "property float y\nproperty list uchar short extra\nproperty double z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    lengths = np.arange(len(v)) % 3
    xy = v[:, :2].astype(np.float32)
    if fmt == "ascii":
        rows = [
            b" ".join([b"%r %r %d" % (float(x), float(y), k), *[b"7"] * k, b"%r" % float(z)])
            for (x, y), z, k in zip(xy, v[:, 2], lengths, strict=True)
        ]
        rows += [b"3 %d %d %d" % tuple(t) for t in f]
        return head + b"\n".join(rows) + b"\n"
    e = "<" if fmt == "binary_little_endian" else ">"
    body = b"".join(
        struct.pack(f"{e}ffB{k}hd", x, y, k, *[7] * k, z)
        for (x, y), z, k in zip(xy, v[:, 2], lengths, strict=True)
    )
    return head + body + b"".join(struct.pack(f"{e}B3i", 3, *t) for t in f)


def _obj_cases(v: np.ndarray, f: np.ndarray) -> Iterator[Case]:
    n = len(v)
    grid = obj(v, None)
    for name, face in [
        ("index-far-tabs", b"f\t1\t2\t99999"),
        ("index-far-polygon", b"f 1 2 3 4 5 6 7 99999 8"),
        ("index-zero", b"f 0 1 2"),
        ("index-negative-past-first", b"f -1 -2 -%d" % (n + 1)),
        ("2-corner-face", b"f 1 2"),
        ("empty-corner", b"f 1 /2 3"),
    ]:
        yield Case(f"obj-{name}", ".obj", grid + face + b"\n", "error")
    yield Case("obj-negative-relative", ".obj", obj(v, f - n - 1), "ok")
    yield Case("obj-overflow", ".obj", grid + b"v 1 1e400 0\n", "error")
    yield Case("obj-no-vertices", ".obj", b"# nothing\ng group\n", "error")


def _off_cases(v: np.ndarray, f: np.ndarray) -> Iterator[Case]:
    n, good = len(v), off(v, f)
    face = 2 + n  # the first face's line
    yield Case("off-count-mismatch", ".off", _line(good, face, b"3 0 1 2 3 4 5 6 7"), "error")
    yield Case("off-declared-4-given-3", ".off", _line(good, face, b"4 0 1 2"), "error")
    yield Case("off-index-far", ".off", _line(good, face, b"3 0 1 99999"), "error")
    yield Case("off-index-negative", ".off", _line(good, face, b"3 -1 0 1"), "error")
    wrapped = re.sub(rb"\n3 (\d+) (\d+) (\d+)", rb"\n3 \1\n\2\n\3", good)
    yield Case("off-faces-across-lines", ".off", wrapped, "ok")
    yield Case("off-count-huge", ".off", _line(good, 1, b"%d 99999999999 0" % n), "error")
    yield Case("off-count-smaller", ".off", _line(good, 1, b"%d %d 0" % (n, len(f) - 1)), "error")


def _stl_cases(v: np.ndarray, f: np.ndarray) -> Iterator[Case]:
    good = stl_binary(v, f)
    at = 84 + 50 * 5 + 12 + 4  # triangle 5, first corner, y
    nan = good[:at] + struct.pack("<f", np.nan) + good[at + 4 :]
    yield Case("stl-binary-nan", ".stl", nan, "error")
    larger = good[:80] + struct.pack("<I", len(f) + 1) + good[84:]
    yield Case("stl-binary-count-larger", ".stl", larger, "error")
    yield Case("stl-binary-trailing", ".stl", good + b"\0" * 7, "error")
    text = stl_ascii(v, f)
    two = re.sub(rb"vertex [^\n]*\n", b"", text, count=1)
    yield Case("stl-ascii-2-vertex-facet", ".stl", two, "error")
    yield Case("stl-ascii-nan", ".stl", text.replace(b"vertex ", b"vertex nan ", 1), "error")


def _point_list_cases() -> Iterator[Case]:
    good = point_list(CLOUD)
    yield Case("xyz-hex", ".xyz", good.replace(b"\n", b"\n0x1F 0 0\n", 1), "error")
    yield Case("xyz-two-columns", ".xyz", good + b"1 2\n", "error")
    yield Case("xyz-empty-lines", ".xyz", good.replace(b"\n", b"\n\n\n"), "ok")
    counted = point_list(CLOUD, count=True)
    first = b"%d\n" % len(CLOUD)
    yield Case(
        "pts-count-wrong", ".pts", counted.replace(first, b"%d\n" % (len(CLOUD) + 1), 1), "error"
    )
    yield Case("pts-count-huge", ".pts", counted.replace(first, b"9" * 30 + b"\n", 1), "error")


def _specific_cases() -> Iterator[Case]:
    """The format-specific hostile files, with known answers."""
    yield from _ply_cases(*MESH)
    yield from _obj_cases(*MESH)
    yield from _off_cases(*MESH)
    yield from _stl_cases(*MESH)
    yield from _point_list_cases()


def cases(seed: int = 0) -> list[Case]:
    """Every generated case: random mutations of each valid file, then the specific ones."""
    out = [Case(f"{k}-valid", s, d, "ok") for k, (s, d) in VALID.items()]
    for i, (key, (suffix, data)) in enumerate(VALID.items()):
        out += _random_cases(key, suffix, data, seed * 1000 + i)
    out += _specific_cases()
    return out


# ---------------------------------------------------------------- hostile geometry


def hostile_geometries() -> Iterator[tuple[str, np.ndarray, np.ndarray | None]]:
    """Finite but degenerate geometries: (name, (n, 3) vertices, (m, 3) faces or None).

    Nothing here is invalid input, yet each breaks a naive normal, neighbourhood or
    threshold computation: identical points, points on a line or plane, a handful of
    points, zero-area faces, non-manifold fans, duplicate faces, huge and tiny units.
    """
    rng = np.random.default_rng(9)
    line = np.outer(np.linspace(0, 1, 60), [1.0, 2.0, 3.0])
    plane = np.c_[rng.random((80, 2)), np.zeros(80)]
    yield "identical", np.ones((50, 3)), None
    yield "collinear", line, None
    yield "coplanar", plane, None
    yield "three-points", np.eye(3), None
    yield "two-clusters", np.r_[rng.random((40, 3)), rng.random((40, 3)) + 1e6], None
    yield "duplicates", np.repeat(shapes.cube_grid_points(5), 3, axis=0), None
    yield "tiny-unit", shapes.cube_grid_points(5) * 1e-150, None
    yield "huge-unit", shapes.cube_grid_points(5) * 1e150, None
    tri = np.array([[0, 1, 2]])
    yield "one-triangle", np.eye(3), tri
    yield "zero-area-faces", line[:6], np.array([[0, 1, 2], [1, 2, 3], [3, 4, 5]])
    yield "identical-face-corners", np.eye(3), np.array([[0, 0, 0], [0, 1, 2]])
    fan = np.r_[[[0.0, 0, 0]], [[np.cos(a), np.sin(a), z] for a in range(6) for z in (0, 1)]]
    yield "non-manifold-fan", fan, np.array([[0, i, i + 1] for i in range(1, 12)] * 2)
    v, f = shapes.cube_grid_mesh(2)
    yield "duplicate-faces", v, np.r_[f, f, f[:, ::-1]]
    yield "unreferenced-vertices", np.r_[v, rng.random((20, 3))], f
    cube = shapes.cube_grid_points(9)
    yield "one-point", np.array([[1.0, 2.0, 3.0]]), None
    yield "fewer-points-than-k", cube[:30], None
    yield "far-outlier", np.r_[cube, [[1e12, -1e12, 1e12]]], None
    yield "float32-tiny-unit", cube * 1e-30, None
    yield "float32-huge-unit", cube * 1e30, None
    yield (
        "flat-mesh",
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]]),
        np.array([[0, 1, 2], [1, 3, 2]]),
    )


# ---------------------------------------------------------------- scanner files, bounds


def _las(points: np.ndarray, compress: bool = False) -> bytes:
    """A LAS (or LAZ) file of ``points``, point format 0, as meshlab_sharp writes it."""
    import io

    import laspy

    header = laspy.LasHeader(point_format=0, version="1.2")
    header.scales = np.array([1e-4] * 3)
    header.offsets = points.min(axis=0) if len(points) else np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    buf = io.BytesIO()
    las.write(buf, do_compress=compress)
    return buf.getvalue()


def _e57(points: np.ndarray) -> bytes:
    """An E57 file of ``points`` (pye57 writes files only: through a temporary one)."""
    import tempfile
    from pathlib import Path

    from meshlab_sharp.io.e57 import write_e57

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cloud.e57"
        write_e57(path, points)
        return path.read_bytes()


def _patch(data: bytes, at: int, fmt: str, *values: float) -> bytes:
    """``data`` with ``values`` packed little-endian as ``fmt`` at byte ``at``."""
    out = bytearray(data)
    struct.pack_into("<" + fmt, out, at, *values)
    return bytes(out)


def scanner_cases() -> Iterator[Case]:
    """LAS, LAZ and E57 files that laspy, lazrs and pye57 fail on, file names that are
    not UTF-8 (the byte 0xff in the suffix, the output's name stays plain), and faces
    beyond the corner limit, each with its known answer."""
    las = _las(CLOUD)
    offset = struct.unpack_from("<I", las, 96)[0]
    yield Case("las-valid", ".las", las, "ok")
    yield Case("las-zero-points", ".las", _las(np.zeros((0, 3))), "error")
    yield Case("las-truncated-mid-points", ".las", las[: offset + 20 * 100 + 7], "error")
    yield Case("las-huge-offset", ".las", _patch(las, 96, "I", 0xFFFFFFF0), "error")
    yield Case("las-huge-vlr-count", ".las", _patch(las, 100, "I", 0xFFFFFFFF), "error")
    yield Case("las-scale-inf", ".las", _patch(las, 131, "d", float("inf")), "error")
    yield Case("las-scale-overflow", ".las", _patch(las, 131, "d", 1e308), "error")
    yield Case("las-no-signature", ".las", b"LASX" + las[4:], "error")
    laz = _las(CLOUD, compress=True)
    yield Case("laz-valid", ".laz", laz, "ok")
    yield Case("laz-truncated", ".laz", laz[: len(laz) // 2], "error")
    garbled = bytearray(laz)
    for i in range(len(laz) // 2, len(laz) // 2 + 200):
        garbled[i] ^= 0x5A
    yield Case("laz-garbled-chunk", ".laz", bytes(garbled), "error")
    e57 = _e57(CLOUD)
    yield Case("e57-valid", ".e57", e57, "ok")
    crc = bytearray(e57)
    for i in range(2000, 2050):
        crc[i] ^= 0xFF
    yield Case("e57-crc-page-error", ".e57", bytes(crc), "error")
    yield Case("name-not-utf8", "\udcff.xyz", point_list(CLOUD), "ok")
    yield Case("name-not-utf8-e57", "\udcff.e57", e57, "error")
    head = b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n"
    yield Case("off-size-5000-digits", ".off", head + b"9" * 5000 + b" 0 1 2\n", "error")
    yield Case("off-size-5000-digits-walk", ".off", head + b"9" * 5000 + b"\n0 1 2\n", "error")
    yield Case("off-face-2000-corners", ".off", head + b"2000 0 1 2\n", "error")
    n = 100_000
    angle = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ring = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(n)])
    corners = " ".join(str(i) for i in range(1, n + 1)).encode()
    yield Case(
        "obj-face-100000-corners", ".obj", obj(ring, None) + b"f " + corners + b"\n", "error"
    )
