"""Hostile but finite geometry: degenerate inputs that a detector must survive.

Every case is NaN-free and well formed as a file, but degenerate as geometry: too few
points, all points identical, on a line or a plane, far outliers, zero-area and
repeated-vertex faces, non-manifold fans. Each maps a name to ``(vertices, faces)``
with vertices (n, 3) float64 and faces (m, 3) int64 or None. Used by the fuzz tests of
the Python package and of the MeshLab plugin.
"""

from __future__ import annotations

import numpy as np
import shapes


def _line(n: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)
    return np.stack([t, 2.0 * t, -t], axis=1)


def _fan(n_blades: int) -> tuple[np.ndarray, np.ndarray]:
    """n_blades triangles sharing one edge (a non-manifold edge of valence n_blades)."""
    angles = np.linspace(0.0, 2.0 * np.pi, n_blades, endpoint=False)
    tips = np.stack([np.cos(angles), np.sin(angles), np.full(n_blades, 0.5)], axis=1)
    vertices = np.concatenate([[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]], tips])
    faces = np.array([[0, 1, 2 + b] for b in range(n_blades)], dtype=np.int64)
    return vertices, faces


def hostile_geometries() -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    """The hostile cases, by name: ``{name: (vertices (n, 3), faces (m, 3) or None)}``."""
    cube = shapes.cube_grid_points(9)
    cube_v, cube_f = shapes.cube_grid_mesh(2)
    rng = np.random.default_rng(5)
    cluster = rng.normal(size=(300, 3))
    fan_v, fan_f = _fan(12)
    return {
        "one-point": (np.array([[1.0, 2.0, 3.0]]), None),
        "three-points": (np.eye(3), None),
        "identical-points": (np.tile([[1.0, -2.0, 0.5]], (64, 1)), None),
        "collinear-points": (_line(200), None),
        "coplanar-points": (shapes.flat_square(15) @ shapes.random_rotation(2).T, None),
        "fewer-points-than-k": (cube[:30], None),
        "duplicates-x5": (np.repeat(cube, 5, axis=0), None),
        "far-outlier": (np.concatenate([cube, [[1e12, -1e12, 1e12]]]), None),
        "two-far-clusters": (np.concatenate([cluster, cluster + 1e9]), None),
        "tiny-coordinates": (cube * 1e-30, None),
        "huge-coordinates": (cube * 1e30, None),
        "single-triangle": (np.eye(3), np.array([[0, 1, 2]])),
        "zero-area-faces": (_line(5), np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4]])),
        "repeated-vertex-faces": (cube_v, np.concatenate([cube_f, [[0, 0, 1], [2, 2, 2]]])),
        "non-manifold-fan": (fan_v, fan_f),
        "mesh-with-isolated-vertices": (
            np.concatenate([cube_v, rng.normal(size=(40, 3)) * 5.0]),
            cube_f,
        ),
        "flat-mesh": (
            np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float),
            np.array([[0, 1, 2], [1, 3, 2]]),
        ),
    }
