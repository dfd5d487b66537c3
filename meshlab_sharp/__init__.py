"""meshlab-sharp: automatic sharp feature extraction from 3D points and meshes.

The projected-distance method of Tran et al. (2014): per point, the distance between
the point and its neighbourhood's centroid along the normal; Otsu's threshold on its
histogram; at several scales; a point is a feature if it is a candidate at every scale.

>>> import meshlab_sharp
>>> result = meshlab_sharp.detect("part.ply")          # doctest: +SKIP
>>> result.mask, result.strength, result.thresholds      # doctest: +SKIP

The public names are imported on first use, so that the command line answers
``--version``, ``--help`` and option errors without loading numpy, scipy or pymeshlab.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the public functions and classes, for type checkers and the API reference
    from .errors import InputError, MeshlabSharpError  # noqa: F401
    from .io import Geometry, load, save_features_ply  # noqa: F401
    from .meshset import detect_meshset  # noqa: F401
    from .pipeline import detect  # noqa: F401
    from .preprocessing import Preprocessing, PreprocessingReport, preprocess  # noqa: F401
    from .result import DetectionResult  # noqa: F401

__version__ = "0.1.0"

#: Public name -> the submodule that defines it.
_EXPORTS = {
    "DEFAULT_KNN_SCALES": "defaults",
    "DEFAULT_MODE": "defaults",
    "DEFAULT_RING_SCALES": "defaults",
    "MODES": "defaults",
    "DetectionResult": "result",
    "Geometry": "io",
    "InputError": "errors",
    "MeshlabSharpError": "errors",
    "Preprocessing": "preprocessing",
    "PreprocessingReport": "preprocessing",
    "detect": "pipeline",
    "detect_meshset": "meshset",
    "load": "io",
    "preprocess": "preprocessing",
    "save_features_ply": "io",
}

__all__ = sorted([*_EXPORTS, "__version__"])


def __getattr__(name: str) -> Any:
    """Import a public name's submodule on first use (PEP 562)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'meshlab_sharp' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The module's names, the lazily imported public ones included."""
    return sorted({*globals(), *_EXPORTS})
