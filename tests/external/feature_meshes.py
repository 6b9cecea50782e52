#!/usr/bin/env python3
"""Hex meshes with sharp edges, made with Gmsh's Python API (structured blocks, extruded).

usage: feature_meshes.py KIND OUT.msh N
KIND: `cylinder`: radius 1, z in [0, 2]; an O-grid disc (inner square + 4 blocks) extruded,
      N elements per block side.
      `box_hole`: the box [-1, 1]² × [0, 1] with a cylindrical hole of radius 0.5 along z;
      4 blocks between the hole and the box sides, extruded, N elements per block side.
      `plate_2d`: the square [-1, 1]² with a hole of radius 0.5, quads (Gmsh's frontal
      algorithm, triangles recombined), element size 2 / N.
Writes MSH 4.1 with hexahedra (quads for plate_2d) only (no boundary tags: the features come
from the angles).
"""
import math
import sys

import gmsh


def plate_2d(out, n):
    occ = gmsh.model.occ
    square = occ.addRectangle(-1, -1, 0, 2, 2)
    hole = occ.addDisk(0, 0, 0, 0.5, 0.5)
    occ.cut([(2, square)], [(2, hole)])
    occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", 2.0 / n)
    gmsh.option.setNumber("Mesh.MeshSizeMax", 2.0 / n)
    gmsh.option.setNumber("Mesh.Algorithm", 6)
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.model.mesh.generate(2)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    surfaces = [t for _, t in gmsh.model.getEntities(2)]
    gmsh.model.addPhysicalGroup(2, surfaces, 1)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.write(out)
    gmsh.finalize()


def main():
    kind, out, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    if kind == "plate_2d":
        plate_2d(out, n)
        return
    geo = gmsh.model.geo
    c = geo.addPoint(0, 0, 0)
    curves = {}

    def line(a, b):
        key = (min(a, b), max(a, b))
        if key not in curves:
            curves[key] = (geo.addLine(a, b), a)
        tag, start = curves[key]
        return tag if start == a else -tag

    def arc(a, b):
        key = (min(a, b), max(a, b), "arc")
        if key not in curves:
            curves[key] = (geo.addCircleArc(a, c, b), a)
        tag, start = curves[key]
        return tag if start == a else -tag

    def surface(loop):
        return geo.addPlaneSurface([geo.addCurveLoop(loop)])

    surfaces = []
    angles = [math.pi / 4 + k * math.pi / 2 for k in range(4)]
    if kind == "cylinder":
        a = 0.45
        inner = [geo.addPoint(a * math.cos(t) * math.sqrt(2), a * math.sin(t) * math.sqrt(2), 0) for t in angles]
        outer = [geo.addPoint(math.cos(t), math.sin(t), 0) for t in angles]
        surfaces.append(surface([line(inner[k], inner[(k + 1) % 4]) for k in range(4)]))
        for k in range(4):
            j = (k + 1) % 4
            surfaces.append(surface([line(inner[k], outer[k]), arc(outer[k], outer[j]),
                                     line(outer[j], inner[j]), line(inner[j], inner[k])]))
        height, layers = 2.0, 2 * n
    elif kind == "box_hole":
        r = 0.5
        hole = [geo.addPoint(r * math.cos(t), r * math.sin(t), 0) for t in angles]
        box = [geo.addPoint(math.copysign(1, math.cos(t)), math.copysign(1, math.sin(t)), 0) for t in angles]
        for k in range(4):
            j = (k + 1) % 4
            surfaces.append(surface([line(hole[k], box[k]), line(box[k], box[j]),
                                     line(box[j], hole[j]), arc(hole[j], hole[k])]))
        height, layers = 1.0, n
    else:
        sys.exit("unknown kind " + kind)
    for (tag, _) in curves.values():
        geo.mesh.setTransfiniteCurve(tag, n + 1)
    for s in surfaces:
        geo.mesh.setTransfiniteSurface(s)
        geo.mesh.setRecombine(2, s)
    geo.extrude([(2, s) for s in surfaces], 0, 0, height, [layers], recombine=True)
    geo.synchronize()
    gmsh.model.mesh.generate(3)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    volumes = [t for _, t in gmsh.model.getEntities(3)]
    gmsh.model.addPhysicalGroup(3, volumes, 1)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.write(out)
    gmsh.finalize()


if __name__ == "__main__":
    main()
