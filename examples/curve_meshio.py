#!/usr/bin/env python3
"""Load a linear hex mesh with meshio, curve it at orders 2 and 3, print the quality from the
report, and write Gmsh files that PyFR imports (`pyfr import cone_p3.msh cone_p3.pyfrm`).

usage: python examples/curve_meshio.py [MESH.msh] [OUTDIR]
Needs the package (`pip install .[meshio]`, docs/python.md).
"""
import os
import sys

import meshio

import polyspline

here = os.path.dirname(os.path.abspath(__file__))
path = sys.argv[1] if len(sys.argv) > 1 else os.path.join(here, "..", "meshes", "generated", "block_hex8_8.msh")
outdir = sys.argv[2] if len(sys.argv) > 2 else "."

mesh = meshio.read(path)
for order in (2, 3):
    curved = polyspline.curve(mesh, order=order)
    r = curved.report
    print(f"order {order}: {len(curved.cells)} elements, {len(curved.points)} nodes, "
          f"min scaled Jacobian {r['min_scaled_jacobian']:.4f} (input {r['input_min_scaled_jacobian']:.4f}), "
          f"boundary deviation max {r['boundary_node_distance_max']:.2e}, {r['timings']['total']:.2f} s")
    # The volume group is named `fluid` (where the input names no region), as PyFR wants.
    out = os.path.join(outdir, f"{os.path.splitext(os.path.basename(path))[0]}_p{order}.msh")
    curved.write(out)
    print(f"wrote {out}")
