"""The faces' winding does not change the features: only the line of a normal counts.

STL and OBJ exports often wind some faces the other way round. The crease test compares
the normals of an edge's two faces as if both were wound alike (they go opposite ways
along a shared edge), and the face-average normals sum each face's normal turned to
agree with its neighbours' (:func:`meshlab_sharp.creases.face_windings`).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from shapes import cube_grid_mesh, fold_mesh

from meshlab_sharp import _kernels, detect
from meshlab_sharp.creases import dihedral_angles, face_windings, sharp_vertices
from meshlab_sharp.errors import InputWarning
from meshlab_sharp.normals import face_average_normals

BACKENDS = ["numpy", "compiled"] if _kernels.available() else ["numpy"]


def _reversed(faces: np.ndarray, fraction: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The faces with a random ``fraction`` of them wound the other way round, and which."""
    turned = np.random.default_rng(seed).random(len(faces)) < fraction
    out = faces.copy()
    out[turned] = out[turned][:, ::-1]
    return out, turned


def _moebius(m: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A Moebius strip: m quads (2 m triangles) around a circle, the strip's last column
    joined to its first one upside down."""
    t = np.arange(m) * 2 * np.pi / m
    rows = []
    for s in (-0.3, 0.3):
        r = 1 + s * np.cos(t / 2)
        rows.append(np.c_[r * np.cos(t), r * np.sin(t), s * np.sin(t / 2)])
    vertices = np.concatenate(rows)  # vertex i (lower edge), m + i (upper edge)
    faces = []
    for i in range(m):
        a, b, c, d = i, m + i, (i + 1) % m, m + (i + 1) % m
        if i == m - 1:
            c, d = d, c  # the half twist
        faces += [(a, c, b), (b, c, d)]
    return vertices, np.array(faces, np.int64)


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["robust", "paper"])
def test_same_features_whatever_the_winding(mode: str) -> None:
    vertices, faces = cube_grid_mesh(8)
    expected = detect(vertices, faces, mode=mode)
    assert expected.n_features == 764
    for backend in BACKENDS:
        for fraction in (0.01, 0.1, 0.5):
            turned = _reversed(faces, fraction)[0]
            with warnings.catch_warnings():
                warnings.simplefilter("error", InputWarning)
                got = detect(vertices, turned, mode=mode, backend=backend)
            where = f"{backend}, {fraction:.0%} reversed"
            np.testing.assert_array_equal(got.mask, expected.mask, err_msg=where)
            np.testing.assert_array_equal(got.strength, expected.strength)


@pytest.mark.parametrize("backend", BACKENDS)
def test_windings_turn_exactly_the_reversed_faces(backend: str) -> None:
    vertices, faces = cube_grid_mesh(3)
    turned_faces, turned = _reversed(faces, 0.3)
    flip, unoriented = face_windings(turned_faces, len(vertices), backend=backend)
    assert unoriented == 0
    # one closed part: the lowest face keeps its winding, every other face agrees with it
    np.testing.assert_array_equal(flip, turned != turned[0])
    assert not face_windings(faces, len(vertices), backend=backend)[0].any()


@pytest.mark.parametrize("backend", BACKENDS)
def test_sharp_fold_beyond_90_degrees_stays_sharp(backend: str) -> None:
    # turning by 120 degrees: the two faces' normals point more than 90 degrees apart
    vertices, faces, crease = fold_mesh(120.0)
    expected, threshold = sharp_vertices(vertices, faces, backend=backend)
    np.testing.assert_array_equal(expected, crease)
    edges, angles = dihedral_angles(vertices, faces, backend=backend)
    for seed in range(3):
        turned = _reversed(faces, 0.5, seed)[0]
        mask, got_threshold = sharp_vertices(vertices, turned, backend=backend)
        np.testing.assert_array_equal(mask, crease)
        assert got_threshold == threshold
        got_edges, got_angles = dihedral_angles(vertices, turned, backend=backend)
        np.testing.assert_array_equal(got_edges, edges)
        np.testing.assert_allclose(got_angles, angles, rtol=0, atol=1e-12)
        assert np.isclose(got_angles.max(), np.radians(120.0))


@pytest.mark.parametrize("backend", BACKENDS)
def test_face_average_normals_keep_their_line(backend: str) -> None:
    vertices, faces = cube_grid_mesh(3)
    expected = face_average_normals(vertices, faces, backend=backend)
    turned = _reversed(faces, 0.5)[0]
    got = face_average_normals(vertices, turned, backend=backend)
    # the whole mesh's normals turned at once when the lowest face was reversed
    sign = -1.0 if not np.array_equal(turned[0], faces[0]) else 1.0
    np.testing.assert_array_equal(got, sign * expected)


def test_compiled_windings_and_normals_equal_numpy() -> None:
    if not _kernels.available():
        pytest.skip("compiled kernels not built")
    vertices, faces = cube_grid_mesh(3)
    meshes = [(vertices, _reversed(faces, 0.4, 7)[0]), _moebius()]
    # two parts: the second a copy of the first, shifted, some of its faces reversed
    two = np.concatenate([faces, _reversed(faces, 0.5, 3)[0] + len(vertices)])
    meshes.append((np.concatenate([vertices, vertices + 5.0]), two))
    for v, f in meshes:
        ref = face_windings(f, len(v), backend="numpy")
        fast = face_windings(f, len(v), backend="compiled")
        np.testing.assert_array_equal(fast[0], ref[0])
        assert fast[1] == ref[1]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InputWarning)
            a = face_average_normals(v, f, backend="numpy")
            b = face_average_normals(v, f, backend="compiled")
        assert np.array_equal(a, b)  # bit for bit


@pytest.mark.parametrize("backend", BACKENDS)
def test_non_orientable_part_is_left_as_wound_with_a_warning(backend: str) -> None:
    vertices, faces = _moebius()
    flip, unoriented = face_windings(faces, len(vertices), backend=backend)
    assert unoriented == len(faces)
    assert not flip.any()
    with pytest.warns(InputWarning, match=f"^{len(faces)} faces lie in parts with no consistent"):
        face_average_normals(vertices, faces, backend=backend)
