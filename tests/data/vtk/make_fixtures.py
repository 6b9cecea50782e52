"""Write the VTK legacy test fixtures in this directory.

Run from this directory: `python3 make_fixtures.py` (needs meshio, numpy and vtk; see tests/requirements.txt).

meshio writes most files, `write_v30_ascii` and `write_v20_binary_voxels` write by hand what
meshio cannot, and VTK 9.7 itself writes `block_vtk97_*` (`write_with_vtk`). All files hold the
same mesh (see `block_mesh`): a 2x2x2 block of 8 hexahedra on a 3x3x3
grid, 4 quadrilaterals on its bottom face and 1 vertex cell, with the cell data array
`gmsh:physical` (hexes 1,1,1,1,2,2,2,2; quads 10,10,11,11; vertex 5). Point p = i + 3j + 9k
sits at (i + 0.125 i k, 1.5 j, 0.25 k + 0.125 i), exact in float32. The reader tests
recompute this mesh and compare every variant against it.
"""

import json

import meshio
import numpy as np


def block_mesh():
    pts = []
    for k in range(3):
        for j in range(3):
            for i in range(3):
                pts.append([i + 0.125 * i * k, 1.5 * j, 0.25 * k + 0.125 * i])
    pts = np.array(pts, dtype=np.float64)

    def p(i, j, k):
        return i + 3 * j + 9 * k

    hexes = []
    for k in range(2):
        for j in range(2):
            for i in range(2):
                hexes.append(
                    [
                        p(i, j, k),
                        p(i + 1, j, k),
                        p(i + 1, j + 1, k),
                        p(i, j + 1, k),
                        p(i, j, k + 1),
                        p(i + 1, j, k + 1),
                        p(i + 1, j + 1, k + 1),
                        p(i, j + 1, k + 1),
                    ]
                )
    quads = []
    for j in range(2):
        for i in range(2):
            quads.append([p(i, j, 0), p(i, j + 1, 0), p(i + 1, j + 1, 0), p(i + 1, j, 0)])
    hexes = np.array(hexes)
    quads = np.array(quads)
    verts = np.array([[p(2, 2, 2)]])
    tags = [
        np.array([1, 1, 1, 1, 2, 2, 2, 2], dtype=np.int32),
        np.array([10, 10, 11, 11], dtype=np.int32),
        np.array([5], dtype=np.int32),
    ]
    return pts, hexes, quads, verts, tags


def quad2d_mesh():
    """3x2 quads on a 4x3 grid, plus 2 tagged boundary lines; point p = i + 4j at (i, 0.5 j)."""
    pts = np.array([[i, 0.5 * j, 0.0] for j in range(3) for i in range(4)])
    quads = np.array(
        [[i + 4 * j, i + 1 + 4 * j, i + 5 + 4 * j, i + 4 + 4 * j] for j in range(2) for i in range(3)]
    )
    lines = np.array([[0, 1], [1, 2]])
    tags = [np.array([7, 7, 7, 8, 8, 8], dtype=np.int32), np.array([3, 4], dtype=np.int32)]
    return pts, quads, lines, tags


def meshio_block(float32=False):
    pts, hexes, quads, verts, tags = block_mesh()
    if float32:
        pts = pts.astype(np.float32)
    return meshio.Mesh(
        pts,
        [("hexahedron", hexes), ("quad", quads), ("vertex", verts)],
        cell_data={"gmsh:physical": tags},
    )


