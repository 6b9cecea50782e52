#!/usr/bin/env python3
"""Read our output files with the downstream tools our users run, unchanged, and report what
each tool saw, as one JSON object on stdout.

usage:
  clients_probe.py pyfr MESH.msh OUT.pyfrm ...  PyFR's importer (`pyfr import`), then its file:
                                                counts, and per element type the node
                                                coordinates of every element in PyFR's order,
                                                PyFR's reference points and Gmsh's map of the
                                                same file evaluated there
  clients_probe.py mfem MESH ...                PyMFEM: counts, attributes, volume, min det J
  clients_probe.py meshio MESH ...              meshio: cells per type, physical groups, points,
                                                and per cell block its connectivity and the
                                                reference coordinates of its nodes in the
                                                convention meshio uses for the type
  clients_probe.py pyhope MESH.msh DIR          PyHOPE converts MESH to HOPR HDF5 in DIR; counts,
                                                boundary names, NGeo and the volume of its nodes

Prints a JSON list, one object per file (pyhope: one object); where the tool refused the file,
the object is {"error": the tool's message}.
"""
import json
import os
import subprocess
import sys

import numpy as np


# PyFR's default tolerance below which `pyfr import` snaps an element's nodes to its linear
# interpolant (passed explicitly so that the tests know it).
PYFR_LINTOL = 1e-5


def pyfr(mesh, out):
    import h5py

    # PyFR's own command line, as a user runs it.
    run = subprocess.run([sys.executable, "-m", "pyfr", "import", "-l", str(PYFR_LINTOL),
                          mesh, out], capture_output=True, text=True)
    if run.returncode != 0:
        return {"error": f"pyfr import failed: {run.stderr.strip()[-2000:]}"}
    with h5py.File(out, "r") as f:
        codec = [c.decode() for c in f["codec"][:]]
        location = np.asarray(f["nodes"]["location"])
        eles, bcs, curved, geometry = {}, {}, 0, {}
        for etype, data in f["eles"].items():
            eles[etype] = int(data.shape[0])
            curved += int(np.count_nonzero(data["curved"]))
            faces = data["faces"]
            # Each face: (codec index, other element or -1, ...): count the boundary faces.
            cidx = faces["cidx"] if faces.dtype.names else faces[..., 0]
            for c in np.asarray(cidx).ravel():
                name = codec[int(c)]
                if name.startswith("bc/"):
                    bcs[name[3:]] = bcs.get(name[3:], 0) + 1
            pts = np.asarray(data.attrs["pts"], dtype=float)
            coords = location[np.asarray(data["nodes"])]
            geometry[etype] = {
                "pts": pts.tolist(),
                "coords": coords.tolist(),
                "curved": np.asarray(data["curved"]).tolist(),
                "gmsh": gmsh_at(mesh, pts, coords.shape[-1]).tolist(),
            }
        return {"eles": eles, "bcs": bcs, "curved": curved,
                "nodes": int(f["nodes"].shape[0]), "lintol": PYFR_LINTOL,
                "geometry": geometry}


def gmsh_at(mesh, pts, ndim):
    """Gmsh's own map of every volume element of `mesh` (file order) at the reference points
    `pts` (Gmsh's quad/hex reference is PyFR's, [-1,1]^d): [element][point][coordinate]."""
    import gmsh
    from gmsh_volume import Volume, session

    with session():
        vol = Volume(mesh)
        _, bf, _ = gmsh.model.mesh.getBasisFunctions(vol.etype, vol.local(pts), "Lagrange")
        bf = np.asarray(bf).reshape(len(pts), vol.nnodes)
        return np.einsum("pk,ekx->epx", bf, vol.coords(vol.conn))[..., :ndim]


def mfem_probe(mesh):
    import mfem.ser as mfem

    m = mfem.Mesh(mesh, 1, 1)
    dim = m.Dimension()
    nodes = m.GetNodes()
    order = nodes.FESpace().GetMaxElementOrder() if nodes is not None else 1
    volume, min_det = 0.0, float("inf")
    for e in range(m.GetNE()):
        t = m.GetElementTransformation(e)
        # det J has degree dim·order − 1 in each variable: this tensor rule is exact for it.
        ir = mfem.IntRules.Get(m.GetElementBaseGeometry(e), dim * order)
        for k in range(ir.GetNPoints()):
            ip = ir.IntPoint(k)
            t.SetIntPoint(ip)
            w = t.Weight()
            min_det = min(min_det, w)
            volume += ip.weight * w
    return {"dim": dim, "elements": m.GetNE(), "boundary_elements": m.GetNBE(),
            "order": order, "volume": volume, "min_det_jac": min_det,
            "attributes": m.attributes.ToList(),
            "bdr_attributes": m.bdr_attributes.ToList()}


