#!/usr/bin/env python3
"""Largest distance from the cylinder r = R about the z axis of the nodes of a boundary group's
facets, by where the facet lies on the group, as Gmsh reads the file (high-order nodes
included).

usage: cylinder_cells.py FILE.msh GROUP R
Prints one JSON object {"corner": e, "theta": e, "z": e, "interior": e}: "theta" for the
facets with a node on the group's lowest or highest angle about z (and none on its lowest or
highest z), "z" for those with a node on its lowest or highest z (and none on those angles),
"corner" for those with both, "interior" for the others.
"""
import json
import math
import sys

import gmsh

from wall_error import group_facets, open_group


def main():
    path, group, radius = sys.argv[1], sys.argv[2], float(sys.argv[3])
    dim, tag, tags, coords = open_group(path, group)
    x = {int(tags[i]): coords[3 * i:3 * i + 3] for i in range(len(tags))}
    angle = {v: math.atan2(p[1], p[0]) for v, p in x.items()}
    a_lo, a_hi = min(angle.values()), max(angle.values())
    z_lo, z_hi = min(p[2] for p in x.values()), max(p[2] for p in x.values())
    tol = 1e-9
    out = {}
    for facet in group_facets(dim, tag):
        on_a = any(min(abs(angle[v] - a_lo), abs(angle[v] - a_hi)) < tol for v in facet)
        on_z = any(min(abs(x[v][2] - z_lo), abs(x[v][2] - z_hi)) < tol for v in facet)
        key = ("corner" if on_z else "theta") if on_a else ("z" if on_z else "interior")
        e = max(abs(math.hypot(x[v][0], x[v][1]) - radius) for v in facet)
        out[key] = max(out.get(key, 0.0), e)
    gmsh.finalize()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
