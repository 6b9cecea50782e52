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

Run from this directory with Gmsh's Python module and Debian's cgns-convert installed.
"""
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
gmsh.finalize()

subprocess.run(["plot3d_to_cgns", "-f", "../plot3d/two_blocks.xyz", "two_blocks_plot3d.cgns"], check=True)
subprocess.run(["cgnsconvert", "-a", "hex_box_gmsh.cgns", "hex_box.adf"], check=True)
