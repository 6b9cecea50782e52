"""Make the CGNS reader fixtures with independent tools: Gmsh's CGNS export (the CGNS library
it links), the CGNS library's own `plot3d_to_cgns` and `cgnsconvert`.

hex_box_gmsh.cgns               Gmsh, unstructured: the unit cube as 2x2x2 HEXA_8, QUAD_4
                                boundary sections, families "wall" (faces 1-2, 8 quads),
                                "far" (faces 3-6, 16 quads), volume family "fluid".
quads_gmsh.cgns                 Gmsh, unstructured 2D: [0,2]x[0,1] as 3x3 QUAD_4, BAR_2
                                sections, families "bottom" (3 bars) and "rest" (9 bars).
two_blocks_structured_gmsh.cgns Gmsh, structured: two 3x3x3 zones sharing the face x = 1,
                                joined by GridConnectivity1to1 (PointRange/Transform),
                                "inlet" on the face x = 0 (4 quads), BCs on every face.
two_blocks_plot3d.cgns          plot3d_to_cgns of ../plot3d/two_blocks.xyz: two structured
                                zones, no connectivity (glued at coincident vertices).
hex_box.adf                     cgnsconvert -a of hex_box_gmsh.cgns (the ADF container).
periodic_sector_gmsh.cgns       Gmsh, unstructured: a 30-degree sector of an annulus (r in
                                [1, 2], z in [0, 1], revolved about z), 12 HEXA_8, the side
                                faces "side0" (y = 0) and "side1" declared periodic (rotation
                                by 30 degrees about z): one periodic GridConnectivity_t per
                                mesh entity and direction; "rest" the other faces.

Run from this directory with Gmsh's Python module and Debian's cgns-convert installed.
"""
import math
import subprocess

import gmsh


def transfinite(n):
    for c in gmsh.model.getEntities(1):
        gmsh.model.mesh.setTransfiniteCurve(c[1], n)
    for s in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(s[1])
        gmsh.model.mesh.setRecombine(2, s[1])
    for v in gmsh.model.getEntities(3):
        gmsh.model.mesh.setTransfiniteVolume(v[1])


gmsh.initialize()
gmsh.option.setNumber("General.Terminal", 0)

gmsh.model.add("hex_box_gmsh")
gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
gmsh.model.occ.synchronize()
transfinite(3)
gmsh.model.addPhysicalGroup(3, [1], name="fluid")
gmsh.model.addPhysicalGroup(2, [1, 2], name="wall")
gmsh.model.addPhysicalGroup(2, [3, 4, 5, 6], name="far")
gmsh.model.mesh.generate(3)
gmsh.write("hex_box_gmsh.cgns")

gmsh.model.add("quads_gmsh")
gmsh.model.occ.addRectangle(0, 0, 0, 2, 1)
gmsh.model.occ.synchronize()
transfinite(4)
gmsh.model.addPhysicalGroup(2, [1], name="fluid")
gmsh.model.addPhysicalGroup(1, [1], name="bottom")
gmsh.model.addPhysicalGroup(1, [2, 3, 4], name="rest")
gmsh.model.mesh.generate(2)
gmsh.write("quads_gmsh.cgns")

gmsh.model.add("two_blocks_structured_gmsh")
gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
gmsh.model.occ.addBox(1, 0, 0, 1, 1, 1)
gmsh.model.occ.fragment([(3, 1)], [(3, 2)])
gmsh.model.occ.synchronize()
transfinite(3)
gmsh.model.addPhysicalGroup(3, [1, 2], name="fluid")
gmsh.model.addPhysicalGroup(2, [1], name="inlet")
gmsh.model.mesh.generate(3)
gmsh.option.setNumber("Mesh.CgnsExportStructured", 1)
gmsh.write("two_blocks_structured_gmsh.cgns")

gmsh.model.add("periodic_sector_gmsh")
g = gmsh.model.geo
p = [g.addPoint(1, 0, 0), g.addPoint(2, 0, 0), g.addPoint(2, 0, 1), g.addPoint(1, 0, 1)]
lines = [g.addLine(p[i], p[(i + 1) % 4]) for i in range(4)]
side0 = g.addPlaneSurface([g.addCurveLoop(lines)])
for c in lines:
    g.mesh.setTransfiniteCurve(c, 3)
g.mesh.setTransfiniteSurface(side0)
g.mesh.setRecombine(2, side0)
out = g.revolve([(2, side0)], 0, 0, 0, 0, 0, 1, math.pi / 6, numElements=[3], recombine=True)
g.synchronize()
side1 = out[0][1]
gmsh.model.addPhysicalGroup(3, [t for d, t in out if d == 3], name="fluid")
gmsh.model.addPhysicalGroup(2, [side0], name="side0")
gmsh.model.addPhysicalGroup(2, [side1], name="side1")
gmsh.model.addPhysicalGroup(2, [t for d, t in out if d == 2 and t != side1], name="rest")
c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
gmsh.model.mesh.setPeriodic(2, [side1], [side0], [c, -s, 0, 0, s, c, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])
gmsh.model.mesh.generate(3)
gmsh.write("periodic_sector_gmsh.cgns")
gmsh.finalize()

subprocess.run(["plot3d_to_cgns", "-f", "../plot3d/two_blocks.xyz", "two_blocks_plot3d.cgns"], check=True)
subprocess.run(["cgnsconvert", "-a", "hex_box_gmsh.cgns", "hex_box.adf"], check=True)
