"""Make the malformed CGNS fixtures in malformed/: each is a copy of a Gmsh-written fixture
with one node broken by h5py (the HDF5 library itself), so the reader's error must name that
node's path.

    file                      broken node (base quads_gmsh.cgns, zone q_Part0)
    no_coordinate_y.cgns      GridCoordinates/CoordinateY removed
    short_coordinate.cgns     GridCoordinates/CoordinateX: 15 values for 16 vertices
    huge_shape.cgns           GridCoordinates/CoordinateX: a chunked dataset declaring 10^12
                              doubles, none stored (the memory bound must refuse it)
    real_connectivity.cgns    4_S_1/ElementConnectivity stored as R8
    vertex_out_of_range.cgns  4_S_1/ElementConnectivity: first node 99 (16 vertices)
    inverted_range.cgns       4_S_1/ElementRange [21, 13]
    unknown_type.cgns         4_S_1: element type code 99
    no_zone_type.cgns         ZoneType removed
    bc_outside.cgns           ZoneBC/L_1/PointRange [1, 99] (21 elements)
    link.cgns                 GridCoordinates typed LK (a link into another file)
    bad_transform.cgns        structured two-block fixture: Transform [1, 1, 3]
    missing_donor.cgns        structured two-block fixture: donor zone renamed "nowhere"
    truncated.cgns            quads_gmsh.cgns cut after 4096 bytes

Run from this directory with h5py installed.
"""
import os
import shutil

import h5py
import numpy as np

os.makedirs("malformed", exist_ok=True)
Z = "quads_gmsh.cgns/q_Part0"
S = "twoblock_s.cgns/fluid_V00001/ZoneGridConnectivity/S00002 (V00001 & V00002)"


def broken(name, source="quads_gmsh.cgns"):
    path = f"malformed/{name}"
    shutil.copy(source, path)
    return h5py.File(path, "r+")


def replace(group, values, **kw):
    """Replace the node's " data" dataset by `values` (or by a dataset made from `kw`)."""
    del group[" data"]
    if kw:
        group.create_dataset(" data", **kw)
    else:
        group.create_dataset(" data", data=values)


def c1(text):
    return np.frombuffer(text.encode(), dtype=np.int8)


with broken("no_coordinate_y.cgns") as f:
    del f[f"{Z}/GridCoordinates/CoordinateY"]

with broken("short_coordinate.cgns") as f:
    g = f[f"{Z}/GridCoordinates/CoordinateX"]
    replace(g, g[" data"][:15])

with broken("huge_shape.cgns") as f:
    replace(f[f"{Z}/GridCoordinates/CoordinateX"], None, shape=(10**12,), dtype="f8",
            chunks=(4096,))

with broken("real_connectivity.cgns") as f:
    g = f[f"{Z}/4_S_1/ElementConnectivity"]
    replace(g, g[" data"][:].astype("f8"))
    g.attrs["type"] = np.bytes_(b"R8")

with broken("vertex_out_of_range.cgns") as f:
    g = f[f"{Z}/4_S_1/ElementConnectivity"]
    v = g[" data"][:]
    v[0] = 99
    replace(g, v)

with broken("inverted_range.cgns") as f:
    replace(f[f"{Z}/4_S_1/ElementRange"], np.array([21, 13], dtype=np.int32))

with broken("unknown_type.cgns") as f:
    replace(f[f"{Z}/4_S_1"], np.array([99, 0], dtype=np.int32))

with broken("no_zone_type.cgns") as f:
    del f[f"{Z}/ZoneType"]

with broken("bc_outside.cgns") as f:
    replace(f[f"{Z}/ZoneBC/L_1/PointRange"], np.array([[1], [99]], dtype=np.int32))

with broken("link.cgns") as f:
    f[f"{Z}/GridCoordinates"].attrs["type"] = np.bytes_(b"LK")

with broken("bad_transform.cgns", "two_blocks_structured_gmsh.cgns") as f:
    replace(f[f"{S}/Transform"], np.array([1, 1, 3], dtype=np.int32))

with broken("missing_donor.cgns", "two_blocks_structured_gmsh.cgns") as f:
    replace(f[S], c1("nowhere"))

with open("quads_gmsh.cgns", "rb") as src, open("malformed/truncated.cgns", "wb") as dst:
    dst.write(src.read(4096))
