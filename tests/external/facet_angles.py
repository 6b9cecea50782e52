#!/usr/bin/env python3
"""Smoothness and cell quality of a high-order quad/hex MSH file, measured with Gmsh alone.

usage: facet_angles.py FILE.msh [FILE.msh ...]
Prints a JSON list, one object per file:
  "facets": interior facets measured,
  "angle_mean", "angle_p99", "angle_max": the angle in degrees, at the centre of each
      interior facet, between the two elements' derivatives transversal to it (0 = C¹),
  "ratio_min", "ratio_p1": per element min/max det J over a Gauss rule of degree 2p+2
      (Gmsh's Jacobian ratio), minimum and 1st percentile over the elements.
Derivatives come from Gmsh's getJacobians at the reference facet centres; facets are matched
by their corner node tags, the transversal reference direction by the reference coordinates of
the corner nodes (no node ordering is assumed).
"""
import json
import sys

import gmsh
import numpy as np

from gmsh_volume import Volume, session


def measure(path):
    vol = Volume(path)
    dim, ref, conn = vol.dim, vol.ref, vol.conn
    ne = conn.shape[0]
    # Reference facets: (direction k, side value ±1, corner indices), centre coordinates.
    facets = []
    for k in range(dim):
        for s in (-1.0, 1.0):
            corners = [i for i in range(vol.nprim) if abs(ref[i][k] - s) < 1e-12]
            centre = [0.0, 0.0, 0.0]
            centre[k] = s
            facets.append((k, s, corners, centre))
    loc = [c for f in facets for c in f[3]]
    jac, _, _ = gmsh.model.mesh.getJacobians(vol.etype, loc)
    # Per element, per facet point: 3×3 matrix stored by column (d x / d u_k = column k).
    jac = np.array(jac).reshape(ne, len(facets), 3, 3)
    seen = {}
    angles = []
    for e in range(ne):
        for fi, (k, s, corners, _) in enumerate(facets):
            key = tuple(sorted(int(conn[e][c]) for c in corners))
            # Derivative across the facet pointing out of the element.
            d = s * jac[e, fi, k, :]
            if key in seen:
                d0 = seen.pop(key)
                # Out of the first element = into this one: −d.
                c = np.dot(d0, -d) / (np.linalg.norm(d0) * np.linalg.norm(d))
                angles.append(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
            else:
                seen[key] = d
    angles = np.array(angles) if angles else np.zeros(1)
    dets = vol.gauss_dets(signed=False)
    ratio = dets.min(axis=1) / dets.max(axis=1)
    return {
        "file": path,
        "elements": int(ne),
        "facets": int(len(angles)),
        "angle_mean": float(angles.mean()),
        "angle_p99": float(np.percentile(angles, 99)),
        "angle_max": float(angles.max()),
        "ratio_min": float(ratio.min()),
        "ratio_p1": float(np.percentile(ratio, 1)),
    }


def main():
    with session():
        out = [measure(p) for p in sys.argv[1:]]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
