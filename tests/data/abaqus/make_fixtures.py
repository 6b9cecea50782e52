"""Make the Abaqus reader fixtures.

hsphere8.inp and ball2d.inp are written by meshio 5.3.5 (an independent writer) from real
meshes of this repository; features.inp is written here by hand to cover parts, assemblies,
surfaces, GENERATE sets, continuation lines and comments. The script prints the reference
values the unit tests check.
"""
import numpy as np
import meshio

ROOT = "../../../meshes/real/"

# 3D: 648 hexes of sfepy/hsphere8.vtk, with two element sets.
m = meshio.read(ROOT + "sfepy/hsphere8.vtk")
hexes = m.cells_dict["hexahedron"]
# The first 100 hexes get their own set (tag 1), every hex is in "all" (tag 2 for the rest).
sets = {"first100": [np.arange(100)], "all": [np.arange(len(hexes))]}
out = meshio.Mesh(m.points, [("hexahedron", hexes)], cell_sets=sets)
meshio.write("hsphere8.inp", out, file_format="abaqus")
print("hsphere8: points", len(m.points), "hexes", len(hexes), "sets", {k: len(v[0]) for k, v in sets.items()})
print("  point 100", m.points[100].tolist(), "hex 37", hexes[37].tolist())

# 2D: dealii/unstructured_refined_ball.msh, quads and boundary lines.
m = meshio.read(ROOT + "dealii/unstructured_refined_ball.msh")
quads = m.cells_dict["quad"]
lines = m.cells_dict["line"]
out = meshio.Mesh(m.points[:, :2], [("quad", quads), ("line", lines)])
meshio.write("ball2d.inp", out, file_format="abaqus")
print("ball2d: points", len(m.points), "quads", len(quads), "lines", len(lines))
print("  point 7", m.points[7].tolist(), "quad 5", quads[5].tolist(), "line 3", lines[3].tolist())

# Hand-written: two hexes (2x1x1) with node ids 11.., one part instanced in an assembly.
nodes = {}
nid = 11
for k in range(2):
    for j in range(2):
        for i in range(3):
            nodes[(i, j, k)] = nid
            nid += 2  # sparse ids


def hexa(i):
    c = [(i, 0, 0), (i + 1, 0, 0), (i + 1, 1, 0), (i, 1, 0)]
    return [nodes[p] for p in c] + [nodes[(a, b, 1)] for (a, b, _) in c]


h1, h2 = hexa(0), hexa(1)
faces = {1: [0, 1, 2, 3], 2: [4, 7, 6, 5], 3: [0, 4, 5, 1], 4: [1, 5, 6, 2], 5: [2, 6, 7, 3], 6: [3, 7, 4, 0]}
with open("features.inp", "w", newline="") as f:
    w = lambda s: f.write(s + "\r\n")
    w("*Heading")
    w("** two hexes in a part, written for the reader tests")
    w("*Part, name=Block")
    w("*Node")
    for (i, j, k), n in sorted(nodes.items(), key=lambda t: t[1]):
        w(f"{n:7d}, {0.5 * i:g}, {j:g}, {k:g}")
    w("*Element, type=C3D8R,")
    w("  elset=Solid")
    w(f"101, {h1[0]}, {h1[1]}, {h1[2]}, {h1[3]},")
    w(f"   {h1[4]}, {h1[5]}, {h1[6]}, {h1[7]}")
    w("** a comment inside the section")
    w(f"103, " + ", ".join(map(str, h2)))
    w("*Elset, elset=RIGHT, generate")
    w(" 103, 103, 1")
    w("*Nset, nset=dangling")
    w(" 1, 2, 99999")
    w("*Surface, type=ELEMENT, name=Bottom")
    w("Solid, S1")
    w("*End Part")
    w("*Part, name=Other")
    w("*Node")
    w("1, 9, 9, 9")
    w("*Element, type=C3D4")
    w("1, 1, 1, 1, 1")
    w("*End Part")
    w("*Assembly, name=Assembly")
    w("*Instance, name=Block-1, part=Block")
    w("  1., 0., 0.")
    w("*End Instance")
    w("*Node")
    w("1, 5., 5., 5.")
    w("*Elset, elset=_OuterX, internal, instance=Block-1")
    w(" 103,")
    w("*Surface, type=ELEMENT, name=OuterX")
    w("_OuterX, S4")
    w("Block-1.Solid, S3")
    w("*End Assembly")
    w("*Material, name=Steel")
    w("*Elastic")
    w("210000., 0.3")

print("features: facets Bottom", [[h[i] for i in faces[1]] for h in (h1, h2)])
print("  OuterX S4 of 103", [h2[i] for i in faces[4]], "S3 of both", [[h[i] for i in faces[3]] for h in (h1, h2)])
print("  node ids", sorted(nodes.values()), "h1", h1, "h2", h2)
