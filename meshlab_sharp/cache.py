"""The user's cache folder of meshlab-sharp (``$XDG_CACHE_HOME/meshlab-sharp``)."""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """``$XDG_CACHE_HOME/meshlab-sharp``, or ``~/.cache/meshlab-sharp``: the MeshLab
    sources and the plugin's builds, and the built sample parts."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "meshlab-sharp"
