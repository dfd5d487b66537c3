"""Run the calling script in the project's virtual environment.

``python3 scripts/NAME.py`` then works from a clean checkout: when the interpreter
running it cannot import the package's dependencies (numpy, scipy, pymeshlab), the
script runs again under ``.venv/bin/python``, after ``bash scripts/setup.sh`` has made
``.venv`` where it is missing. An interpreter that has them (an activated or any other
environment) runs the script itself.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
VENV_PYTHON = ROOT / ".venv" / "bin" / "python"
NEEDS = ("numpy", "scipy", "pymeshlab")
#: Set in the re-run, so that a .venv still missing a dependency fails instead of looping.
GUARD = "MESHLAB_SHARP_SCRIPT_VENV"


def enter() -> None:
    """Return when this interpreter has the dependencies; otherwise re-run the script
    (``sys.argv``) under ``.venv/bin/python``, setting ``.venv`` up first if needed."""
    if all(importlib.util.find_spec(name) is not None for name in NEEDS):
        return
    script = Path(sys.argv[0]).name
    if os.environ.get(GUARD):
        missing = [n for n in NEEDS if importlib.util.find_spec(n) is None]
        print(
            f"{script}: error: {', '.join(missing)} missing in {sys.executable}: "
            "run bash scripts/setup.sh",
            file=sys.stderr,
        )
        raise SystemExit(1)
    if not VENV_PYTHON.exists():
        print(f"{script}: setting up .venv (bash scripts/setup.sh)", file=sys.stderr)
        if subprocess.run(["bash", str(ROOT / "scripts" / "setup.sh")], check=False).returncode:
            print(f"{script}: error: bash scripts/setup.sh failed", file=sys.stderr)
            raise SystemExit(1)
    os.environ[GUARD] = "1"
    os.execv(str(VENV_PYTHON), [str(VENV_PYTHON), *sys.argv])
