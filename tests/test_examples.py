"""The examples run as they are documented."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from meshlab_sharp.io import load

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def test_pymeshlab_pipeline_example(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(EXAMPLES / "pymeshlab_pipeline.py"), "-o", str(tmp_path),
         "--points", "6000"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "sharp features" in proc.stdout
    scan = load(tmp_path / "scan.ply")
    annotated = load(tmp_path / "scan_annotated.ply")
    features = load(tmp_path / "scan_features.ply")
    # outliers removed by the MeshLab filters (60 were added to 6,000 points)
    assert len(scan.vertices) - 60 <= len(annotated.vertices) < len(scan.vertices)
    assert 0.03 * len(annotated.vertices) < len(features.vertices) < 0.3 * len(annotated.vertices)
