#!/usr/bin/env python3
"""Independent check of high-order mesh files with Gmsh's own reader and basis functions.

usage: gmsh_probe.py JOBS.json
JOBS.json: {"jobs": [{"file": "a.msh", "probes": [[element_index, u, v, w], ...]}, ...]} with
element_index counting the volume elements (quads in 2D, hexes in 3D) in file order and
(u, v, w) in [0,1]^d. Prints a JSON list, one object per job: {"elements", "type_name",
"order", "points": [[x, y, z], ...], "min_det_jac", "max_det_jac", "boundary_elements",
"physical_groups": {"dim tag": name}}. Determinants come from a Gauss rule of degree 2p+2.
"""
import json
import sys

import gmsh
import numpy as np


def probe(path, probes):
    gmsh.clear()
    gmsh.open(path)
    dim = gmsh.model.getDimension()
    types, tags, node_tags = gmsh.model.mesh.getElements(dim)
    assert len(types) == 1, "one volume element type expected"
    etype = types[0]
    name, edim, order, nnodes, ref, _ = gmsh.model.mesh.getElementProperties(etype)
    conn = np.array(node_tags[0], dtype=np.int64).reshape(-1, nnodes)
    all_tags, coords, _ = gmsh.model.mesh.getNodes()
    pos = {int(t): coords[3 * i:3 * i + 3] for i, t in enumerate(all_tags)}
    points = []
    for e, u, v, w in probes:
        local = [2 * u - 1, 2 * v - 1, 2 * w - 1 if dim == 3 else 0.0]
        _, bf, _ = gmsh.model.mesh.getBasisFunctions(etype, local, "Lagrange")
        x = np.zeros(3)
        for k in range(nnodes):
            x += bf[k] * np.array(pos[int(conn[e][k])])
        points.append(x.tolist())
    loc, _ = gmsh.model.mesh.getIntegrationPoints(etype, "Gauss%d" % (2 * order + 2))
    _, dets, _ = gmsh.model.mesh.getJacobians(etype, loc)
    _, btags, _ = gmsh.model.mesh.getElements(dim - 1)
    groups = {}
    for d, t in gmsh.model.getPhysicalGroups():
        groups["%d %d" % (d, t)] = gmsh.model.getPhysicalName(d, t)
    return {
        "elements": int(conn.shape[0]),
        "type_name": name,
        "order": int(order),
        "points": points,
        "min_det_jac": float(np.min(dets)),
        "max_det_jac": float(np.max(dets)),
        "boundary_elements": int(sum(len(t) for t in btags)),
        "physical_groups": groups,
    }


def main():
    jobs = json.load(open(sys.argv[1]))["jobs"]
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    print(json.dumps([probe(j["file"], j["probes"]) for j in jobs]))
    gmsh.finalize()


if __name__ == "__main__":
    main()
