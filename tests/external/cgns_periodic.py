#!/usr/bin/env python3
"""Periodic grid connectivity of a CGNS/HDF5 file, read with h5py (not the CGNS library, not
polyspline's reader).

usage: cgns_periodic.py FILE.cgns
Prints one JSON object:
  "phys_dim": the base's physical dimension, "diagonal": bounding-box diagonal of the nodes,
  "sides": {family name: sorted 1-based node ids of its boundary section's elements},
  "connections": per GridConnectivity_t of the zone's ZoneGridConnectivity_t:
      {"name", "donor" (the node's value), "type" (GridConnectivityType), "location"
      (GridLocation), "n" (PointList length), "donor_n", "distinct" (distinct PointList
      entries), "current_side"/"donor_side" (the family whose section's nodes are exactly the
      PointList / PointListDonor set, "" if none), "center", "angles", "translation"
      (Periodic_t, as stored), "max_mismatch" (largest |M x_current - x_donor| over the
      entries, absolute, M the CGNS map: about the centre rotate about x, then y, then z by
      the angles, then translate), "max_residual" (the same with the map fitted to the pairs
      by least squares: shows whether the pairs are rigid images at all)}.
"""
import json
import sys

import h5py
import numpy as np


def label(g):
    return g.attrs["label"].tobytes().decode().rstrip("\0 ")


def text(g):
    return g[" data"][()].tobytes().decode().rstrip("\0 ")


def children(g, lab):
    return [g[k] for k in g if isinstance(g[k], h5py.Group) and label(g[k]) == lab]


def cgns_map(c, a, t, x):
    y = x - c
    for axis in range(3):
        i, j = (axis + 1) % 3, (axis + 2) % 3
        cs, sn = np.cos(a[axis]), np.sin(a[axis])
        yi, yj = y[:, i].copy(), y[:, j].copy()
        y[:, i] = cs * yi - sn * yj
        y[:, j] = sn * yi + cs * yj
    return y + c + t


def main():
    f = h5py.File(sys.argv[1], "r")
    (base,) = children(f, "CGNSBase_t")
    phys = int(base[" data"][()][1])
    (zone,) = children(base, "Zone_t")
    gc = children(zone, "GridCoordinates_t")[0]
    cols = [gc[n][" data"][()] for n in ("CoordinateX", "CoordinateY", "CoordinateZ") if n in gc]
    while len(cols) < 3:
        cols.append(np.zeros_like(cols[0]))
    x = np.stack(cols, axis=1)
    diagonal = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))
    sections = []
    for s in children(zone, "Elements_t"):
        lo, hi = (int(v) for v in s["ElementRange"][" data"][()])
        sections.append((lo, hi, s["ElementConnectivity"][" data"][()]))
    sides = {}
    for bc in children(children(zone, "ZoneBC_t")[0], "BC_t"):
        lo, hi = (int(v) for v in bc["PointRange"][" data"][()].ravel())
        fam = text(bc["FamilyName"])
        nodes = [c for (a, b, c) in sections if a == lo and b == hi]
        if nodes:
            sides[fam] = sorted({int(v) for v in nodes[0]})

    def side_of(ids):
        s = sorted(set(ids))
        return next((k for k, v in sides.items() if v == s), "")

    out = []
    for zgc in children(zone, "ZoneGridConnectivity_t"):
        for conn in children(zgc, "GridConnectivity_t"):
            cur = conn["PointList"][" data"][()].ravel().astype(np.int64)
            don = conn["PointListDonor"][" data"][()].ravel().astype(np.int64)
            per = conn["GridConnectivityProperty"]["Periodic"]
            vec = lambda n: np.pad(per[n][" data"][()].astype(np.float64), (0, 3 - phys))
            c, a, t = vec("RotationCenter"), vec("RotationAngle"), vec("Translation")
            xc, xd = x[cur - 1], x[don - 1]
            miss = np.linalg.norm(cgns_map(c, a, t, xc.copy()) - xd, axis=1)
            # Best rigid fit (Kabsch) of the pairs, independent of the stored parameters.
            mc, md = xc.mean(axis=0), xd.mean(axis=0)
            u, _, vt = np.linalg.svd((xc - mc).T @ (xd - md))
            r = (u @ vt).T
            if np.linalg.det(r) < 0:
                vt[-1] *= -1
                r = (u @ vt).T
            res = np.linalg.norm((xc - mc) @ r.T + md - xd, axis=1)
            out.append({
                "name": conn.name.split("/")[-1],
                "donor": text(conn),
                "type": text(conn["GridConnectivityType"]),
                "location": text(conn["GridLocation"]),
                "n": int(len(cur)),
                "donor_n": int(len(don)),
                "distinct": int(len(set(cur.tolist()))),
                "current_side": side_of(cur),
                "donor_side": side_of(don),
                "center": c.tolist(),
                "angles": a.tolist(),
                "translation": t.tolist(),
                "max_mismatch": float(miss.max()),
                "max_residual": float(res.max()),
            })
    print(json.dumps({"phys_dim": phys, "diagonal": diagonal, "sides": sides, "connections": out}))


if __name__ == "__main__":
    main()
