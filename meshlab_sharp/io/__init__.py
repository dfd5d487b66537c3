"""Input and output: the Geometry type, guarded readers, atomic writers."""

from ..outputs import OutputSet, atomic_write
from .curves import CURVE_FORMATS, check_curves_path, curve_arrays, require_ezdxf, save_curves
from .geometry import (
    Geometry,
    as_geometry,
    mesh_arrays,
    tag_input_indices,
    tagged_input_indices,
)
from .quiet import quiet_stdout
from .readers import POINT_LIST_EXTENSIONS, load
from .writers import (
    add_vertex_attribute,
    feature_colors,
    feature_meshset,
    save_features_ply,
    save_indices,
    save_json,
    select_vertices,
)

__all__ = [
    "CURVE_FORMATS",
    "POINT_LIST_EXTENSIONS",
    "Geometry",
    "OutputSet",
    "add_vertex_attribute",
    "as_geometry",
    "atomic_write",
    "check_curves_path",
    "curve_arrays",
    "feature_colors",
    "feature_meshset",
    "load",
    "mesh_arrays",
    "quiet_stdout",
    "require_ezdxf",
    "save_curves",
    "save_features_ply",
    "save_indices",
    "save_json",
    "select_vertices",
    "tag_input_indices",
    "tagged_input_indices",
]
