"""numpy arrays in and out, against analytic geometry."""
import numpy as np
import pytest

import polyspline
from conftest import gmsh_jacobians


def square_grid(n):
    """The unit square as n×n quads, its four sides tagged 1..4 and named."""
    x = np.linspace(0.0, 1.0, n + 1)
    pts = np.array([(xi, yj) for yj in x for xi in x])
    vid = lambda i, j: j * (n + 1) + i  # noqa: E731
    quads = np.array([[vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)]
                      for j in range(n) for i in range(n)])
    facets, tags = [], []
    for i in range(n):
        facets += [[vid(i, 0), vid(i + 1, 0)], [vid(n, i), vid(n, i + 1)],
                   [vid(i + 1, n), vid(i, n)], [vid(0, i + 1), vid(0, i)]]
        tags += [1, 2, 3, 4]
    names = {1: "bottom", 2: "right", 3: "top", 4: "left"}
    return pts, quads, np.array(facets), np.array(tags), names


def cube_grid(n):
    x = np.linspace(0.0, 1.0, n + 1)
    pts = np.array([(a, b, c) for c in x for b in x for a in x])
    v = lambda i, j, k: (k * (n + 1) + j) * (n + 1) + i  # noqa: E731
    hexes = np.array([[v(i, j, k), v(i + 1, j, k), v(i + 1, j + 1, k), v(i, j + 1, k),
                       v(i, j, k + 1), v(i + 1, j, k + 1), v(i + 1, j + 1, k + 1), v(i, j + 1, k + 1)]
                      for k in range(n) for j in range(n) for i in range(n)])
    return pts, hexes


def test_arrays_with_tags_keep_tags_names_and_straight_sides(tmp_path):
    pts, quads, facets, tags, names = square_grid(4)
    c = polyspline.curve((pts, quads, facets, tags, names), order=3, backend="cpu")
    assert c.dim == 2 and c.cells.shape == (16, 16) and c.facets.shape == (16, 4)
    assert sorted(np.bincount(c.facet_tags)[1:]) == [4, 4, 4, 4]
    assert c.tag_names == names
    # Each side stays on its line: the straight boundary is reproduced exactly.
    for tag, (axis, value) in {1: (1, 0.0), 2: (0, 1.0), 3: (1, 1.0), 4: (0, 0.0)}.items():
        nodes = c.points[c.facets[c.facet_tags == tag]]
        np.testing.assert_allclose(nodes[..., axis], value, atol=1e-12)
    path = tmp_path / "square.msh"
    c.write(path)
    n, lo, _, volume = gmsh_jacobians(path)
    assert n == 16 and lo > 0 and volume == pytest.approx(1.0, rel=1e-12)
    assert {"bottom", "right", "top", "left"} <= set(c.to_meshio().field_data)


def test_straight_reproduces_the_bilinear_map():
    pts, quads, *_ = square_grid(3)
    c = polyspline.curve((pts, quads), order=2, straight=True, backend="cpu")
    # Gmsh's quad9: corners, edge midpoints, centre; of an axis-aligned cell: its averages.
    corners = c.points[c.cells[:, :4]]
    np.testing.assert_allclose(c.points[c.cells[:, 8]], corners.mean(axis=1), atol=1e-14)
    for k in range(4):
        mid = (corners[:, k] + corners[:, (k + 1) % 4]) / 2
        np.testing.assert_allclose(c.points[c.cells[:, 4 + k]], mid, atol=1e-14)


def test_hex_arrays_fill_the_cube(tmp_path):
    pts, hexes = cube_grid(3)
    c = polyspline.curve((pts, hexes), order=2, backend="cpu")
    assert c.dim == 3 and c.cells.shape == (27, 27) and len(c.facets) == 54
    assert c.points.min() >= -1e-12 and c.points.max() <= 1 + 1e-12
    path = tmp_path / "cube.msh"
    c.write(path)
    n, lo, _, volume = gmsh_jacobians(path)
    assert n == 27 and lo > 0 and volume == pytest.approx(1.0, rel=1e-12)


def test_vtk_order_is_a_permutation_of_gmsh_order():
    pts, hexes = cube_grid(2)
    c = polyspline.curve((pts, hexes), order=3, backend="cpu")
    vtk_cells, vtk_facets = c.cells_vtk()
    assert vtk_cells.shape == c.cells.shape
    np.testing.assert_array_equal(np.sort(vtk_cells, axis=1), np.sort(c.cells, axis=1))
    np.testing.assert_array_equal(vtk_cells[:, :8], c.cells[:, :8])
    np.testing.assert_array_equal(np.sort(vtk_facets, axis=1), np.sort(c.facets, axis=1))