def meshio_probe(mesh):
    import meshio

    # The format's own reader, so that its error (not meshio's generic one) is reported.
    m = meshio.vtu.read(mesh) if mesh.endswith(".vtu") else meshio.read(mesh)
    cells = {}
    blocks = []
    for block in m.cells:
        cells[block.type] = cells.get(block.type, 0) + len(block.data)
        blocks.append({"type": block.type, "dim": int(block.dim),
                       "conn": np.asarray(block.data).tolist(),
                       "ref": reference(mesh, block.type, len(block.data[0]))})
    groups = {name: [int(v[0]), int(v[1])] for name, v in m.field_data.items()}
    return {"points": int(len(m.points)), "cells": cells, "groups": groups,
            "coords": np.asarray(m.points).tolist(), "blocks": blocks}


def reference(mesh, mtype, nnodes):
    """Reference coordinates in [0,1]^d of the nodes of meshio's cell type `mtype` read from
    `mesh`, in the order meshio gives them, from the tool that defines that order: VTK's cell
    for VTU files and for the MSH types meshio reorders to VTK's order (hexahedron27, ...),
    Gmsh's element for the other MSH types."""
    from meshio._vtk_common import meshio_to_vtk_type
    from meshio.gmsh.common import _gmsh_to_meshio_order, _meshio_to_gmsh_type

    ident = np.arange(nnodes)[None, :]
    vtk_order = mesh.endswith(".vtu") or not np.array_equal(
        _gmsh_to_meshio_order(mtype, ident), ident)
    if vtk_order:
        return vtk_reference(mesh, meshio_to_vtk_type[mtype], nnodes)
    import gmsh
    from gmsh_volume import session

    with session():
        props = gmsh.model.mesh.getElementProperties(_meshio_to_gmsh_type[mtype])
    dim, n = props[1], props[3]
    assert n == nnodes, (mtype, n, nnodes)
    ref = np.asarray(props[4]).reshape(n, dim)
    # Gmsh's line, quad and hex references are [-1,1]^d.
    return ((ref + 1.0) / 2.0).tolist()


def vtk_reference(mesh, vtk_type, nnodes):
    """VTK's parametric coordinates ([0,1]^d) of the nodes of its cell type `vtk_type` with
    `nnodes` points: a cell of that type as VTK's reader reads it from `mesh` (Lagrange cells
    take their order from their point count), else VTK's fixed cell of the type."""
    from vtkmodules.vtkCommonDataModel import vtkGenericCell

    cell = None
    if mesh.endswith(".vtu"):
        from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

        reader = vtkXMLUnstructuredGridReader()
        reader.SetFileName(mesh)
        reader.Update()
        grid = reader.GetOutput()
        for i in range(grid.GetNumberOfCells()):
            if grid.GetCellType(i) == vtk_type:
                cell = grid.GetCell(i)
                break
    if cell is None:
        cell = vtkGenericCell()
        cell.SetCellType(vtk_type)
    n = cell.GetNumberOfPoints()
    assert n == nnodes, (vtk_type, n, nnodes)
    dim = cell.GetCellDimension()
    pc = np.asarray(cell.GetParametricCoords()).reshape(n, 3)
    return pc[:, :dim].tolist()


