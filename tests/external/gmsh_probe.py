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
its reference element [-1,1]^d, signed in 2D too (see gmsh_volume.py: a mirrored quad's are
negative).
"""
import json
import sys

import gmsh
import numpy as np

from gmsh_volume import Volume, session


def probe(path, probes, det_at):
    vol = Volume(path)
    dim = vol.dim
    points = []
    for e, u, v, w in probes:
        _, bf, _ = gmsh.model.mesh.getBasisFunctions(
            vol.etype, vol.local([2 * u - 1, 2 * v - 1, 2 * w - 1][:dim]), "Lagrange")
        points.append((np.asarray(bf) @ vol.coords(vol.conn[e])).tolist())
    dets = vol.gauss_dets()
    at = []
    for e, u, v, w in det_at:
        j, d, _ = gmsh.model.mesh.getJacobian(
            int(vol.tags[e]), vol.local([2 * u - 1, 2 * v - 1, 2 * w - 1][:dim]))
        at.append(float(vol.signed(j, d)[0]))
    _, btags, _ = gmsh.model.mesh.getElements(dim - 1)
    groups = {}
    for d, t in gmsh.model.getPhysicalGroups():
        groups["%d %d" % (d, t)] = gmsh.model.getPhysicalName(d, t)
    return {
        "elements": int(vol.conn.shape[0]),
        "type_name": vol.name,
        "order": vol.order,
        "points": points,
        "min_det_jac": float(np.min(dets)),
        "max_det_jac": float(np.max(dets)),
        "dets": at,
        "boundary_elements": int(sum(len(t) for t in btags)),
        "physical_groups": groups,
    }


def main():
    jobs = json.load(open(sys.argv[1]))["jobs"]
    with session():
        out = [probe(j["file"], j["probes"], j.get("det_at", [])) for j in jobs]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
