#!/usr/bin/env python3
"""Periodic quad and hex meshes made by Gmsh's API (`gmsh.model.mesh.setPeriodic`), for the
reader of the `$Periodic` section.

usage: gmsh_periodic_input.py OUT_DIR
Writes, each with physical groups on every boundary and the volume:
  channel2d_41.msh, channel2d_41b.msh, channel2d_22.msh: a 2D channel 0 <= x <= 1 whose
      sides x = 0 ("left") and x = 1 ("right") are the same curved spline, translated by
      (1, 0, 0); "bottom" and "top" straight; transfinite, recombined (quads); MSH 4.1 ASCII,
      4.1 binary and 2.2 ASCII;
  sector2d_41.msh: the annular sector 1 <= r <= 2, 0 <= theta <= 30 deg, "theta_hi" the image
      of "theta_lo" under the 30 deg rotation about z; "hub" and "shroud" arcs;
  box3d_41.msh: the box [0, 1] x [0, 0.5] x [0, 0.5], hexes, "xmax" the image of "xmin"
      under (1, 0, 0).
Prints nothing; exits non-zero if Gmsh fails.
"""
import math
import os
import sys

import gmsh


def save(path, version, binary):
    gmsh.option.setNumber("Mesh.MshFileVersion", version)
    gmsh.option.setNumber("Mesh.Binary", 1 if binary else 0)
    gmsh.write(path)


def channel(out):
    gmsh.model.add("channel")
    g = gmsh.model.geo
    pts = [(0.0, 0.0), (0.12, 0.3), (-0.08, 0.65), (0.0, 1.0)]
    left = [g.addPoint(x, y, 0) for x, y in pts]
    right = [g.addPoint(x + 1.0, y, 0) for x, y in pts]
    cl = g.addSpline(left)
    cr = g.addSpline(right)
    cb = g.addLine(left[0], right[0])
    ct = g.addLine(left[-1], right[-1])
    loop = g.addCurveLoop([cb, cr, -ct, -cl])
    s = g.addPlaneSurface([loop])
    g.synchronize()
    periodic_quads(
        s,
        {cl: 9, cr: 9, cb: 7, ct: 7},
        (cr, cl, [1, 0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]),
        {"left": cl, "right": cr, "bottom": cb, "top": ct},
    )
    save(os.path.join(out, "channel2d_41.msh"), 4.1, False)
    save(os.path.join(out, "channel2d_41b.msh"), 4.1, True)
    save(os.path.join(out, "channel2d_22.msh"), 2.2, False)
    gmsh.model.remove()


def periodic_quads(s, points, periodic, names):
    """Mesh the plane surface s with transfinite quads: points[curve] nodes on each curve,
    periodic = (image, master, affine map master -> image by rows), names[name] = curve as a
    physical group, s as "fluid"."""
    m = gmsh.model.mesh
    for c, n in points.items():
        m.setTransfiniteCurve(c, n)
    image, master, affine = periodic
    m.setPeriodic(1, [image], [master], affine)
    m.setTransfiniteSurface(s)
    m.setRecombine(2, s)
    for name, c in names.items():
        gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, [c]), name)
    gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [s]), "fluid")
    m.generate(2)


def sector(out):
    gmsh.model.add("sector")
    g = gmsh.model.geo
    t = math.radians(30.0)
    o = g.addPoint(0, 0, 0)
    a1 = g.addPoint(1, 0, 0)
    a2 = g.addPoint(2, 0, 0)
    b1 = g.addPoint(math.cos(t), math.sin(t), 0)
    b2 = g.addPoint(2 * math.cos(t), 2 * math.sin(t), 0)
    lo = g.addLine(a1, a2)
    hi = g.addLine(b1, b2)
    hub = g.addCircleArc(a1, o, b1)
    shroud = g.addCircleArc(a2, o, b2)
    s = g.addPlaneSurface([g.addCurveLoop([lo, shroud, -hi, -hub])])
    g.synchronize()
    c, sn = math.cos(t), math.sin(t)
    periodic_quads(
        s,
        {lo: 5, hi: 5, hub: 7, shroud: 7},
        (hi, lo, [c, -sn, 0, 0, sn, c, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]),
        {"theta_lo": lo, "theta_hi": hi, "hub": hub, "shroud": shroud},
    )
    save(os.path.join(out, "sector2d_41.msh"), 4.1, False)
    gmsh.model.remove()


def box(out):
    gmsh.model.add("box")
    v = gmsh.model.occ.addBox(0, 0, 0, 1, 0.5, 0.5)
    gmsh.model.occ.synchronize()
    faces = gmsh.model.getEntities(2)
    com = {f: gmsh.model.occ.getCenterOfMass(2, f) for _, f in faces}
    xmin = min(com, key=lambda f: com[f][0])
    xmax = max(com, key=lambda f: com[f][0])
    m = gmsh.model.mesh
    for _, c in gmsh.model.getEntities(1):
        m.setTransfiniteCurve(c, 4)
    for _, f in faces:
        m.setTransfiniteSurface(f)
        m.setRecombine(2, f)
    m.setTransfiniteVolume(v)
    m.setPeriodic(2, [xmax], [xmin], [1, 0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])
    gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [xmin]), "xmin")
    gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [xmax]), "xmax")
    rest = [f for _, f in faces if f not in (xmin, xmax)]
    gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, rest), "walls")
    gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [v]), "fluid")
    gmsh.option.setNumber("Mesh.Recombine3DAll", 1)
    m.generate(3)
    save(os.path.join(out, "box3d_41.msh"), 4.1, False)
    gmsh.model.remove()


def main():
    out = sys.argv[1]
    gmsh.initialize(["-nopopup"])
    gmsh.option.setNumber("General.Terminal", 0)
    channel(out)
    sector(out)
    box(out)
    gmsh.finalize()


if __name__ == "__main__":
    main()