def pyhope(mesh, out_dir):
    import h5py
    import meshio

    # What PyHOPE needs besides the file: the boundary names (from the file's physical
    # groups, here read by meshio) and the geometry order.
    m = meshio.read(mesh)
    kinds = {b.type for b in m.cells}
    order = {"hexahedron": 1, "hexahedron27": 2, "hexahedron64": 3, "hexahedron125": 4}
    hexes = [k for k in kinds if k.startswith("hexahedron")]
    if len(hexes) != 1:
        sys.exit(f"pyhope probe: one hexahedron type expected, found {sorted(kinds)}")
    ngeo = order[hexes[0]]
    vdim = 3
    names = [n for n, (_, d) in m.field_data.items() if d == vdim - 1]
    os.makedirs(out_dir, exist_ok=True)
    lines = ["ProjectName = probe", "Mode = External", f"Filename = {os.path.abspath(mesh)}",
             "MeshIsAlreadyCurved = T", f"NGeo = {ngeo}", "OutputFormat = HDF5",
             "doSortIJK = F", "MeshSorting = None"]
    for n in names:
        lines += [f"BoundaryName = {n}", "BoundaryType = (/3,0,0,0/)"]
    ini = os.path.join(out_dir, "parameter.ini")
    with open(ini, "w") as f:
        f.write("\n".join(lines) + "\n")
    run = subprocess.run([sys.executable, "-m", "pyhope", "parameter.ini"], cwd=out_dir,
                         capture_output=True, text=True)
    out = os.path.join(out_dir, "probe_mesh.h5")
    if run.returncode != 0 or not os.path.exists(out):
        sys.exit(f"pyhope failed ({run.returncode}): {(run.stdout + run.stderr).strip()[-3000:]}")
    with h5py.File(out, "r") as f:
        ngeo_out = int(np.ravel(f.attrs["Ngeo"])[0])
        nelems = int(np.ravel(f.attrs["nElems"])[0])
        bc_names = [b.decode().strip() for b in f["BCNames"][:]]
        coords = np.asarray(f["NodeCoords"][:])
        side_info = np.asarray(f["SideInfo"][:])
    # Volume of the HOPR elements: Lagrange on NGeo+1 equidistant nodes per direction, ijk
    # order, integrated by Gauss-Legendre (exact for the polynomial det J).
    n = ngeo_out + 1
    x = coords.reshape(nelems, n, n, n, 3)  # [e, k, j, i, xyz]
    gp, gw = np.polynomial.legendre.leggauss(2 * n + 1)
    ref = np.linspace(-1.0, 1.0, n)

    def basis(t):
        v = np.ones((len(t), n))
        d = np.zeros((len(t), n))
        for a in range(n):
            for b in range(n):
                if b != a:
                    v[:, a] *= (t - ref[b]) / (ref[a] - ref[b])
            for c in range(n):
                if c == a:
                    continue
                term = np.full(len(t), 1.0 / (ref[a] - ref[c]))
                for b in range(n):
                    if b not in (a, c):
                        term *= (t - ref[b]) / (ref[a] - ref[b])
                d[:, a] += term
        return v, d

    v, d = basis(gp)
    xi = np.einsum("pi,qj,rk,ekjix->epqrx", d, v, v, x)
    xj = np.einsum("pi,qj,rk,ekjix->epqrx", v, d, v, x)
    xk = np.einsum("pi,qj,rk,ekjix->epqrx", v, v, d, x)
    det = np.einsum("epqrx,epqrx->epqr", xi, np.cross(xj, xk))
    w = np.einsum("p,q,r->pqr", gw, gw, gw)
    volume = float(np.sum(det * w))
    # Boundary sides: SideInfo column 5 (1-based) is the BC index, 0 inside.
    bc_count = {}
    for idx in side_info[:, 4]:
        if idx > 0:
            name = bc_names[idx - 1]
            bc_count[name] = bc_count.get(name, 0) + 1
    return {"ngeo": ngeo_out, "elements": nelems, "bc_names": bc_names,
            "bc_sides": bc_count, "volume": volume, "min_det_jac": float(det.min())}


def each(probe, files):
    out = []
    for f in files:
        try:
            out.append(probe(*f))
        except Exception as e:  # the tool's refusal, reported per file
            out.append({"error": f"{type(e).__name__}: {e}"})
    return out


def main():
    what, args = sys.argv[1], sys.argv[2:]
    if what == "pyfr":
        res = each(pyfr, zip(args[0::2], args[1::2]))
    elif what == "mfem":
        res = each(mfem_probe, [(a,) for a in args])
    elif what == "meshio":
        res = each(meshio_probe, [(a,) for a in args])
    elif what == "pyhope":
        res = pyhope(args[0], args[1])
    else:
        sys.exit(f"unknown probe {what}")
    print(json.dumps(res))


if __name__ == "__main__":
    main()
