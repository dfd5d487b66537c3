"""meshlab-sharp: automatic sharp feature extraction from 3D points and meshes.

The projected-distance method of Tran et al. (2014): per point, the distance between
the point and its neighbourhood's centroid along the normal; Otsu's threshold on its
histogram; at several scales; a point is a feature if it is a candidate at every scale.

>>> import meshlab_sharp
>>> result = meshlab_sharp.detect("part.ply")          # doctest: +SKIP
>>> result.mask, result.strength, result.thresholds      # doctest: +SKIP
"""

from .errors import InputError, MeshlabSharpError
from .io import Geometry, load, save_features_ply
from .meshset import detect_meshset
from .multiscale import DEFAULT_KNN_SCALES, DEFAULT_RING_SCALES
from .options import DEFAULT_MODE, MODES
from .pipeline import detect
from .preprocessing import Preprocessing, PreprocessingReport, preprocess
from .result import DetectionResult

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
