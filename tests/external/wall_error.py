#!/usr/bin/env python3
"""Largest distance of the nodes of a boundary group from its analytic wall, as Gmsh reads the
file (high-order nodes included).

usage: wall_error.py FILE.msh GROUP WALL
WALL: "r=R" (the cylinder or circle of radius R about the z axis) or "bump=B" (the curve
y = B sin^2(pi x)). Prints one JSON object {"nodes": n, "max_error": e, "by_kind": {...}}:
"by_kind" is the largest error over the nodes of the group's facets of each kind, "seam" for
those with a node on a periodic side (an entity Gmsh's getPeriodicNodes links, either side),
"inner" for the others, each with "_rim" appended for those with a node on another
non-periodic boundary group (3D: where the wall meets the end planes in a feature edge).
"""
import json
import math
import sys

import gmsh


def open_group(path, group):
    """Open `path` in Gmsh; the mesh's dimension, the boundary group's tag, and its nodes'
    tags and flat coordinates."""
    gmsh.initialize(["-nopopup"])
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(path)
    dim = gmsh.model.getDimension()
    tag = next(
        t for d, t in gmsh.model.getPhysicalGroups(dim - 1)
        if gmsh.model.getPhysicalName(d, t) == group
    )
    tags, coords = gmsh.model.mesh.getNodesForPhysicalGroup(dim - 1, tag)
    return dim, tag, tags, coords


def group_facets(dim, tag):
    """Every facet of boundary group `tag`, as the list of its node tags (high-order too)."""
    for ent in gmsh.model.getEntitiesForPhysicalGroup(dim - 1, tag):
        for etype, _, enodes in zip(*gmsh.model.mesh.getElements(dim - 1, ent)):
            nn = gmsh.model.mesh.getElementProperties(etype)[3]
            for k in range(len(enodes) // nn):
                yield [int(v) for v in enodes[k * nn:(k + 1) * nn]]


def main():
    path, group, wall = sys.argv[1:4]
    dim, tag, tags, coords = open_group(path, group)
    kind, value = wall.split("=")
    value = float(value)
    error = {}
    n = len(coords) // 3
    for i in range(n):
        x, y = coords[3 * i], coords[3 * i + 1]
        if kind == "r":
            e = abs(math.hypot(x, y) - value)
        else:
            e = abs(y - value * math.sin(math.pi * x) ** 2)
        error[int(tags[i])] = e
    # Nodes on the periodic sides, and on the other boundary groups.
    seam, periodic = set(), set()
    for _, ent in gmsh.model.getEntities(dim - 1):
        master, nodes, mnodes, _ = gmsh.model.mesh.getPeriodicNodes(dim - 1, ent, True)
        if master != ent and len(nodes):
            seam.update(int(v) for v in nodes)
            seam.update(int(v) for v in mnodes)
            periodic.update((int(ent), int(master)))
    rim = set()
    for d, t in gmsh.model.getPhysicalGroups(dim - 1):
        ents = [int(e) for e in gmsh.model.getEntitiesForPhysicalGroup(d, t)]
        if t != tag and not any(e in periodic for e in ents):
            rim.update(int(v) for v in gmsh.model.mesh.getNodesForPhysicalGroup(d, t)[0])
    by_kind = {}
    for facet in group_facets(dim, tag):
        key = "seam" if any(v in seam for v in facet) else "inner"
        if any(v in rim for v in facet):
            key += "_rim"
        worst = max(error[v] for v in facet)
        by_kind[key] = max(by_kind.get(key, 0.0), worst)
    gmsh.finalize()
    print(json.dumps({"nodes": n, "max_error": max(error.values()), "by_kind": by_kind}))


if __name__ == "__main__":
    main()
