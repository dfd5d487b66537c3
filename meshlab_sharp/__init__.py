"""meshlab-sharp: automatic sharp feature extraction from 3D points and meshes.

The projected-distance method of Tran et al. (2014): per point, the distance between
the point and its neighbourhood's centroid along the normal; Otsu's threshold on its
histogram; at several scales; a point is a feature if it is a candidate at every scale.

>>> import meshlab_sharp
>>> result = meshlab_sharp.detect("part.ply")          # doctest: +SKIP
>>> result.mask, result.strength, result.thresholds      # doctest: +SKIP
"""

from __future__ import annotations

import importlib

from .errors import InputError, MeshlabSharpError

TYPE_CHECKING = False  # typing itself takes a while to import
if TYPE_CHECKING:
    from typing import Any

    from .io import Geometry, load, save_features_ply
    from .meshset import detect_meshset
    from .multiscale import DEFAULT_KNN_SCALES, DEFAULT_RING_SCALES
    from .pipeline import DEFAULT_MODE, MODES, DetectionResult, detect
    from .preprocessing import Preprocessing, PreprocessingReport, preprocess

#: Where each public name is defined. They are imported on first use, so that the
#: command line (``python -m meshlab_sharp``) sets its signal handlers before numpy,
#: scipy and pymeshlab load.
_LAZY = {
    "Geometry": "io",
    "load": "io",
    "save_features_ply": "io",
    "detect_meshset": "meshset",
    "DEFAULT_KNN_SCALES": "multiscale",
    "DEFAULT_RING_SCALES": "multiscale",
    "DEFAULT_MODE": "pipeline",
    "MODES": "pipeline",
    "DetectionResult": "pipeline",
    "detect": "pipeline",
    "Preprocessing": "preprocessing",
    "PreprocessingReport": "preprocessing",
    "preprocess": "preprocessing",
}


def __getattr__(name: str) -> Any:
    """A public name or a submodule, imported on first use."""
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    try:
        return importlib.import_module(f".{name}", __name__)
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None


__version__ = "0.1.0"

__all__ = [
    "DEFAULT_KNN_SCALES",
    "DEFAULT_MODE",
    "DEFAULT_RING_SCALES",
    "MODES",
    "DetectionResult",
    "Geometry",
    "InputError",
    "MeshlabSharpError",
    "Preprocessing",
    "PreprocessingReport",
    "__version__",
    "detect",
    "detect_meshset",
    "load",
    "preprocess",
    "save_features_ply",
]
