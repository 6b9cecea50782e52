#!/usr/bin/env python3
"""Independent check of high-order mesh files with Gmsh's own reader and basis functions.

usage: gmsh_probe.py JOBS.json
JOBS.json: {"jobs": [{"file": "a.msh", "probes": [[element_index, u, v, w], ...],
"det_at": [[element_index, u, v, w], ...]}, ...]} with element_index counting the volume
elements (quads in 2D, hexes in 3D) in file order, (u, v, w) in [0,1]^d and "det_at" optional.
Prints a JSON list, one object per job: {"elements", "type_name", "order",
"points": [[x, y, z], ...], "min_det_jac", "max_det_jac", "dets": [...], "boundary_elements",
"physical_groups": {"dim tag": name}}. "min_det_jac"/"max_det_jac" come from a Gauss rule of
degree 2p+2 and "dets" are at the "det_at" points; all are Gmsh's determinants with respect to
its reference element [-1,1]^d. They are signed in 2D too: Gmsh's own 2D determinant is the
length of the cross product (never negative), so a quad's is taken here from the first two
rows of Gmsh's Jacobian matrix (dx/du dy/dv - dy/du dx/dv), which is negative for a mirrored
(clockwise) quad.
"""
import json
import sys

import gmsh
import numpy as np


def signed(dim, jacs, dets):
    """Gmsh's determinants, with the sign of the in-plane Jacobian in 2D (see above)."""
    if dim == 3:
        return np.asarray(dets)
    j = np.asarray(jacs).reshape(-1, 9)
    return j[:, 0] * j[:, 4] - j[:, 1] * j[:, 3]


def probe(path, probes, det_at):
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
    jacs, dets, _ = gmsh.model.mesh.getJacobians(etype, loc)
    dets = signed(dim, jacs, dets)
    at = []
    for e, u, v, w in det_at:
        local = [2 * u - 1, 2 * v - 1, 2 * w - 1 if dim == 3 else 0.0]
        j, d, _ = gmsh.model.mesh.getJacobian(int(tags[0][e]), local)
        at.append(float(signed(dim, j, d)[0]))
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
        "dets": at,
        "boundary_elements": int(sum(len(t) for t in btags)),
        "physical_groups": groups,
    }


def main():
    jobs = json.load(open(sys.argv[1]))["jobs"]
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    print(json.dumps([probe(j["file"], j["probes"], j.get("det_at", [])) for j in jobs]))
    gmsh.finalize()


if __name__ == "__main__":
    main()
