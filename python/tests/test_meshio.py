"""meshio meshes in and out: meshio's node conventions, checked by meshio's own Gmsh reader
and by Gmsh."""
import numpy as np
import pytest

import polyspline
from conftest import HEXES, QUADS, cli, gmsh_jacobians, need


@pytest.mark.parametrize("mesh,order", [(QUADS, 2), (QUADS, 4), (HEXES, 2), (HEXES, 3)])
def test_to_meshio_written_by_meshio_is_valid_in_gmsh_with_our_volume(tmp_path, mesh, order):
    meshio = need("meshio")
    curved = polyspline.curve(mesh, order=order, backend="cpu")
    m = curved.to_meshio()
    path = tmp_path / "meshio.msh"
    meshio.write(path, m, file_format="gmsh")
    ours = tmp_path / "ours.msh"
    curved.write(ours)
    n, lo, hi, volume = gmsh_jacobians(path)
    n_ref, _, _, volume_ref = gmsh_jacobians(ours)
    assert n == n_ref == len(curved.cells)
    assert lo > 0, f"meshio's file has min det J {lo}"
    assert volume == pytest.approx(volume_ref, rel=1e-12)


@pytest.mark.parametrize("mesh,order", [(QUADS, 3), (HEXES, 2), (HEXES, 3)])
def test_to_meshio_matches_meshio_reading_the_cli_file(tmp_path, mesh, order):
    meshio = need("meshio")
    msh = tmp_path / "cli.msh"
    status, err = cli("curve", mesh, "-o", msh, "--order", order, "--backend", "cpu")
    assert status == 0, err
    theirs = meshio.read(msh)
    ours = polyspline.curve(mesh, order=order, backend="cpu").to_meshio()
    volume, facet = ours.cells[0].type, ours.cells[1].type
    a, b = ours.get_cells_type(volume), theirs.get_cells_type(volume)
    assert a.shape == b.shape
    # The same elements in the same order, each node where meshio puts it.
    np.testing.assert_array_equal(ours.points[a], theirs.points[b])
    # The file groups the facets by tag: the same facets, node order included.
    key = lambda pts, cells: {tuple(map(tuple, pts[c].round(12))) for c in cells}  # noqa: E731
    assert key(ours.points, ours.get_cells_type(facet)) == key(theirs.points, theirs.get_cells_type(facet))


def test_meshio_mesh_input_gives_the_path_result(tmp_path):
    meshio = need("meshio")
    m = meshio.read(QUADS)
    a = polyspline.curve(m, order=2, backend="cpu")
    b = polyspline.curve(QUADS, order=2, backend="cpu")
    np.testing.assert_array_equal(a.cells, b.cells)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.facet_tags, b.facet_tags)
    assert a.tag_names == b.tag_names


def test_read_gives_meshio_what_meshio_reads(tmp_path):
    meshio = need("meshio")
    ours = polyspline.read(HEXES)
    theirs = meshio.read(HEXES)
    np.testing.assert_array_equal(ours.points, theirs.points)
    np.testing.assert_array_equal(ours.get_cells_type("hexahedron"),
                                  theirs.get_cells_type("hexahedron"))


def test_read_of_a_curved_file_is_the_curved_mesh(tmp_path):
    need("meshio")
    curved = polyspline.curve(HEXES, order=3, backend="cpu")
    path = tmp_path / "c.vtu"
    curved.write(path)
    back = polyspline.read(path)
    cells = back.get_cells_type("hexahedron64")
    assert cells.shape == curved.cells.shape
    np.testing.assert_allclose(back.points[cells], curved.points[curved.cells], rtol=0, atol=1e-12)