def write_v30_ascii(path):
    """VTK 3.0 ASCII written by hand: voxels and pixels instead of hexes and quads, tags as
    SCALARS (with a lower-priority MaterialIds array first), and data sections to skip."""
    pts, hexes, quads, verts, tags = block_mesh()
    voxel = [0, 1, 3, 2, 4, 5, 7, 6]
    pixel = [0, 1, 3, 2]
    # The block is not axis-aligned (x depends on k), which the reader does not check; a
    # voxel/pixel is only a node order here.
    lines = ["# vtk DataFile Version 3.0", "hand-written block with voxels and pixels", "ASCII"]
    lines.append("DATASET UNSTRUCTURED_GRID")
    lines.append("FIELD FieldData 2")
    lines.append("TIME 1 1 double")
    lines.append("0.5")
    lines.append("CYCLE 1 1 int")
    lines.append("3")
    lines.append(f"POINTS {len(pts)} double")
    for x in pts:
        lines.append(" ".join(repr(float(v)) for v in x))
    n = len(hexes) + len(quads) + len(verts)
    size = 9 * len(hexes) + 5 * len(quads) + 2 * len(verts)
    lines.append("")
    lines.append(f"CELLS {n} {size}")
    for h in hexes:
        lines.append("8 " + " ".join(str(h[v]) for v in voxel))
    for q in quads:
        lines.append("4 " + " ".join(str(q[v]) for v in pixel))
    for v in verts:
        lines.append(f"1 {v[0]}")
    lines.append(f"CELL_TYPES {n}")
    lines += ["11"] * len(hexes) + ["8"] * len(quads) + ["1"] * len(verts)
    lines.append(f"POINT_DATA {len(pts)}")
    lines.append("SCALARS temperature float 2")
    lines.append("LOOKUP_TABLE default")
    lines += ["1.0 2.0"] * len(pts)
    lines.append("VECTORS velocity double")
    lines += ["0 0 1"] * len(pts)
    lines.append(f"CELL_DATA {n}")
    lines.append("SCALARS MaterialIds int 1")
    lines.append("LOOKUP_TABLE default")
    lines.append(" ".join(["99"] * n))
    lines.append("SCALARS gmsh:physical int")
    lines.append("LOOKUP_TABLE my_table")
    lines.append(" ".join(str(t) for t in np.concatenate(tags)))
    lines.append("LOOKUP_TABLE my_table 2")
    lines.append("0 0 0 1")
    lines.append("1 1 1 1")
    lines.append("FIELD extra 2")
    lines.append(f"pressure 1 {n} float")
    lines.append(" ".join(["0.5"] * n))
    lines.append("METADATA")
    lines.append("INFORMATION 0")
    lines.append("")
    lines.append(f"names 1 {n} string")
    lines.append(" ".join(["a%20b"] * n))
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_v20_binary_voxels(path):
    """VTK 2.0 BINARY written by hand (big-endian): float points, voxels, int tags in a
    FIELD array named CellEntityIds, and a POINT_DATA SCALARS with a binary LOOKUP_TABLE."""
    pts, hexes, quads, verts, tags = block_mesh()
    voxel = [0, 1, 3, 2, 4, 5, 7, 6]
    out = bytearray()
    out += b"# vtk DataFile Version 2.0\nbig-endian binary\nBINARY\nDATASET UNSTRUCTURED_GRID\n"
    out += f"POINTS {len(pts)} float\n".encode()
    out += pts.astype(">f4").tobytes() + b"\n"
    n = len(hexes) + len(quads) + len(verts)
    cells = []
    for h in hexes:
        cells += [8] + [int(h[v]) for v in voxel]
    for q in quads:
        cells += [4] + [int(x) for x in q]
    for v in verts:
        cells += [1, int(v[0])]
    out += f"CELLS {n} {len(cells)}\n".encode()
    out += np.array(cells, dtype=">i4").tobytes() + b"\n"
    out += f"CELL_TYPES {n}\n".encode()
    types = [11] * len(hexes) + [9] * len(quads) + [1] * len(verts)
    out += np.array(types, dtype=">i4").tobytes() + b"\n"
    out += f"POINT_DATA {len(pts)}\n".encode()
    out += b"SCALARS flag unsigned_char 1\nLOOKUP_TABLE lut\n"
    out += bytes(len(pts)) + b"\n"
    out += b"LOOKUP_TABLE lut 2\n" + bytes([0, 10, 13, 32, 255, 255, 255, 255]) + b"\n"
    out += f"CELL_DATA {n}\nFIELD FieldData 2\n".encode()
    out += f"weight 1 {n} double\n".encode() + np.full(n, 0.5, dtype=">f8").tobytes() + b"\n"
    out += f"CellEntityIds 1 {n} vtktypeint64\n".encode()
    out += np.concatenate(tags).astype(">i8").tobytes() + b"\n"
    with open(path, "wb") as f:
        f.write(out)


def main():
    meshio.write("block_v51_ascii.vtk", meshio_block(), file_format="vtk", binary=False)
    meshio.write("block_v51_binary.vtk", meshio_block(), file_format="vtk", binary=True)
    meshio.write(
        "block_v42_ascii.vtk", meshio_block(), file_format="vtk42", binary=False
    )
    meshio.write(
        "block_v42_binary_f32.vtk",
        meshio_block(float32=True),
        file_format="vtk42",
        binary=True,
    )
    write_v30_ascii("block_v30_voxels.vtk")
    write_v20_binary_voxels("block_v20_binary_voxels.vtk")
    pts, quads, lines, tags = quad2d_mesh()
    meshio.write(
        "quad2d_v51_binary.vtk",
        meshio.Mesh(pts, [("quad", quads), ("line", lines)], cell_data={"medit:ref": tags}),
        file_format="vtk",
        binary=True,
    )


