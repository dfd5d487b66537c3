"""Fuzzing: malformed files through the real command line, hostile arrays through the API.

Every generated file (``malformed.py``: every accepted format, truncations, garbage,
bad tokens and counts, bad face indices...) runs as its own ``meshlab-sharp detect``
process, so a native crash shows as a signal, not as a dead test run. Each must exit 0
or 1, print exactly one ``meshlab-sharp: error:`` line when it fails, finish within a
time limit and leave its input untouched. Arrays and options given to
:func:`meshlab_sharp.detect` are generated with hypothesis: a result or an InputError,
never another exception.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import malformed
import numpy as np
import pytest
import shapes
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import meshlab_sharp

TIMEOUT_S = 60
CASES = malformed.cases(seed=0)
GROUPS = sorted({c.name.split("-")[0] for c in CASES})


def _run(
    case: malformed.Case, folder: Path, *options: str, message: str | None = None
) -> str | None:
    """Run the CLI on the case's file (with ``options``); a description of what went
    wrong (with ``message``: also when the error line does not hold it), or None."""
    path = folder / f"{case.name}{case.suffix}"
    path.write_bytes(case.data)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "meshlab_sharp", "detect", str(path), "-q", *options]
    cmd += ["-o", str(folder / f"{case.name}_out.ply"), "--force"]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S, env=env)
    except subprocess.TimeoutExpired:
        return f"{case.name}: no answer within {TIMEOUT_S} s"
    lines = proc.stderr.splitlines()
    problems = []
    if proc.returncode < 0:
        problems.append(f"killed by signal {-proc.returncode}")
    elif proc.returncode not in (0, 1):
        problems.append(f"exit {proc.returncode}")
    if proc.returncode == 1 and (
        len(lines) != 1 or not lines[0].startswith("meshlab-sharp: error: ")
    ):
        problems.append("not one 'meshlab-sharp: error:' line")
    if proc.returncode == 0 and lines:
        problems.append("output on stderr")
    wanted = {"ok": 0, "error": 1}.get(case.expect, proc.returncode)
    if proc.returncode != wanted:
        problems.append(f"expected exit {wanted}")
    if hashlib.sha256(path.read_bytes()).digest() != hashlib.sha256(case.data).digest():
        problems.append("input modified")
    if message is not None and message not in proc.stderr:
        problems.append(f"the error does not say {message!r}")
    if proc.returncode != 0 and (folder / f"{case.name}_out.ply").exists():
        problems.append("output written")
    if not problems:
        return None
    return f"{case.name}: exit {proc.returncode}, {'; '.join(problems)}: {proc.stderr[-300:]!r}"


@pytest.mark.slow
@pytest.mark.parametrize("group", GROUPS)
def test_malformed_files_through_the_cli(tmp_path, group):
    """Each case in its own process; two at a time (CI has two cores)."""
    group_cases = [c for c in CASES if c.name.split("-")[0] == group]
    with ThreadPoolExecutor(max_workers=2) as pool:
        failures = [r for r in pool.map(lambda c: _run(c, tmp_path), group_cases) if r]
    assert not failures, "\n".join(failures)


SCANNER_CASES = list(malformed.scanner_cases())
#: What the one-line error of each scanner case says.
SCANNER_ERRORS = {
    "las-zero-points": "no points",
    "las-truncated-mid-points": "truncated: the header announces",
    "las-huge-offset": "the offset to the points (4294967280) is outside the file",
    "las-huge-vlr-count": "4294967295 variable-length records",
    "las-scale-inf": "scale or offset of the header is zero or not finite",
    "las-scale-overflow": "non-finite coordinate",
    "las-no-signature": "no LASF signature",
    "laz-truncated": "cannot read the LAS/LAZ file: ",
    "laz-garbled-chunk": "cannot read the LAS/LAZ file: ",
    "e57-crc-page-error": "cannot read the E57 file: checksum mismatch",
    "name-not-utf8-e57": "the file name is not valid UTF-8",
    "off-size-5000-digits": "is not an integer",
    "off-size-5000-digits-walk": "(5000 digits) corners, more than the 1000",
    "off-face-2000-corners": "a face with 2000 corners, more than the 1000",
    "obj-face-100000-corners": "line 100002: a face with 100000 corners, more than the 1000",
}


#: Each scanner case in memory, and out of core where it is a point cloud.
SCANNER_RUNS = [(case, "in memory") for case in SCANNER_CASES] + [
    (case, "tiled")
    for case in SCANNER_CASES
    if case.suffix[-4:] in (".las", ".laz", ".e57", ".xyz")
]


@pytest.mark.parametrize(
    "case, route", SCANNER_RUNS, ids=[f"{route}-{case.name}" for case, route in SCANNER_RUNS]
)
def test_scanner_files_and_bounds_through_the_cli(tmp_path, case, route):
    """laspy's, lazrs' and pye57's failures, non-UTF-8 names and faces beyond the
    corner limit: exit 0 or one line naming the problem, in memory and out of core."""
    options = ("--max-memory", "300MB") if route == "tiled" else ()
    assert _run(case, tmp_path, *options, message=SCANNER_ERRORS.get(case.name)) is None


@pytest.mark.filterwarnings("error")
def test_mutated_files_load_or_raise_input_error(tmp_path):
    """Many more random mutations, read in-process (the readers are numpy only): a
    Geometry or an InputError, never another exception, never a warning."""
    rng = np.random.default_rng(5)
    inserts = [*malformed.BAD_TOKENS, *malformed.ODD_NUMBERS, b"\n", b"\r", b"\t", b"#", b"/"]
    for key, (suffix, data) in malformed.VALID.items():
        for k in range(40):
            b = bytearray(data)
            at = int(rng.integers(len(b)))
            if k % 4 == 0:
                b[at] = int(rng.integers(256))
            elif k % 4 == 1:
                del b[at:]
            elif k % 4 == 2:
                b[at:at] = inserts[int(rng.integers(len(inserts)))]
            else:
                del b[at : at + int(rng.integers(1, 40))]
            path = tmp_path / f"{key}-{k}{suffix}"
            path.write_bytes(bytes(b))
            with contextlib.suppress(meshlab_sharp.InputError):
                meshlab_sharp.load(path)


def test_generator_covers_every_format():
    suffixes = {c.suffix for c in CASES}
    assert suffixes == {".ply", ".obj", ".off", ".stl", ".xyz", ".pts", ".asc", ".txt"}
    assert {c.expect for c in CASES} == {"ok", "error", "either"}
    assert [c.data for c in malformed.cases(seed=0)] == [c.data for c in CASES]  # seeded
    assert 100 <= len(CASES) <= 200


# ---------------------------------------------------------------- the API, with hypothesis

_FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, 1e-300, -1e-300, 1e300, 5e-324, 1.0, -1.0]),
)
_DTYPES = st.sampled_from(
    [np.float64, np.float32, np.float16, np.int8, np.int64, np.uint16, np.bool_, np.complex128]
)
_SCALES = st.one_of(
    st.none(),
    st.lists(st.integers(-5, 60), max_size=5),
    st.lists(st.sampled_from([2.5, "8", None, 10**20, np.int64(12), True]), min_size=1, max_size=3),
    st.integers(-3, 40),
    st.just("12"),
)
_FUZZ = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def _detect_or_input_error(*args, **kwargs) -> str:
    """Run detect: "result" or "InputError"; any other exception fails the test."""
    try:
        result = meshlab_sharp.detect(*args, **kwargs)
    except meshlab_sharp.InputError:
        return "InputError"
    n = len(result.mask)
    assert result.mask.dtype == bool
    assert result.n_features == int(result.mask.sum()) <= n
    return "result"


@_FUZZ
@given(
    points=hnp.arrays(
        _DTYPES,
        st.tuples(st.integers(0, 70), st.integers(0, 4)),
        elements=None,
    ),
    scales=_SCALES,
)
def test_any_array_gives_a_result_or_an_input_error(points, scales):
    event(_detect_or_input_error(points, scales=scales))


@st.composite
def _degenerate_clouds(draw):
    """Clouds with structure: duplicates, lines, planes, scaled by tiny or huge units."""
    n = draw(st.integers(30, 160))
    kind = draw(st.sampled_from(["random", "line", "plane", "duplicates", "identical"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    p = rng.random((n, 3))
    if kind == "line":
        p = np.outer(p[:, 0], rng.random(3))
    elif kind == "plane":
        p[:, 2] = 0.0
    elif kind == "duplicates":
        p = np.repeat(p[: max(n // 4, 1)], 4, axis=0)
    elif kind == "identical":
        p[:] = p[0]
    scale = draw(st.sampled_from([1.0, 1e-120, 1e-30, 1e30, 1e120]))
    return p * scale + draw(st.sampled_from([0.0, 1e6, -1e12]))


@_FUZZ
@given(
    points=_degenerate_clouds(),
    scales=st.one_of(st.none(), st.lists(st.integers(2, 30), min_size=1, max_size=3)),
)
def test_degenerate_clouds_give_a_result_or_an_input_error(points, scales):
    event(_detect_or_input_error(points, scales=scales))


@_FUZZ
@given(
    faces=hnp.arrays(
        np.int64,
        st.tuples(st.integers(0, 30), st.sampled_from([3, 3, 3, 2, 4])),
        elements=st.integers(0, 97),  # the mesh has 98 vertices
    ),
    bad=st.sampled_from([None, None, -1, 98, 2**40]),
    dtype=st.sampled_from([np.int64, np.int32, np.uint8, np.float64]),
    weighting=st.sampled_from(["gaussian", "none", "gaussian", "cubic"]),
    mode=st.sampled_from(["paper", "robust", "paper", "fast"]),
)
def test_any_faces_and_options_give_a_result_or_an_input_error(faces, bad, dtype, weighting, mode):
    vertices, _ = shapes.cube_grid_mesh(2)
    if bad is not None and faces.size:
        faces.flat[0] = bad
    event(_detect_or_input_error(vertices, faces.astype(dtype), weighting=weighting, mode=mode))


@pytest.mark.parametrize(
    "name, vertices, faces",
    list(malformed.hostile_geometries()),
    ids=lambda x: x if isinstance(x, str) else "",
)
def test_hostile_geometry_gives_a_result_or_an_input_error(name, vertices, faces):
    _detect_or_input_error(vertices, faces)


def test_geometry_cannot_be_built_invalid():
    vertices = np.eye(3)
    for faces in ([[0, 1, -1]], [[0, 1, 3]], [[0, 1]], [[0.0, 1.0, 2.0]]):
        with pytest.raises(meshlab_sharp.InputError):
            meshlab_sharp.Geometry(vertices, np.array(faces), "direct")
    with pytest.raises(meshlab_sharp.InputError, match="non-finite"):
        meshlab_sharp.Geometry(np.array([[0.0, np.nan, 0.0]]), None, "direct")
    with pytest.raises(meshlab_sharp.InputError, match="face indices"):
        meshlab_sharp.detect(vertices, np.array([[0, 1, -1]]))
