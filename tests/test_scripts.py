"""``python3 scripts/NAME.py`` from a Python without the dependencies runs the script
in the project's ``.venv`` (``scripts/_venv.py``), or fails with one clear line."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
VENV_PYTHON = ROOT / ".venv" / "bin" / "python"


def _bare_python() -> str:
    """The interpreter this environment was made from, when it lacks pymeshlab."""
    base = Path(sys.base_prefix) / "bin" / "python3"
    if not base.exists():
        pytest.skip("no base interpreter")
    probe = "import importlib.util, sys; sys.exit(importlib.util.find_spec('pymeshlab') is None)"
    if subprocess.run([str(base), "-c", probe], check=False).returncode != 1:
        pytest.skip("the base interpreter has pymeshlab")
    if importlib.util.find_spec("pymeshlab") is None:
        pytest.skip("this interpreter lacks pymeshlab")
    return str(base)


def _run(python: str, *args: str, **env: str) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if k != "MESHLAB_SHARP_SCRIPT_VENV"}
    return subprocess.run(
        [python, *args],
        cwd=ROOT,
        env={**clean, **env},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


@pytest.mark.parametrize("script", ["evaluate_cad.py", "evaluate.py", "evaluate_curves.py"])
def test_a_bare_python_runs_the_script_in_the_venv(script):
    if not VENV_PYTHON.exists():
        pytest.skip("no .venv here (the script would set one up)")
    proc = _run(_bare_python(), f"scripts/{script}", "--help")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage:")


def test_a_venv_without_the_dependencies_fails_in_one_line():
    proc = _run(_bare_python(), "scripts/evaluate_cad.py", "--help", MESHLAB_SHARP_SCRIPT_VENV="1")
    assert proc.returncode == 1
    assert proc.stdout == ""
    assert proc.stderr.strip().splitlines() == [
        f"evaluate_cad.py: error: pymeshlab missing in {_bare_python()}: run bash scripts/setup.sh"
    ]
