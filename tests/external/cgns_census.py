"""Counts of a CGNS/HDF5 file read with h5py (the HDF5 library), independent of polyspline's
reader: the oracle of the real-CGNS census test.

    cgns_census.py FILE.cgns

Prints JSON: per element type name the number of elements over all zones and sections
(`MIXED` sections element by element), the vertex count of each zone, the number of distinct
vertex positions over all zones (coordinates rounded to 1e-9 of the bounding box: the vertex
count after zones are glued at coincident vertices), and per boundary name (the BC's
`FamilyName`, else its own name) the number of entries of its `PointList`/`ElementList`.
Unstructured zones and CGNS 3 `MIXED` sections only (the real files at hand).
"""
import json
import sys

import h5py
import numpy as np

TYPES = {2: ("NODE", 1), 3: ("BAR_2", 2), 5: ("TRI_3", 3), 7: ("QUAD_4", 4),
         10: ("TETRA_4", 4), 12: ("PYRA_5", 5), 14: ("PENTA_6", 6), 17: ("HEXA_8", 8)}


def label(g):
    return g.attrs["label"].decode().rstrip("\0 ")


def text(g):
    return bytes(g[" data"][()].astype(np.uint8)).decode().rstrip("\0 ")


def children(g, want):
    return [c for c in g.values() if isinstance(c, h5py.Group) and label(c) == want]


f = h5py.File(sys.argv[1], "r")
(base,) = [b for b in children(f, "CGNSBase_t") if children(b, "Zone_t")]
counts, zone_vertices, bcs, points = {}, [], {}, []
for z in children(base, "Zone_t"):
    zone_vertices.append(int(z[" data"][()].flat[0]))
    xyz = [z["GridCoordinates"][f"Coordinate{c}"][" data"][()] for c in "XYZ"]
    points.append(np.stack(xyz, axis=1))
    for s in children(z, "Elements_t"):
        code = int(s[" data"][0])
        conn = s["ElementConnectivity"][" data"][()]
        if code == 20:
            at = 0
            while at < len(conn):
                name, n = TYPES[int(conn[at])]
                counts[name] = counts.get(name, 0) + 1
                at += 1 + n
        else:
            name, n = TYPES[code]
            counts[name] = counts.get(name, 0) + len(conn) // n
    for zbc in children(z, "ZoneBC_t"):
        for bc in children(zbc, "BC_t"):
            fam = children(bc, "FamilyName_t")
            name = text(fam[0]) if fam else bc.attrs["name"].decode().rstrip("\0 ")
            for key in ("PointList", "ElementList"):
                if key in bc:
                    bcs[name] = bcs.get(name, 0) + int(bc[key][" data"].size)
p = np.concatenate(points)
scale = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
distinct = len(np.unique(np.round(p / (1e-9 * scale)).astype(np.int64), axis=0))
print(json.dumps({"elements": counts, "zone_vertices": zone_vertices,
                  "distinct_vertices": distinct, "boundaries": bcs}))
