"""Feature curves of meshes along the mesh's own sharp edges: known answers on coarse and
fine tessellations (a cube down to 2 triangles a face, an STL-like cylinder, a box with
rounded edges), independence of the faces' winding, and the native library's chains the
same as the numpy reference's to the bit."""

from __future__ import annotations

import numpy as np
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp.curves import _native
from meshlab_sharp.reference import curves as reference
from meshlab_sharp.reference.curves.mesh import crease_chains

CUBE_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)


def _cube(case: str) -> tuple[np.ndarray, np.ndarray]:
    """The cube [-1, 1]^3: 2 triangles a face, or midpoint-subdivided."""
    if case == "two-triangles":
        return shapes.two_triangle_cube()
    return shapes.cube_grid_mesh(int(case.split("-")[1]))


def _mesh(case: str) -> tuple[np.ndarray, np.ndarray]:
    """Small meshes with sharp edges, coarse and fine."""
    if case == "cylinder-24":
        return shapes.prism_mesh(shapes.polygon(24), 2.0)
    if case == "rounded-box":
        return shapes.prism_mesh(shapes.rounded_rectangle(3.0, 2.0, 0.5), 1.0)
    if case == "noisy-shuffled-cube":
        return shapes.shuffled_mesh(*shapes.noisy_mesh(*shapes.cube_grid_mesh(4), 0.05))
    return _cube(case)


def _edges(faces: np.ndarray) -> set[tuple[int, int]]:
    return {
        tuple(sorted(map(int, e)))
        for f in faces
        for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))
    }


@pytest.mark.parametrize("case", ["two-triangles", "subdivided-1", "subdivided-2", "subdivided-4"])
def test_a_cube_gives_its_12_edges_and_8_corners_at_every_tessellation(case):
    """Each curve is one edge of the cube, corner to corner along the mesh's edges, kept
    however few mesh edges it has (one on the 2-triangle cube, where it is a single
    sharp mesh edge and the diagonals across the faces are flat); 8 corners, exactly the
    cube's."""
    vertices, faces = _cube(case)
    result = meshlab_sharp.detect(vertices, faces, curves=True)
    assert len(result.curves) == 12 and len(result.corners) == 8
    edges = _edges(faces)
    per_edge = 2 ** int(case.split("-")[1]) if case != "two-triangles" else 1
    for c in result.curves:
        assert c.kind == "line" and not c.closed
        assert len(c.points) == per_edge + 1
        assert abs(c.length - 2.0) < 1e-12
        np.testing.assert_array_equal(c.points, vertices[c.indices])
        assert all(
            tuple(sorted((int(c.indices[a]), int(c.indices[b])))) in edges for a, b in c.segments
        )
        # along the cube's edge: two coordinates at +-1 at every vertex
        assert np.all(np.sum(np.abs(np.abs(c.points) - 1) == 0, axis=1) >= 2)
        ends = {tuple(c.points[0]), tuple(c.points[-1])}
        assert ends <= {tuple(p) for p in CUBE_CORNERS}
    assert sorted(map(tuple, result.corners.points)) == sorted(map(tuple, CUBE_CORNERS))


def test_an_stl_like_cylinder_gives_its_two_rims_only():
    """24 facets (15 degrees apart: below the crease angle, no curve between them), caps
    fanned from one rim vertex (long thin triangles, flat): two closed circles, one per
    rim, through the rims' 24 vertices; no seam, no facet edge, no corner."""
    vertices, faces = shapes.prism_mesh(shapes.polygon(24), 2.0)
    result = meshlab_sharp.detect(vertices, faces, curves=True)
    assert len(result.curves) == 2 and len(result.corners) == 0
    heights = []
    for c in result.curves:
        assert c.closed and c.kind == "arc" and len(c.points) == 24
        assert np.ptp(c.points[:, 2]) == 0.0
        heights.append(c.points[0, 2])
        assert abs(c.params["radius"] - 1.0) < 0.02
    assert sorted(heights) == [0.0, 2.0]


def test_a_box_with_rounded_edges_gives_no_curve_on_the_rounds():
    """A box whose four vertical edges are rounded (STL-like: 6 facets a quarter turn,
    7.5 and 15 degrees apart): the two outlines of the flat caps, closed, and nothing on
    the rounds; no corner (the outlines turn smoothly)."""
    vertices, faces = shapes.prism_mesh(shapes.rounded_rectangle(3.0, 2.0, 0.5), 1.0)
    result = meshlab_sharp.detect(vertices, faces, curves=True)
    assert len(result.curves) == 2 and len(result.corners) == 0
    for c in result.curves:
        assert c.closed and len(c.points) == len(vertices) // 2
        assert np.ptp(c.points[:, 2]) == 0.0  # on a cap's plane, never down a round


