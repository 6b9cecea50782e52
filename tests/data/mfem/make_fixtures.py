"""Hand-written MFEM fixtures (no independent MFEM writer is installed; the files follow the
format description at mfem.org and mfem/mesh/mesh_readers.cpp). Run from this directory.

Mesh: two unit squares side by side, vertices 0..5 at (0,0) (1,0) (2,0) (0,1) (1,1) (2,1);
element attributes 1 and 2; boundary segments tagged 1 (bottom), 2 (right), 3 (top), 4 (left).
"""

verts = [(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (2, 1)]
# Higher-order dofs of an H1_2D_P2 space (7 edges, 2 interiors; the top edges are bent).
edges = [(0.5, 0), (1, 0.5), (0.5, 1.1), (0, 0.5), (1.5, 0), (2, 0.5), (1.5, 1.1)]
inner = [(0.5, 0.5), (1.5, 0.5)]
dofs = verts + edges + inner

topo = """
dimension
2

elements
2
1 3 0 1 4 3
2 3 1 2 5 4
"""
bdr = """
boundary
6
1 1 0 1
1 1 1 2
2 1 2 5
3 1 5 4
3 1 4 3
4 1 3 0
"""
# Both layouts of named sets: name on its own line (MFEM >= 4.8) and name, size, values on one.
sets_el = """
attribute_sets
1
"fluid" 2 1 2
"""
sets_bdr = """
bdr_attribute_sets
2
"left wall"
1
4
"walls" 2 1 3
"""


def nodes(ordering):
    s = """
vertices
6

nodes
FiniteElementSpace
FiniteElementCollection: H1_2D_P2
VDim: 2
Ordering: %d

""" % ordering
    if ordering == 1:  # byVDIM: x y per dof
        s += "".join("%g %g\n" % d for d in dofs)
    else:  # byNODES: all x, then all y
        s += "".join("%g\n" % d[0] for d in dofs) + "".join("%g\n" % d[1] for d in dofs)
    return s


linear = "MFEM mesh v1.0\n\n# two unit squares side by side\n" + topo + bdr + "\nvertices\n6\n2\n"
linear += "".join("%g %g\n" % v for v in verts)
open("two_quads.mesh", "w").write(linear)
for name, ordering in [("two_quads_q2_byvdim.mesh", 1), ("two_quads_q2_bynodes.mesh", 0)]:
    text = "MFEM mesh v1.3\n" + topo + sets_el + bdr + sets_bdr + nodes(ordering) + "\nmfem_mesh_end\n"
    open(name, "w").write(text)
