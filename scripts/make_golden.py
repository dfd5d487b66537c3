#!/usr/bin/env python3
"""Write the golden outputs of ``detect`` (robust and paper mode) that
``tests/test_golden.py`` compares with: ``tests/data/golden/<shape>.json``.

Run after a deliberate change of either mode's answers, and commit the files with it:

    python3 scripts/make_golden.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import _venv  # scripts/, the script's own folder, is on sys.path

_venv.enter()

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import golden  # noqa: E402


def _dump(data: dict) -> str:
    """JSON with one line per key and the lists inline (short, readable diffs)."""
    parts = []
    for key, value in data.items():
        if isinstance(value, dict):
            inner = ",\n".join(f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in value.items())
            parts.append(f" {json.dumps(key)}: {{\n{inner}\n }}")
        else:
            parts.append(f" {json.dumps(key)}: {json.dumps(value)}")
    return "{\n" + ",\n".join(parts) + "\n}\n"


def main() -> None:
    """Write one JSON file per shape of :data:`golden.SHAPES`."""
    golden.FOLDER.mkdir(parents=True, exist_ok=True)
    for name, make in golden.SHAPES.items():
        data = golden.record(*make())
        golden.path(name).write_text(_dump(data))
        print(name, {mode: len(data[mode]["indices"]) for mode in golden.MODES})


if __name__ == "__main__":
    main()
