"""The native library's detection sequence through its C ABI (``ms_detect``,
``ms_parse_scales``: what the MeshLab plugin calls), without MeshLab: ``native/src``
built with gcc and g++ alone into a small driver (``tests/sharp_core_driver.cpp``),
against the Python-driven path of :func:`meshlab_sharp.detect` (``return_details=True``)
on the same float64 arrays: the same scales, thresholds, candidate counts, features and
strengths. Runs wherever g++ is (no MeshLab sources, no Qt)."""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import shapes

import meshlab_sharp
from evaluation import groundtruth
from meshlab_sharp import _header, _kernels
from meshlab_sharp.cleaning import clean
from meshlab_sharp.cli import parse_scales
from meshlab_sharp.errors import InputError
from meshlab_sharp.io.geometry import Geometry
from meshlab_sharp.options import MIN_KNN_SCALE
from meshlab_sharp.reference import detect as reference_sequence
from meshlab_sharp.sample import sample_part

ROOT = Path(__file__).resolve().parent.parent
DRIVER = Path(__file__).resolve().parent / "sharp_core_driver.cpp"
NATIVE = ROOT / "native"

pytestmark = [
    pytest.mark.slow,  # compiles and runs a C++ driver of the library
    pytest.mark.skipif(shutil.which("g++") is None, reason="needs g++"),
]


@pytest.fixture(scope="module")
def driver(tmp_path_factory) -> Path:
    """The driver, compiled with the flags native/CMakeLists.txt gives each file."""
    out = tmp_path_factory.mktemp("core")
    include = NATIVE / "include"
    flags = ["-O3", "-ffp-contract=off", "-fno-math-errno", "-DMS_LIBMVEC=1", "-fPIC"]
    objects = []
    for source in sorted((NATIVE / "src").glob("*.c")):
        objects.append(out / f"{source.stem}.o")
        command = ["gcc", "-c", "-std=c99", *flags, f"-I{include}", source, "-o", objects[-1]]
        subprocess.run(command, check=True)
    cxx = ["g++", "-O3", "-std=c++14", "-ffp-contract=off", "-fno-math-errno", "-Wall", "-Werror"]
    cxx += ["-Wno-unused-parameter", "-fPIC", f"-I{include}"]
    for source in sorted((NATIVE / "src").glob("*.cpp")):
        objects.append(out / f"{source.stem}.o")
        subprocess.run([*cxx, "-c", source, "-o", objects[-1]], check=True)
    exe = out / "driver"
    command = [*cxx, DRIVER, *objects, "-o", exe, "-lmvec", "-lm", "-pthread"]
    subprocess.run(command, check=True)
    return exe


def run_core(
    driver: Path,
    tmp: Path,
    vertices: np.ndarray,
    faces: np.ndarray | None,
    *,
    mode: str,
    knn: str = "12 16 20 24 28 32 36 40",
    rings: str = "1 2 3 4",
    weighting: str = "gaussian",
    as_points: bool = False,
) -> tuple[dict[str, list[float]], np.ndarray, np.ndarray]:
    """The core's summary lines (scales, thresholds, candidates, progress), strengths
    (n,) float64 and features (n,) bool; raises InputError with the core's message."""
    f = np.zeros((0, 3), np.int32) if faces is None else np.asarray(faces, np.int32)
    v = np.ascontiguousarray(vertices, np.float64)
    src, out = tmp / "in.bin", tmp / "out.bin"
    header = np.array([len(v), len(f)], np.int64).tobytes()
    src.write_bytes(header + v.tobytes() + np.ascontiguousarray(f).tobytes())
    args = [driver, src, out, mode, knn, rings, weighting, "1" if as_points else "0"]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=300, check=False)
    if proc.returncode == 2:
        raise InputError(proc.stderr.removeprefix("error: ").strip())
    assert proc.returncode == 0, proc.stderr
    lines = {}
    for line in proc.stdout.splitlines():
        name, *values = line.split()
        lines[name] = [float(x) for x in values]
    data = out.read_bytes()
    n = len(v)
    strength = np.frombuffer(data[: 8 * n], np.float64)
    return lines, strength, np.frombuffer(data[8 * n :], np.uint8).astype(bool)


