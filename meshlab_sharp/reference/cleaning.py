"""Cleaning, the reference: pymeshlab's own filters, as ALGORITHM.md asks for them.

``meshing_remove_duplicate_vertices`` merges exact duplicates into their first
occurrence; on a mesh ``meshing_remove_null_faces`` and
``meshing_remove_unreferenced_vertices`` then drop the zero-area faces and the vertices
no face uses. The filters compact and renumber the mesh without saying where each
vertex came from, so every vertex carries its input index through them in a custom
attribute (:func:`meshlab_sharp.io.tag_input_indices`). The compiled cleaning
(:func:`meshlab_sharp.cleaning.clean`) keeps the same vertices and faces.
"""

from __future__ import annotations

import numpy as np
import pymeshlab

from ..errors import InputError
from ..io import Geometry, mesh_arrays, tag_input_indices, tagged_input_indices


def clean(geometry: Geometry) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
    """Merge exact duplicates, drop zero-area faces and unreferenced vertices.

    Parameters
    ----------
    geometry : Geometry
        Validated input: ``vertices`` (n, 3) float64, ``faces`` (f, 3) int64 or None.

    Returns
    -------
    vertices : (m, 3) float64
        The cleaned vertices, in the input's relative order.
    faces : (g, 3) int64 or None
        The cleaned triangles (indices into ``vertices``); None for a cloud.
    to_input : (m,) int64
        The input index of each cleaned vertex (increasing).
    from_input : (n,) int64
        The cleaned index of each input vertex (its survivor's), -1 where dropped.

    Raises
    ------
    InputError
        A mesh all of whose faces have zero area.
    """
    v = geometry.vertices
    ms = pymeshlab.MeshSet()
    if geometry.is_mesh:
        mesh = pymeshlab.Mesh(vertex_matrix=v, face_matrix=geometry.faces.astype(np.int32))
    else:
        mesh = pymeshlab.Mesh(vertex_matrix=v)
    tag_input_indices(mesh)
    ms.add_mesh(mesh)
    ms.meshing_remove_duplicate_vertices()
    if geometry.is_mesh:
        ms.meshing_remove_null_faces()
        ms.meshing_remove_unreferenced_vertices()
    to_input = tagged_input_indices(ms, len(v))
    _, faces = mesh_arrays(ms)
    del ms
    if geometry.is_mesh and faces is None:
        raise InputError(
            f"{geometry.source}: every face has zero area; nothing is left of the mesh "
            "(use --as-points to treat its vertices as a point cloud)"
        )

    # Input vertex -> its first occurrence (pymeshlab keeps the first of equal vertices).
    _, first, group = np.unique(v, axis=0, return_index=True, return_inverse=True)
    survivor = first[group.reshape(-1)]
    cleaned_of_input = np.full(len(v), -1, dtype=np.int64)
    cleaned_of_input[to_input] = np.arange(len(to_input))
    from_input = cleaned_of_input[survivor]
    if not np.all(np.diff(to_input) > 0) or np.any(
        from_input[to_input] != np.arange(len(to_input))
    ):
        raise RuntimeError("internal error: pymeshlab reordered vertices while cleaning")
    return v[to_input], faces, to_input, from_input
