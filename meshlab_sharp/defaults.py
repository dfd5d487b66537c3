"""Option choices and defaults, importable without numpy, scipy or pymeshlab.

The command line builds its parser and checks its options from these before any heavy
module is imported, so ``--version``, ``--help`` and option errors answer at once. The
numbers come from the C kernel's header (:mod:`meshlab_sharp._header`), which the
MeshLab plugin compiles too.
"""

from __future__ import annotations

import signal

from . import _header

#: PCA normal weightings: Gaussian weights ``exp(-d^2/h^2)`` or plain PCA.
WEIGHTINGS: tuple[str, ...] = ("gaussian", "none")
#: The weighting ``detect``, the CLI and the MeshLab plugin use unless told otherwise.
DEFAULT_WEIGHTING = WEIGHTINGS[_header.integer("DEFAULT_WEIGHTING")]
#: Detection modes: the paper's method as ALGORITHM.md reads it, or robust mode
#: (:mod:`meshlab_sharp.robust`, docs/method.md).
MODES: tuple[str, ...] = ("paper", "robust")
#: The mode ``detect``, the CLI and the MeshLab plugin use unless told otherwise.
DEFAULT_MODE = MODES[_header.integer("DEFAULT_MODE")]
#: The most scales one detection takes (the defaults have 8 and 4).
MAX_SCALES = _header.integer("MAX_SCALES")
#: The largest scales, checked before any work: rings (a k-ring's neighbourhoods grow
#: with k squared: ring 32 of a 25,000-vertex mesh takes about 20 s) ...
MAX_RING_SCALE = _header.integer("MAX_RING_SCALE")
#: ... and k nearest neighbours (lists of k neighbours per point and scale).
MAX_KNN_SCALE = _header.integer("MAX_KNN_SCALE")
#: Default scales of a point cloud: k nearest neighbours.
DEFAULT_KNN_SCALES: tuple[int, ...] = _header.integers("DEFAULT_KNN_SCALES")
#: Default scales of a mesh: k-rings.
DEFAULT_RING_SCALES: tuple[int, ...] = _header.integers("DEFAULT_RING_SCALES")
#: Denoising methods: ``auto`` picks ``taubin`` for meshes and ``rimls`` for clouds.
DENOISE_METHODS: tuple[str, ...] = ("auto", "taubin", "two_steps", "rimls", "apss")
#: Most mesh smoothing iterations (``smoothing_steps``; each is a pass over the mesh).
MAX_SMOOTHING_STEPS = 1000
#: Signals held back while an output set creates a temporary file or renames its files.
HELD_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM, signal.SIGHUP})
