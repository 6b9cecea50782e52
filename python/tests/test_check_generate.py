"""`check` and `generate` from Python: the command line's reports and files, checked against
Gmsh's own Jacobian bounds and meshio's reading of the command line's files."""
import json
import subprocess

import numpy as np
import pytest

import polyspline
from conftest import HEXES, QUADS, cli, cli_error, cli_path, gmsh_open, need


def cli_json(*args):
    run = subprocess.run([str(cli_path()), *map(str, args)], capture_output=True, text=True)
    return run.returncode, json.loads(run.stdout)


def gmsh_min_det_jac(path):
    """Gmsh's minDetJac per volume element (its Bezier bound of det J), in file order."""
    with gmsh_open(path) as (gmsh, dim):
        _, tags, _ = gmsh.model.mesh.getElements(dim)
        return np.asarray(gmsh.model.mesh.getElementQualities(tags[0], "minDetJac"))


def inverted(curved, element):
    """`curved` as a meshio mesh with the interior node of `element` thrown past its first
    corner: that element folds, no other one moves (the node is its own)."""
    m = curved.to_meshio()
    cells = curved.cells
    centre = cells[element, -1]
    assert np.sum(cells == centre) == 1
    corner = curved.points[cells[element, 0]]
    m.points[centre] = corner + 3.0 * (corner - curved.points[centre])
    return m


@pytest.mark.parametrize("mesh,order", [(QUADS, 3), (HEXES, 2)])
def test_check_is_the_cli_check_json(tmp_path, mesh, order):
    curved = polyspline.curve(mesh, order=order, backend="cpu")
    path = tmp_path / "c.msh"
    curved.write(path)
    status, theirs = cli_json("check", path, "--json")
    assert status == 0
    assert polyspline.check(path) == theirs
    assert curved.check() == theirs
    assert theirs["invalid"] == 0 and theirs["elements"] == len(curved.cells)


@pytest.mark.parametrize("mesh,order", [(QUADS, 2), (HEXES, 2)])
def test_check_agrees_with_gmsh_min_det_jac(tmp_path, mesh, order):
    meshio = need("meshio")
    curved = polyspline.curve(mesh, order=order, backend="cpu")
    good = tmp_path / "good.msh"
    curved.write(good)
    assert np.all(gmsh_min_det_jac(good) > 0)
    assert polyspline.check(good)["invalid"] == 0
    element = len(curved.cells) // 2
    bad = inverted(curved, element)
    path = tmp_path / "bad.msh"
    meshio.write(path, bad, file_format="gmsh")
    gmsh = gmsh_min_det_jac(path)
    report = polyspline.check(path)
    assert list(np.flatnonzero(gmsh <= 0)) == [element]
    assert report["invalid"] == 1 and report["worst_element"] == element
    assert report["min_det_jacobian"] < 0
    # The meshio mesh itself, and the command line's exit status 3.
    assert polyspline.check(bad) == report
    status, theirs = cli_json("check", path, "--json")
    assert status == 3 and theirs == report
    with pytest.raises(polyspline.ValidityError, match="1 element"):
        polyspline.check(bad, strict=True)


def test_check_errors_are_the_cli_errors(tmp_path):
    missing = tmp_path / "missing.msh"
    with pytest.raises(polyspline.InputError) as e:
        polyspline.check(missing)
    assert str(e.value) == cli_error("check", missing)
    with pytest.raises(TypeError):
        polyspline.check(42)


GENERATE = [
    ("disc", {"elements": 300}),
    ("cylinder", {"elements": 400}),
    ("torus", {"elements": 300}),
    ("ogrid", {"around": 32, "across": 12, "wall": "circle"}),
    ("cgrid", {"around": 32, "across": 10, "wake": 8, "layers": 2, "span": 0.5}),
    ("channel", {"around": 16, "across": 8, "first_height": 0.02, "bump": 0.15}),
    ("sector", {"around": 8, "across": 8, "first_height": 0.02, "sector": 40, "layers": 2}),
]


def cli_args(options):
    out = []
    for k, v in options.items():
        out += ["--" + k.replace("_", "-"), str(v)]
    return out


@pytest.mark.parametrize("kind,options", GENERATE)
def test_generate_is_the_cli_file_and_counts(tmp_path, kind, options):
    meshio = need("meshio")
    theirs = tmp_path / "cli.msh"
    status, err = cli("generate", kind, "-o", theirs, *cli_args(options))
    assert status == 0, err
    ours = tmp_path / "py.msh"
    mesh = polyspline.generate(kind, output=ours, **options)
    assert ours.read_bytes() == theirs.read_bytes()
    # The counts against meshio's reading of the command line's file.
    m = meshio.read(theirs)
    volume, facet = ("hexahedron", "quad") if mesh.dim == 3 else ("quad", "line")
    assert len(m.get_cells_type(volume)) == len(mesh.cells) == mesh.info["elements"]
    assert len(m.get_cells_type(facet)) == len(mesh.facets) == mesh.info["boundary_facets"]
    assert len(np.unique(m.get_cells_type(volume))) == mesh.info["vertices"]
    np.testing.assert_array_equal(m.points[m.get_cells_type(volume)], mesh.points[mesh.cells])
    assert mesh.order == 1 and mesh.check()["invalid"] == 0


def test_generate_validation_is_the_cli(tmp_path):
    out = tmp_path / "o.msh"
    with pytest.raises(polyspline.ParameterError) as e:
        polyspline.generate("disc")
    assert str(e.value) == cli_error("generate", "disc", "-o", out)
    with pytest.raises(polyspline.ParameterError) as e:
        polyspline.generate("ogrid", growth=0.5)
    theirs = cli_error("generate", "ogrid", "-o", out, "--growth", "0.5")
    assert str(e.value) == theirs.replace(str(out), "<generate>")
    with pytest.raises(polyspline.ParameterError) as e:
        polyspline.generate("square")
    assert str(e.value) == cli_error("generate", "square", "-o", out)
    with pytest.raises(TypeError, match="output_file"):
        polyspline.generate("disc", elements=10, output_file=out)


def test_a_generated_mesh_curves_as_its_file(tmp_path):
    path = tmp_path / "disc.msh"
    mesh = polyspline.generate("disc", elements=200, output=path)
    a = polyspline.curve(mesh, order=2, backend="cpu")
    b = polyspline.curve(path, order=2, backend="cpu")
    np.testing.assert_array_equal(a.cells, b.cells)
    np.testing.assert_allclose(a.points, b.points, rtol=0, atol=1e-13)
    assert a.report["min_scaled_jacobian"] == pytest.approx(b.report["min_scaled_jacobian"], abs=1e-12)