def _with_outliers(points: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(21)
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = 0.2 * np.linalg.norm(hi - lo)
    return np.concatenate([points, rng.uniform(lo - pad, hi + pad, (len(points) // 100, 3))])


def _case(name: str) -> tuple[np.ndarray, np.ndarray | None, dict[str, object]]:
    if name == "cube-points":
        return shapes.cube_grid_points(15), None, {}
    if name == "sample-points":
        return sample_part("points", n_points=6000).vertices, None, {}
    if name == "sample-mesh":
        part = sample_part("mesh")
        return part.vertices, part.faces, {}
    if name == "sample-mesh-as-points":
        part = sample_part("mesh")
        return part.vertices, part.faces, {"as_points": True}
    if name == "box-cylinder-unweighted":
        return shapes.box_cylinder_points(4000, seed=3), None, {"weighting": "none"}
    if name == "box-other-scales":
        return shapes.random_box_points(3000, seed=8), None, {"scales": (8, 14, 20, 26, 32)}
    if name == "outliers":
        return _with_outliers(sample_part("points", n_points=6000).vertices), None, {}
    if name == "noise50":  # robust mode grows the scales
        s = groundtruth.make_condition("fandisk", "noise50", n_points=6000)
        return s.vertices, None, {}
    if name == "star-prism":  # acute tips join the candidates (reference.robust.acute_tips)
        s = groundtruth.make_condition("star_prism", "clean", n_points=6000)
        return s.vertices, None, {}
    if name == "fandisk-mesh":
        v, f, _ = groundtruth.reference_surface("fandisk")
        return v, f, {}
    if name == "fold-mesh-shuffled":  # 80,601 vertices: the ring pass renumbers them
        v, f, _ = shapes.fold_mesh(90.0, m=200)
        return (*shapes.shuffled_mesh(v, f, seed=6), {})
    if name == "fold-mesh-grid-numbered":  # the ring pass takes most searches from the last
        v, f, _ = shapes.fold_mesh(60.0, m=60)
        return (*shapes.noisy_mesh(v, f, 0.05, seed=4), {})
    if name == "box-far-point":  # dropped before the unit is chosen
        return np.vstack([shapes.random_box_points(3000), [[1e300, -1e300, 1e300]]]), None, {}
    if name == "cube-mesh-half-reversed":  # the features whatever the faces' winding
        v, f = shapes.cube_grid_mesh(3)
        turned = np.random.default_rng(5).random(len(f)) < 0.5
        f = f.copy()
        f[turned] = f[turned][:, ::-1]
        return v, f, {}
    if name == "shuffled-grid":  # double and triple smallest eigenvalues
        axes = np.meshgrid(*[np.arange(12.0)] * 3, indexing="ij")
        grid = np.stack(axes, -1).reshape(-1, 3)
        return grid[np.random.default_rng(0).permutation(len(grid))], None, {}
    if name == "cube-mesh-rings-1-6":
        v, f = shapes.cube_grid_mesh(3)
        return v, f, {"scales": (1, 2, 3, 4, 5, 6)}
    raise AssertionError(name)


CASES = [
    "cube-points",
    "sample-points",
    "sample-mesh",
    "sample-mesh-as-points",
    "box-cylinder-unweighted",
    "box-other-scales",
    "outliers",
    "noise50",
    "star-prism",
    "fandisk-mesh",
    "cube-mesh-rings-1-6",
    "box-far-point",
    "cube-mesh-half-reversed",
    "shuffled-grid",
    "fold-mesh-shuffled",
    "fold-mesh-grid-numbered",
]


@pytest.mark.parametrize("mode", ["paper", "robust"])
@pytest.mark.parametrize("case", CASES)
def test_the_library_agrees_with_python(driver, tmp_path, case, mode):
    vertices, faces, options = _case(case)
    scales = options.get("scales")
    mesh = faces is not None and not options.get("as_points", False)
    text = " ".join(map(str, scales)) if scales else None
    lines, strength, feature = run_core(
        driver,
        tmp_path,
        vertices,
        faces,
        mode=mode,
        knn=text if text and not mesh else "12 16 20 24 28 32 36 40",
        rings=text if text and mesh else "1 2 3 4",
        weighting=str(options.get("weighting", "gaussian")),
        as_points=bool(options.get("as_points", False)),
    )
    expected = reference_sequence.detect(
        vertices,
        faces,
        mode=mode,
        scales=scales,
        weighting=options.get("weighting", "gaussian"),
        as_points=bool(options.get("as_points", False)),
    )
    assert tuple(int(s) for s in lines["scales"]) == expected.scales
    np.testing.assert_array_equal(lines["thresholds"], expected.thresholds)
    np.testing.assert_array_equal(lines["candidates"], expected.candidate_counts)
    assert int((feature != expected.mask).sum()) == 0, "points differ"
    np.testing.assert_array_equal(strength, expected.strength)
    assert expected.n_features > 0
    if case == "noise50" and mode == "robust":
        assert expected.scales[0] > 12


def test_the_grid_numbered_case_takes_the_shifted_search():
    """The agreement case above where the kernel's ring pass takes a vertex's search from
    the previous vertex's (ms_shifted_lists), which the library's sequence asks for too."""
    vertices, faces, _ = _case("fold-mesh-grid-numbered")
    cleaned = clean(Geometry(vertices, faces, "fold"))
    shifted = _kernels.shifted_lists(*_kernels.adjacency(cleaned.faces, len(cleaned.vertices)))
    assert shifted.mean() > 0.9


def test_the_progress_bar_moves(driver, tmp_path):
    """The callback is called per chunk of points, from 0 to 100, never backwards."""
    points = shapes.random_box_points(200000, seed=1)  # 25 chunks
    lines, _, _ = run_core(driver, tmp_path, points, None, mode="robust")
    progress = lines["progress"]
    assert progress[0] == 0 and progress[-1] == 100
    assert np.all(np.diff(progress) >= 0)
    assert len(set(progress)) >= 10


@pytest.mark.parametrize(
    ("vertices", "message"),
    [
        (np.zeros((0, 3)), "no vertices"),
        (np.tile([[1.0, 2.0, 3.0]], (60, 1)), "identical"),
        (shapes.cube_grid_points(9)[:25], "fewer than the largest scale"),
        (np.array([[0.0, 0.0, np.nan]] * 50), "non-finite"),
    ],
)
def test_bad_input_is_refused_with_a_message(driver, tmp_path, vertices, message):
    with pytest.raises(InputError, match=message):
        run_core(driver, tmp_path, vertices, None, mode="robust")


def test_the_constants_are_the_headers():
    """Python's names take the header's values (a few spot checks of the parsed numbers);
    the plugin's example script lists the header's default scales (a .mlx names every
    parameter, so it cannot take them from the header)."""
    from meshlab_sharp import creases, multiscale, robust, threshold

    c = _header.CONSTANTS
    assert multiscale.DEFAULT_KNN_SCALES == (12, 16, 20, 24, 28, 32, 36, 40)
    assert (threshold.BINS, creases.NOISE_FACTOR) == (256, 4.0 / 0.3186)
    assert robust.R_MIN == 0.11054786333836651  # from CREASE_ANGLE = 20.0
    for name in (
        "NOISE_KNN",
        "NOISE_QUIET",
        "NOISE_TOLERATED",
        "SUPPORT_FREE_SCORE",
        "ACUTE_SCORE",
        "ACUTE_SCORE_MAX",
        "NOISE_MAX_FACTOR",
        "THIN_CONE_COS",
    ):
        assert getattr(robust, name) == c[name]
    script = (ROOT / "meshlab_plugin_cpp" / "examples" / "sharp_features_default.mlx").read_text()
    for name in ("knnScales", "ringScales"):
        found = re.search(rf'value="([^"]*)" name="{name}"', script)
        assert found, name
        key = "DEFAULT_KNN_SCALES" if name == "knnScales" else "DEFAULT_RING_SCALES"
        assert tuple(map(int, found.group(1).split())) == c[key]


def test_the_option_lists_are_the_headers():
    """The default mode and weighting, the smallest scales and the most scales are the
    header's in Python (known values) and in the plugin's filter (its enums take the
    header's default index, and list the same names in the same order as Python); the
    example scripts name the same enums and defaults (a .mlx names every parameter)."""
    from meshlab_sharp import defaults as chosen
    from meshlab_sharp import options

    assert (chosen.DEFAULT_MODE, chosen.DEFAULT_WEIGHTING) == ("robust", "gaussian")
    assert (options.MIN_KNN_SCALE, options.MIN_RING_SCALE, chosen.MAX_SCALES) == (2, 1, 64)
    assert meshlab_sharp.DetectionResult.mode == chosen.DEFAULT_MODE
    lists = {"mode": chosen.MODES, "weighting": chosen.WEIGHTINGS}
    defaults = {"mode": chosen.DEFAULT_MODE, "weighting": chosen.DEFAULT_WEIGHTING}
    glue = (ROOT / "meshlab_plugin_cpp" / "src" / "filter_sharp_features.cpp").read_text()
    for name, names in lists.items():
        enum = re.search(rf'RichEnum\("{name}", (\w+), QStringList\(\)((?: << "\w+")+)', glue)
        assert enum, name
        assert enum.group(1) == f"MS_DEFAULT_{name.upper()}"
        assert tuple(re.findall(r'"(\w+)"', enum.group(2).lower())) == names
    for scales, low in (("knnScales", "MS_MIN_KNN_SCALE"), ("ringScales", "MS_MIN_RING_SCALE")):
        assert re.search(rf'readScales\(par, "{scales}", {low}, [^)]*\)', glue), scales
    for script in (ROOT / "meshlab_plugin_cpp" / "examples").glob("*.mlx"):
        text = script.read_text()
        for name, names in lists.items():
            param = re.search(rf'<Param type="RichEnum" value="(\d)" name="{name}"[^>]*>', text)
            assert param, (script.name, name)
            labels = re.findall(r'enum_val\d="(\w+)"', param.group(0))
            assert tuple(x.lower() for x in labels) == names, script.name
            assert names[int(param.group(1))] == defaults[name], script.name


@pytest.mark.parametrize(
    ("knn", "message"),
    [
        ("2:66", "invalid scales '2:66': 65 scales, more than 64"),
        ("2:2000000000", "invalid scales '2:2000000000': 1999999999 scales, more than 64"),
        (" ".join(["12"] * 65), "65 scales, more than 64"),
        ("1 12", "scales must be >= 2, got 1"),
    ],
)
def test_the_library_refuses_the_scales_python_refuses(driver, tmp_path, knn, message):
    """At most MAX_SCALES scales (a range is refused before it is built), k at least
    MIN_KNN_SCALE: the command line's limits and messages."""
    points = shapes.cube_grid_points(9)
    with pytest.raises(InputError, match=re.escape(message)):
        run_core(driver, tmp_path, points, None, mode="robust", knn=knn)


def test_the_header_parser_reads_only_its_forms():
    assert _header.parse("#define MS_A (1.0 / 4.0)\n#define MS_B {1, 2}\n#define MS_C 7\n") == {
        "A": 0.25,
        "B": (1, 2),
        "C": 7,
    }
    with pytest.raises(ValueError, match="unsupported constant"):
        _header.parse("#define MS_A sqrt(2.0)\n")
    with pytest.raises(TypeError, match="MS_BINS is 256, not float"):
        _header.real("BINS")


SCALE_TEXTS = [
    "12 16 20",
    "20,12, 16",
    " 8\t12  16 ",
    "12:40:4",
    "10:30:10",
    "4:4",
    "+12 16",
    "16 16 12",
    "8 12,16",
    "8,,12",
    "8,",
    "",
    " ",
    "12;16",
    "1_2 16",
    "12.0 16",
    "4:2",
    "1:2:0",
    "1:2:3:4",
    "2:66",
    "99999999999 12",
    "1 12",
]


@pytest.mark.parametrize("text", SCALE_TEXTS)
def test_the_library_reads_scales_as_the_command_line_does(driver, tmp_path, text):
    """One grammar for the scales: the library's ``ms_parse_scales`` accepts what
    ``meshlab_sharp.cli.parse_scales`` accepts, giving the same sorted distinct scales,
    and refuses the rest with the same message."""
    points = shapes.cube_grid_points(9)
    try:
        expected: list[float] | str = [float(s) for s in sorted(set(parse_scales(text)))]
    except argparse.ArgumentTypeError as error:
        expected = str(error)
    if isinstance(expected, list) and expected[0] < MIN_KNN_SCALE:
        expected = f"scales must be >= {MIN_KNN_SCALE}, got {int(expected[0])}"
    try:
        got: list[float] | str = run_core(driver, tmp_path, points, None, mode="paper", knn=text)[
            0
        ]["scales"]
    except InputError as error:
        got = str(error)
    assert got == expected
