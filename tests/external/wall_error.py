#!/usr/bin/env python3
"""Largest distance of the nodes of a boundary group from its analytic wall, as Gmsh reads the
file (high-order nodes included).

usage: wall_error.py FILE.msh GROUP WALL
WALL: "r=R" (the cylinder or circle of radius R about the z axis) or "bump=B" (the curve
y = B sin^2(pi x)). Prints one JSON object {"nodes": n, "max_error": e}.
"""
import json
import math
import sys

import gmsh


def main():
    path, group, wall = sys.argv[1:4]
    gmsh.initialize(["-nopopup"])
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(path)
    dim = gmsh.model.getDimension()
    tag = next(
        t for d, t in gmsh.model.getPhysicalGroups(dim - 1)
        if gmsh.model.getPhysicalName(d, t) == group
    )
    _, coords = gmsh.model.mesh.getNodesForPhysicalGroup(dim - 1, tag)
    kind, value = wall.split("=")
    value = float(value)
    worst = 0.0
    n = len(coords) // 3
    for i in range(n):
        x, y = coords[3 * i], coords[3 * i + 1]
        if kind == "r":
            e = abs(math.hypot(x, y) - value)
        else:
            e = abs(y - value * math.sin(math.pi * x) ** 2)
        worst = max(worst, e)
    gmsh.finalize()
    print(json.dumps({"nodes": n, "max_error": worst}))


if __name__ == "__main__":
    main()