def test_the_curves_do_not_depend_on_the_faces_winding():
    """Faces wound the other way round (some of them, or all): the same curves."""
    vertices, faces = shapes.two_triangle_cube()
    want = reference.extract_curves(vertices, np.ones(len(vertices), bool), faces)
    turned = faces.copy()
    turned[::3] = turned[::3, ::-1]
    for f in (turned, faces[:, ::-1]):
        got = reference.extract_curves(vertices, np.ones(len(vertices), bool), f)
        assert [c[1].tolist() for c in got.curves] == [c[1].tolist() for c in want.curves]
        assert got.corner_points.tobytes() == want.corner_points.tobytes()


def test_a_crease_the_detection_saw_is_chained_through_the_vertices_it_left_out():
    """The sharp edges are chained where the detection saw a crease (a sharp edge between
    two features), also through the vertices on it that it left out: with one corner of
    the 2-triangle cube no feature, still 12 curves and 8 corners; with no two features
    on one sharp edge, no chain, and the features are the skeleton's."""
    vertices, faces = shapes.two_triangle_cube()
    mask = np.ones(len(vertices), bool)
    mask[0] = False
    chains = crease_chains(vertices, faces, mask, mask)
    assert len(chains.pieces) == 12 and chains.corners.tolist() == list(range(8))
    assert all(len(pc.nodes) == 2 for pc in chains.pieces)
    assert not chains.rest.any()  # every feature is on a sharp edge
    mask = np.zeros(len(vertices), bool)
    mask[[0, 7]] = True  # opposite corners
    chains = crease_chains(vertices, faces, mask, mask)
    assert chains.pieces == [] and len(chains.corners) == 0
    np.testing.assert_array_equal(chains.rest, mask)


@pytest.mark.parametrize(
    "case",
    [
        "two-triangles",
        "subdivided-1",
        "subdivided-4",
        "cylinder-24",
        "rounded-box",
        "noisy-shuffled-cube",
    ],
)
def test_mesh_sharp_edge_curves_are_the_references_to_the_bit(case):
    """The native library's chains of sharp edges, with the skeleton of the features
    away from them: the numpy reference's curves, lengths and corners to the bit, for
    the features of either mode and for every vertex a feature."""
    vertices, faces = _mesh(case)
    robust = meshlab_sharp.detect(vertices, faces)
    paper = meshlab_sharp.detect(vertices, faces, mode="paper")  # fewer of the crease's vertices
    masks = [(robust.mask, robust.kept), (paper.mask, paper.kept)]
    for mask, kept in [*masks, (np.ones(len(vertices), bool), None)]:
        want = reference.extract_curves(vertices, mask, faces, kept)
        got = _native.extract_curves(vertices, mask, faces, kept, None)
        assert want.curves or mask is paper.mask
        assert got.spacing == want.spacing and len(got.curves) == len(want.curves)
        for (p, i, c, length), (wp, wi, wc, wlength) in zip(got.curves, want.curves, strict=True):
            assert p.tobytes() == np.ascontiguousarray(wp).tobytes()
            np.testing.assert_array_equal(i, wi)
            assert (c, np.float64(length).tobytes()) == (wc, np.float64(wlength).tobytes())
        assert got.corner_points.tobytes() == want.corner_points.tobytes()
        np.testing.assert_array_equal(got.corner_indices, want.corner_indices)


def test_a_noisy_mesh_leaves_its_creases_to_the_skeleton():
    """Noise raises the crease threshold (edges beside a crease turn by more than the
    crease angle, one here, one there): no edge is chained alone, every feature goes to
    the skeleton, which still finds the cube's 12 edges and 8 corners."""
    vertices, faces = shapes.noisy_mesh(*shapes.cube_grid_mesh(5), 0.1, seed=1)
    result = meshlab_sharp.detect(vertices, faces, curves=True)
    chains = crease_chains(vertices, faces, result.mask, result.mask)
    assert chains.pieces == [] and len(chains.corners) == 0
    np.testing.assert_array_equal(chains.rest, result.mask)
    assert len(result.curves) == 12 and len(result.corners) == 8
