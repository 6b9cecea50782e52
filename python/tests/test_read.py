"""`polyspline.read` on every input format, against meshio's own readers where meshio reads
the format, and against the command line's `info` counts otherwise."""
import json
import subprocess

import numpy as np
import pytest

import polyspline
from conftest import MESHES, cli_path, need

REAL = MESHES / "real"
# (file, meshio reads it): Gmsh MSH, Medit, legacy VTK, SU2, Abaqus, Exodus, CGNS/HDF5, MFEM.
FILES = [
    (REAL / "dealii" / "example.msh", True),
    (REAL / "sfepy" / "acoustics_mesh3d.mesh", True),
    (REAL / "sfepy" / "hsphere8.vtk", True),
    (REAL / "su2-testcases" / "cylinder.su2", True),
    # meshio 5.3's Abaqus reader fails on this file's node sets (KeyError on a node id).
    (REAL / "trixi-juliacon2024-naca4412" / "NACA4412_2_2D_unique.inp", False),
    (REAL / "libmesh" / "systems_of_equations_ex9.exo", False),
    (MESHES / "converted" / "example_dealii.cgns", False),
    (REAL / "mfem" / "cylinder-hex.mesh", False),
]


def volume(mesh):
    kinds = [c.type for c in mesh.cells]
    kind = "hexahedron" if "hexahedron" in kinds else "quad"
    return kind, np.concatenate([c.data for c in mesh.cells if c.type == kind])


@pytest.mark.parametrize("path,by_meshio", FILES, ids=lambda v: getattr(v, "name", str(v)))
def test_read_every_format(path, by_meshio):
    meshio = need("meshio")
    ours = polyspline.read(path)
    kind, cells = volume(ours)
    if by_meshio:
        theirs = meshio.read(path)
        kind_t, cells_t = volume(theirs)
        assert kind == kind_t and cells.shape == cells_t.shape
        # The same elements with the same corner coordinates, in the same order.
        np.testing.assert_allclose(ours.points[cells][..., :2], theirs.points[cells_t][..., :2],
                                   rtol=0, atol=1e-12)
    run = subprocess.run([str(cli_path()), "info", str(path), "--json"], capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stderr
    info = json.loads(run.stdout)
    assert len(cells) == info["elements"]
    assert len(np.unique(cells)) == info["vertices"]


@pytest.mark.parametrize("path", [FILES[0][0], FILES[5][0], FILES[6][0]], ids=lambda p: p.name)
def test_read_arrays_is_the_meshio_mesh_without_meshio(path):
    need("meshio")
    m = polyspline.read(path)
    a = polyspline.read(path, arrays=True)
    np.testing.assert_array_equal(a["points"], m.points)
    for kind, cells in a["cells"].items():
        np.testing.assert_array_equal(cells, m.get_cells_type(kind))
        assert len(a["cell_tags"][kind]) == len(cells)


def test_read_arrays_of_a_curved_file(tmp_path):
    curved = polyspline.curve(MESHES / "generated" / "block_hex8_8.msh", order=3, backend="cpu")
    path = tmp_path / "c.msh"
    curved.write(path)
    a = polyspline.read(path, arrays=True)
    cells = a["cells"]["hexahedron64"]
    assert cells.shape == curved.cells.shape
    np.testing.assert_array_equal(a["points"][cells], curved.points[curved.cells])
    assert len(a["cells"]["quad16"]) == len(curved.facets)