def vtk_block_grid():
    """The block mesh as a vtkUnstructuredGrid built with VTK's own API (an independent
    writer: VTK 9.7, see tests/requirements.txt)."""
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonCore import vtkIntArray, vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkUnstructuredGrid

    pts, hexes, quads, verts, tags = block_mesh()
    grid = vtkUnstructuredGrid()
    points = vtkPoints()
    points.SetData(numpy_to_vtk(pts, deep=True))
    grid.SetPoints(points)
    for cells, vtk_type in [(hexes, 12), (quads, 9), (verts, 1)]:
        for c in cells:
            grid.InsertNextCell(vtk_type, len(c), [int(v) for v in c])
    arr = vtkIntArray()
    arr.SetName("gmsh:physical")
    for t in np.concatenate(tags):
        arr.InsertNextValue(int(t))
    grid.GetCellData().AddArray(arr)
    # Computing the norm range caches information keys on the points array, which VTK then
    # writes (legacy METADATA blocks, XML <InformationKey> elements).
    grid.GetPoints().GetData().GetRange(-1)
    return grid


def write_with_vtk():
    from vtkmodules.vtkIOLegacy import vtkUnstructuredGridWriter

    grid = vtk_block_grid()
    for name, binary, version in [
        ("block_vtk97_binary.vtk", True, None),
        ("block_vtk97_ascii_v42.vtk", False, 42),
    ]:
        w = vtkUnstructuredGridWriter()
        w.SetInputData(grid)
        w.SetFileName(name)
        if binary:
            w.SetFileTypeToBinary()
        if version:
            w.SetFileVersion(version)
        w.Write()


def lagrange_grid():
    """One cell each of VTK types 72 (order-3 Lagrange hexahedron), 70 (order-2 Lagrange
    quadrilateral), 28 (biquadratic quad), 68 (order-3 Lagrange curve) and 29 (triquadratic
    hexahedron), node ids 0..112 in order, point i at (i, i mod 7, i mod 3)."""
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkUnstructuredGrid

    grid = vtkUnstructuredGrid()
    points = vtkPoints()
    cells = [(72, 64), (70, 9), (28, 9), (68, 4), (29, 27)]
    n = sum(c for _, c in cells)
    for i in range(n):
        points.InsertNextPoint(float(i), float(i % 7), float(i % 3))
    grid.SetPoints(points)
    first = 0
    for t, c in cells:
        grid.InsertNextCell(t, c, list(range(first, first + c)))
        first += c
    return grid


def vtk_cell_ids(path):
    """Node ids of every cell as VTK 9.7's own reader returns them."""
    from vtkmodules.vtkIOLegacy import vtkUnstructuredGridReader
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    r = vtkXMLUnstructuredGridReader() if path.endswith(".vtu") else vtkUnstructuredGridReader()
    r.SetFileName(path)
    r.Update()
    g = r.GetOutput()
    out = []
    for c in range(g.GetNumberOfCells()):
        ids = g.GetCell(c).GetPointIds()
        out.append([ids.GetId(k) for k in range(ids.GetNumberOfIds())])
    return out


def write_lagrange():
    """Lagrange cells written by VTK in the current (5.1) and an old (4.2) legacy version;
    VTK reads old files' Lagrange hexahedra in the VTK 8 numbering. The node ids VTK's reader
    returns for each file go to lagrange_expected.json."""
    from vtkmodules.vtkIOLegacy import vtkUnstructuredGridWriter

    grid = lagrange_grid()
    expected = {}
    for name, version in [("lagrange_vtk97.vtk", None), ("lagrange_vtk97_v42.vtk", 42)]:
        w = vtkUnstructuredGridWriter()
        w.SetInputData(grid)
        w.SetFileName(name)
        if version:
            w.SetFileVersion(version)
        w.Write()
        expected[name] = vtk_cell_ids(name)
    with open("lagrange_expected.json", "w") as f:
        json.dump(expected, f)


if __name__ == "__main__":
    main()
    write_with_vtk()
    write_lagrange()
