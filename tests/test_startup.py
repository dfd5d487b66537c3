"""Fast start: ``--version``, ``--help``, option and output errors answer before numpy,
scipy or pymeshlab is imported (an import budget, not a timing)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

#: Modules that take most of the start-up time; none may be imported to answer.
HEAVY = ("numpy", "scipy", "pymeshlab", "matplotlib", "laspy")

_PROBE = """
import json, sys
from meshlab_sharp.cli import main
try:
    status = main(sys.argv[1:])
except SystemExit as exc:
    status = exc.code
heavy = sorted(m for m in {heavy!r} if m in sys.modules)
print(json.dumps([status, heavy]), file=sys.stderr)
"""


def _answer(args: list[str], cwd: Path) -> tuple[int, list[str], str]:
    """Exit status, the heavy modules imported, and stderr's other lines."""
    proc = subprocess.run(
        [sys.executable, "-c", _PROBE.format(heavy=HEAVY), *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=60,
        check=False,
    )
    *lines, last = proc.stderr.splitlines()
    status, heavy = json.loads(last)
    return status, heavy, "\n".join(lines)


@pytest.mark.parametrize(
    ("args", "status", "message"),
    [
        (["--version"], 0, ""),
        (["--help"], 0, ""),
        (["detect", "--help"], 0, ""),
        (["plugin", "--help"], 0, ""),
        (["detect", "c.ply"], 1, "meshlab-sharp: error: c_sharp.ply exists; use --force"),
        (["detect", "c.ply", "--mode", "fast"], 1, "argument --mode: invalid choice"),
        (["detect", "c.ply", "-o", "c.obj"], 1, "the output must be a .ply, .las or .laz"),
        (["detect", "c.ply", "--indices", "a", "--indices", "b"], 1, "--indices given twice"),
        (["detect", "--denoise", "c.ply"], 1, "looks like a file"),
        (["detect", "c.ply", "--scales", "1:"], 1, "invalid scales"),
        (["detect", "c.ply", "-o", "missing/x.ply"], 1, "the folder missing does not exist"),
    ],
)
def test_answers_without_heavy_imports(tmp_path, args, status, message):
    (tmp_path / "c.ply").write_text("ply\n")
    (tmp_path / "c_sharp.ply").write_text("old\n")
    got, heavy, err = _answer(args, tmp_path)
    assert (got, heavy) == (status, [])
    assert message in err
    if status:
        assert err.startswith("meshlab-sharp: error:") and err.count("\n") == 0


def test_the_library_still_imports_its_names_on_use():
    import meshlab_sharp

    assert callable(meshlab_sharp.detect) and meshlab_sharp.MODES == ("paper", "robust")
    assert set(meshlab_sharp.__all__) <= set(dir(meshlab_sharp))
    from meshlab_sharp.result import DetectionResult

    assert meshlab_sharp.DetectionResult is DetectionResult
    assert all(getattr(meshlab_sharp, name) is not None for name in meshlab_sharp.__all__)
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        _ = meshlab_sharp.nothing


@pytest.mark.slow
def test_preprocessing_option_errors_need_no_scipy_or_pymeshlab(tmp_path):
    """Their checks live with the parameters (numpy only)."""
    (tmp_path / "c.ply").write_text("ply\n")
    for flags, message in (
        (["--simplify", "2"], "--simplify must be a finite number in (0, 1]"),
        (["--remove-outliers", "--outlier-neighbours", "1"], "--outlier-neighbours must be >= 2"),
    ):
        status, heavy, err = _answer(["detect", "c.ply", *flags], tmp_path)
        assert (status, heavy) == (1, ["numpy"])
        assert err.startswith(f"meshlab-sharp: error: {message}") and err.count("\n") == 0
