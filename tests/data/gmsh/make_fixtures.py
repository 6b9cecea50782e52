"""Write the Gmsh reader's test fixtures with independent writers (the gmsh and meshio Python
packages). Run from this directory: python3 make_fixtures.py   (pip install gmsh meshio numpy)

box_*      : a 3x3x3 transfinite hex box written by gmsh in every MSH variant it writes, with
             sparse node tags (old tag * 1000 + 7; MSH 1/2 writers renumber them 1..n), physical
             groups on the volume and on two of its six faces (only physical cells are
             written), a periodic
             face pair ($Periodic) and, in the 4.1 binary file, an appended $NodeData view.
ball_*     : deal.II's unstructured_refined_ball.msh (2.2 ASCII) re-written by gmsh as 2.2 and
             4.1 binary.
cylinder_meshio_41_bin.msh : MFEM's cylinder-hex.mesh written by meshio as MSH 4.1 binary
             (element attributes -> gmsh:physical).
tets_41.msh : a small tetrahedral box (4.1 ASCII).
quad9_22.msh : a second-order quad mesh (quad9, line3, points) (2.2 ASCII).
partitioned_41.msh : the box split into 2 partitions (4.1 ASCII, $PartitionedEntities).
"""
import os
import gmsh
import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..", "..", "..")
out = lambda name: os.path.join(HERE, name)


def write(name, version, binary):
    gmsh.option.setNumber("Mesh.MshFileVersion", version)
    gmsh.option.setNumber("Mesh.Binary", binary)
    gmsh.write(out(name))


def box():
    gmsh.model.add("box")
    gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1.5)
    gmsh.model.occ.synchronize()
    for dim, tag in gmsh.model.getEntities(1):
        xmin, ymin, zmin, xmax, ymax, zmax = gmsh.model.getBoundingBox(dim, tag)
        n = 4 if zmax - zmin > 1e-9 else 3
        gmsh.model.mesh.setTransfiniteCurve(tag, n)
    for dim, tag in gmsh.model.getEntities(2):
        gmsh.model.mesh.setTransfiniteSurface(tag)
        gmsh.model.mesh.setRecombine(2, tag)
    gmsh.model.mesh.setTransfiniteVolume(1)
    faces = {}
    for dim, tag in gmsh.model.getEntities(2):
        c = gmsh.model.occ.getCenterOfMass(2, tag)
        faces[tuple(round(x, 3) for x in c)] = tag
    bottom = faces[(0.5, 0.5, 0.0)]
    top = faces[(0.5, 0.5, 1.5)]
    left = faces[(0.0, 0.5, 0.75)]
    right = faces[(1.0, 0.5, 0.75)]
    gmsh.model.mesh.setPeriodic(2, [right], [left], [1, 0, 0, 1, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])
    gmsh.model.addPhysicalGroup(3, [1], 1, name="block")
    gmsh.model.addPhysicalGroup(2, [bottom], 10, name="bottom")
    gmsh.model.addPhysicalGroup(2, [top], 11, name="top face")
    gmsh.model.mesh.generate(3)
    old, _, _ = gmsh.model.mesh.getNodes()
    gmsh.model.mesh.renumberNodes(old, old * 1000 + 7)
    write("box_22_ascii.msh", 2.2, 0)
    write("box_22_bin.msh", 2.2, 1)
    write("box_41_ascii.msh", 4.1, 0)
    write("box_41_bin.msh", 4.1, 1)
    write("box_40_ascii.msh", 4.0, 0)
    write("box_1_ascii.msh", 1, 0)
    # A view appended as $NodeData to the binary file, to be skipped by the reader.
    tags, coords, _ = gmsh.model.mesh.getNodes()
    v = gmsh.view.add("z")
    gmsh.view.addModelData(v, 0, "box", "NodeData", tags, coords[2::3].reshape(-1, 1))
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", 1)
    gmsh.option.setNumber("PostProcessing.Binary", 1)
    gmsh.option.setNumber("PostProcessing.SaveMesh", 0)
    gmsh.view.write(v, out("box_41_bin.msh"), append=True)
    gmsh.option.setNumber("PostProcessing.Binary", 0)
    # Partitioned copy.
    gmsh.model.mesh.partition(2)
    write("partitioned_41.msh", 4.1, 0)


def ball():
    gmsh.open(os.path.join(ROOT, "meshes/real/dealii/unstructured_refined_ball.msh"))
    gmsh.option.setNumber("Mesh.SaveAll", 1)
    write("ball_22_bin.msh", 2.2, 1)
    write("ball_41_bin.msh", 4.1, 1)
    gmsh.option.setNumber("Mesh.SaveAll", 0)


def tets():
    gmsh.model.add("tets")
    gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.6)
    gmsh.model.mesh.generate(3)
    write("tets_41.msh", 4.1, 0)


def quad9():
    gmsh.model.add("quad9")
    gmsh.model.occ.addRectangle(0, 0, 0, 2, 1)
    gmsh.model.occ.synchronize()
    for _, tag in gmsh.model.getEntities(1):
        gmsh.model.mesh.setTransfiniteCurve(tag, 3)
    gmsh.model.mesh.setTransfiniteSurface(1)
    gmsh.model.mesh.setRecombine(2, 1)
    gmsh.model.mesh.generate(2)
    gmsh.model.mesh.setOrder(2)
    write("quad9_22.msh", 2.2, 0)


def cylinder_meshio():
    import meshio

    lines = open(os.path.join(ROOT, "meshes/real/mfem/cylinder-hex.mesh")).read().split("\n")
    lines = [l.strip() for l in lines]
    i = lines.index("elements")
    n = int(lines[i + 1])
    el = np.array([[int(x) for x in lines[i + 2 + k].split()] for k in range(n)])
    i = lines.index("vertices")
    nv = int(lines[i + 1])
    pts = np.array([[float(x) for x in lines[i + 3 + k].split()] for k in range(nv)])
    assert (el[:, 1] == 5).all()
    mesh = meshio.Mesh(
        pts,
        [("hexahedron", el[:, 2:])],
        cell_data={"gmsh:physical": [el[:, 0]], "gmsh:geometrical": [el[:, 0]]},
    )
    meshio.write(out("cylinder_meshio_41_bin.msh"), mesh, file_format="gmsh", binary=True)


gmsh.initialize()
gmsh.option.setNumber("General.Terminal", 0)
box()
ball()
tets()
quad9()
gmsh.finalize()
cylinder_meshio()
