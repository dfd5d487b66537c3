"""Cleaning as ALGORITHM.md requires, and the maps back to the input.

Exact duplicate vertices are merged into their first occurrence; for meshes, zero-area
faces and then unreferenced vertices are dropped: with the compiled kernels (a hash of
the coordinates, vcg's zero-area test) or with pymeshlab's filters, the reference
(:mod:`meshlab_sharp.reference.cleaning`), the same survivors and faces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _kernels
from .errors import InputError
from .io import Geometry
from .reference import cleaning as reference


@dataclass(frozen=True)
class CleanGeometry:
    """Cleaned geometry and its maps to and from the input's vertex order.

    Attributes
    ----------
    vertices : (m, 3) float64
        Cleaned vertices, in the input's relative order (unless ``renumbered``).
    faces : (f, 3) int64 or None
        Cleaned triangles indexing ``vertices``; None for a point cloud.
    maps : (to_input (m,) int64, from_input (n,) int64) or None
        The maps below; None when they are the identity (cleaning merged, dropped and
        renumbered nothing): then they are made only when read, and ``detect`` reads
        neither (16 bytes a point of a 1M cloud's peak).
    to_input : (m,) int64
        Input index of each cleaned vertex (its first occurrence).
    from_input : (n,) int64
        Cleaned index of each input vertex; -1 for a vertex that was dropped.
    renumbered : bool
        True when cleaning renumbered the vertices for locality (``clean(...,
        local_order=True)``; ``to_input`` is then not increasing); False: cleaning kept
        the input's relative order.
    adjacency : (indptr (m + 1,) int64, indices int32) or None
        The faces' :func:`meshlab_sharp._kernels.adjacency` when the renumbering made it
        (the lists it was made from, renumbered: the same lists) and no face or vertex
        was dropped after it; else None.
    """

    vertices: np.ndarray
    faces: np.ndarray | None
    maps: tuple[np.ndarray, np.ndarray] | None
    renumbered: bool = False
    adjacency: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def with_maps(
        cls,
        vertices: np.ndarray,
        faces: np.ndarray | None,
        to_input: np.ndarray,
        from_input: np.ndarray,
        *,
        renumbered: bool = False,
        adjacency: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> CleanGeometry:
        """The cleaned geometry with its maps, kept only where they are not the identity
        (as many cleaned vertices as input ones, none renumbered: cleaning keeps the
        order)."""
        identity = len(to_input) == len(from_input) and not renumbered
        maps = None if identity else (to_input, from_input)
        return cls(vertices, faces, maps, renumbered=renumbered, adjacency=adjacency)

    @property
    def to_input(self) -> np.ndarray:
        """(m,) int64: the input index of each cleaned vertex."""
        return np.arange(len(self.vertices)) if self.maps is None else self.maps[0]

    @property
    def from_input(self) -> np.ndarray:
        """(n,) int64: the cleaned index of each input vertex, -1 where dropped."""
        return np.arange(len(self.vertices)) if self.maps is None else self.maps[1]

    @property
    def is_mesh(self) -> bool:
        """True when faces remain."""
        return self.faces is not None

    def to_input_order(self, values: np.ndarray, fill: float | bool) -> np.ndarray:
        """Scatter per-cleaned-vertex ``values`` (m, ...) to input order (n, ...).

        Input vertices merged into a duplicate take its value; dropped ones get ``fill``.
        When the maps are the identity (``maps`` None: cleaning merged, dropped and
        renumbered nothing), ``values`` itself, not a copy (a cloud's three outputs
        gathered through the identity took 9 ms at 1M points).
        """
        if self.maps is None:
            return values
        from_input = self.maps[1]
        if len(from_input) and from_input.min() >= 0:
            return values[from_input]  # none dropped: one gather (a third faster)
        out = np.full((len(from_input), *values.shape[1:]), fill, dtype=values.dtype)
        kept = from_input >= 0
        out[kept] = values[from_input[kept]]
        return out


def clean(
    geometry: Geometry,
    *,
    backend: str | None = None,
    workers: int = 1,
    local_order: bool = False,
) -> CleanGeometry:
    """Merge exact duplicates, drop zero-area faces and unreferenced vertices.

    Parameters
    ----------
    geometry : Geometry
        Validated input (finite coordinates, valid face indices).
    backend : {"compiled", "numpy"}, optional
        "numpy": pymeshlab's filters (:func:`meshlab_sharp.reference.cleaning.clean`);
        "compiled": a hash of the
        coordinates in C and vcg's zero-area test, same survivors, same faces.
        Default: :func:`meshlab_sharp._kernels.default_backend`.
    workers : int, default 1
        Threads of the compiled backend's face pass (-1: every core; its duplicate
        merge runs on one); the result does not depend on it.
    local_order : bool, default False
        Compiled backend: a mesh whose vertex order is scattered
        (:func:`meshlab_sharp._kernels.scattered_faces`) is renumbered breadth-first
        (:func:`meshlab_sharp._kernels.bfs_renumber`) before its faces are tested, its
        faces and their corners kept in order; every per-vertex list and sum of
        detection then meets the same faces and neighbours in the same order, so its
        outputs, mapped back through ``to_input_order``, are the same bit for bit.

    Returns
    -------
    CleanGeometry

    Raises
    ------
    InputError
        A mesh all of whose faces have zero area.
    """
    if _kernels.resolve(backend) == "compiled":
        return _clean_compiled(geometry, workers, local_order)
    return CleanGeometry.with_maps(*reference.clean(geometry))


def _clean_compiled(geometry: Geometry, workers: int, local_order: bool) -> CleanGeometry:
    """:func:`clean` without pymeshlab: what its filters do, as vcg does it.

    ``meshing_remove_duplicate_vertices`` keeps the first of equal vertices (``==`` on
    each coordinate) and the order of the others; ``meshing_remove_null_faces`` drops
    faces with ``DoubleArea <= 0`` (a face using a merged vertex twice is one);
    ``meshing_remove_unreferenced_vertices`` then compacts, keeping the order.
    ``local_order``: the renumbering between the merge and the faces' test.
    """
    to_input, from_input, merged = _kernels.merge_duplicates(geometry.vertices)
    if not geometry.is_mesh:
        return CleanGeometry.with_maps(merged, None, to_input, from_input)
    distinct = len(to_input) == len(from_input)
    faces, remap = geometry.faces, None if distinct else from_input
    n, m = len(merged), len(faces)
    new = None
    if local_order and n < 2**31 and _kernels.scattered_faces(faces, n, remap):
        # Renumbered breadth-first (faces and corners in the same order): the faces' test
        # and every step of detection after it read nearby memory, where a scattered
        # order (a scanned or remeshed input's) misses the caches at every read.
        if remap is not None:
            faces, remap = remap[faces], None
        new = _kernels.bfs_renumber(_kernels.adjacency(faces, n), merged)
        rank = new.rank.astype(np.int64)
        faces, merged = rank[faces], new.points
        to_input, from_input = to_input[new.order], rank[from_input]
    faces, used = _kernels.keep_faces(merged, faces, remap, workers)
    if len(faces) == 0:
        raise InputError(
            f"{geometry.source}: every face has zero area; nothing is left of the mesh "
            "(use --as-points to treat its vertices as a point cloud)"
        )
    if used.all():
        renumber = None
    else:
        renumber = np.cumsum(used) - 1
        faces = renumber[faces]
        merged = merged[used]
        to_input = to_input[used]
        from_input = np.where(used[from_input], renumber[from_input], -1)
    return CleanGeometry.with_maps(
        merged,
        faces,
        to_input,
        from_input,
        renumbered=new is not None,
        # the lists are the faces' own when the test dropped no face and no vertex
        adjacency=None if new is None or renumber is not None or len(faces) < m else new.adjacency,
    )
