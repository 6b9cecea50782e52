#!/usr/bin/env python3
"""Analytic shapes meshed by Gmsh, and the distance of a high-order mesh's boundary from them.

usage:
  fidelity_shapes.py make SHAPE LEVEL OUT_LINEAR.msh OUT_CAD_ORDER2.msh
      Builds SHAPE in Gmsh's OpenCASCADE kernel (so Gmsh knows the exact surface), meshes it
      linearly at refinement LEVEL (1 = coarsest; the mesh size halves per level) and writes the
      linear mesh, then Gmsh's own order-2 mesh of it (setOrder(2): high-order nodes on the CAD).
      Prints {"elements": N}.
  fidelity_shapes.py measure SHAPE [--only curved|all] FILE.msh [FILE.msh ...]
      Prints one JSON object per file: RMS and max distance of its boundary from the exact
      surface (relative to the bounding-box diagonal), sampled on a 9 x 9 (3D) or 17 (2D) lattice
      of parameter points per boundary side, and the number of boundary sides. With
      `--only curved`, only the points nearest to a curved part of the surface count (the hole
      of the plate, the side of the cylinder; every point of the other shapes).

  fidelity_shapes.py locate SHAPE FILE.msh [FILE.msh ...]
      Prints one JSON object per file: where its boundary error is (max and RMS per kind of
      lattice point, corner / edge midpoint / side midpoint or face centre / in between, for
      the sides that interpolate their corners and for the others) and the worst point.

Shapes (all with Gmsh 4.15's Python API; MSH 2.2 output):
  disk      O-grid disk of radius 1 (quads): a square block and four ring blocks, transfinite
  torus     O-grid torus (hexes): that disk, radius 0.5, revolved about the z axis at distance 1
  cylinder  O-grid cylinder of radius 1 and height 1 with flat caps (hexes, sharp rims)
  plate     2 x 2 plate with a hole of radius 0.5 (quads): frontal-Delaunay for quads,
            recombined, so many vertices are irregular
  ball      ball of radius 1: Gmsh tetrahedra subdivided into hexahedra (every boundary vertex
            of the subdivision is irregular somewhere)
"""
import json
import math
import sys

import numpy as np

SHAPES = ["disk", "torus", "cylinder", "plate", "ball"]
DIM = {"disk": 2, "torus": 3, "cylinder": 3, "plate": 2, "ball": 3}
# Exact volumes (areas in 2D).
VOLUME = {
    "disk": math.pi,
    "torus": 2.0 * math.pi**2 * 1.0 * 0.25,
    "cylinder": math.pi,
    "plate": 4.0 - math.pi * 0.25,
    "ball": 4.0 / 3.0 * math.pi,
}


def _ogrid_disk(kernel, cx, r, n, plane="xy"):
    """Five-block O-grid of the disk of radius r centred at (cx, 0, 0) in `plane` ("xy" or
    "xz"), n cells along each arc and ceil(n/2) across the ring, transfinite and recombined;
    returns its surfaces. `kernel` is gmsh.model.occ or gmsh.model.geo."""
    a = 0.5 * r

    def pt(u, v):
        return kernel.addPoint(cx + u, v, 0.0) if plane == "xy" else kernel.addPoint(cx + u, 0.0, v)

    c = pt(0.0, 0.0)
    corners = [(-a, -a), (a, -a), (a, a), (-a, a)]
    s = [pt(*p) for p in corners]
    q = [pt(r * x / (a * math.sqrt(2)), r * y / (a * math.sqrt(2))) for x, y in corners]
    inner = [kernel.addLine(s[k], s[(k + 1) % 4]) for k in range(4)]
    arcs = [kernel.addCircleArc(q[k], c, q[(k + 1) % 4]) for k in range(4)]
    spokes = [kernel.addLine(s[k], q[k]) for k in range(4)]
    surfs = [kernel.addPlaneSurface([kernel.addCurveLoop(inner)])]
    for k in range(4):
        loop = kernel.addCurveLoop([inner[k], spokes[(k + 1) % 4], -arcs[k], -spokes[k]])
        surfs.append(kernel.addPlaneSurface([loop]))
    m = max(1, (n + 1) // 2)
    for l in inner + arcs:
        kernel.mesh.setTransfiniteCurve(l, n + 1)
    for l in spokes:
        kernel.mesh.setTransfiniteCurve(l, m + 1)
    for sf in surfs:
        kernel.mesh.setTransfiniteSurface(sf)
        kernel.mesh.setRecombine(2, sf)
    return surfs


def build(shape, level):
    """Builds and meshes `shape` in the current Gmsh model; returns the mesh dimension."""
    import gmsh

    occ = gmsh.model.occ
    mesh = gmsh.model.mesh
    gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
    f = 2 ** (level - 1)
    if shape in ("disk", "cylinder", "torus"):
        # The built-in kernel: OpenCASCADE loses the structured layers of a full revolution.
        geo = gmsh.model.geo
        n = 4 * f if shape != "torus" else 2 * f
        r = 0.5 if shape == "torus" else 1.0
        cx = 1.0 if shape == "torus" else 0.0
        surfs = _ogrid_disk(geo, cx, r, n, "xz" if shape == "torus" else "xy")
        if shape == "cylinder":
            geo.extrude([(2, s) for s in surfs], 0, 0, 1.0, numElements=[n], recombine=True)
        elif shape == "torus":
            # Four quarter turns (the kernel revolves by less than π); each input surface
            # gives its top surface followed by its volume.
            cur = [(2, s) for s in surfs]
            for _ in range(4):
                out = geo.revolve(cur, 0, 0, 0, 0, 0, 1, math.pi / 2, numElements=[2 * n], recombine=True)
                cur = [out[i] for i in range(len(out) - 1) if out[i + 1][0] == 3]
            geo.removeAllDuplicates()
        geo.synchronize()
        dim = 2 if shape == "disk" else 3
    elif shape == "plate":
        rect = occ.addRectangle(-1, -1, 0, 2, 2)
        hole = occ.addDisk(0, 0, 0, 0.5, 0.5)
        occ.cut([(2, rect)], [(2, hole)])
        occ.synchronize()
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 1)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.25 / f)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.25 / f)
        dim = 2
    elif shape == "ball":
        occ.addSphere(0, 0, 0, 1.0)
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.4 / f)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.4 / f)
        gmsh.option.setNumber("Mesh.SubdivisionAlgorithm", 2)
        dim = 3
    else:
        raise SystemExit(f"unknown shape {shape}")
    gmsh.model.addPhysicalGroup(dim, [t for _, t in gmsh.model.getEntities(dim)], name="domain")
    mesh.generate(dim)
    return dim


def make(shape, level, linear_out, cad_out):
    import gmsh

    gmsh.initialize(["-nopopup"])
    gmsh.option.setNumber("General.Terminal", 0)
    dim = build(shape, level)
    n = 0
    for t in gmsh.model.mesh.getElementTypes(dim):
        n += len(gmsh.model.mesh.getElementsByType(t)[0])
    gmsh.write(linear_out)
    gmsh.model.mesh.setOrder(2)
    gmsh.write(cad_out)
    gmsh.finalize()
    return {"elements": n}


# ---------------------------------------------------------------- distance from the exact shape


def distance(shape, x):
    """Distance of points x (N x 3) from the boundary of the exact shape."""
    x = np.asarray(x, dtype=float)
    if shape == "disk":
        return np.abs(np.hypot(x[:, 0], x[:, 1]) - 1.0)
    if shape == "ball":
        return np.abs(np.linalg.norm(x, axis=1) - 1.0)
    if shape == "torus":
        rho = np.hypot(x[:, 0], x[:, 1]) - 1.0
        return np.abs(np.hypot(rho, x[:, 2]) - 0.5)
    if shape == "cylinder":
        rho, z = np.hypot(x[:, 0], x[:, 1]), x[:, 2]
        inside = (rho <= 1.0) & (z >= 0.0) & (z <= 1.0)
        d_in = np.minimum(1.0 - rho, np.minimum(z, 1.0 - z))
        dr = np.maximum(rho - 1.0, 0.0)
        dz = np.maximum(np.maximum(-z, z - 1.0), 0.0)
        return np.where(inside, d_in, np.hypot(dr, dz))
    if shape == "plate":
        r = np.hypot(x[:, 0], x[:, 1])
        d_hole = np.abs(r - 0.5)
        ax, ay = np.abs(x[:, 0]), np.abs(x[:, 1])
        inside = (ax <= 1.0) & (ay <= 1.0)
        d_in = np.minimum(1.0 - ax, 1.0 - ay)
        d_out = np.hypot(np.maximum(ax - 1.0, 0.0), np.maximum(ay - 1.0, 0.0))
        return np.minimum(d_hole, np.where(inside, d_in, d_out))
    raise SystemExit(f"unknown shape {shape}")


def boundary_points(path, dim, samples=None):
    """Points sampled on every boundary side of the elements of dimension `dim` in `path` (the
    file's own Lagrange map, via Gmsh's basis functions); also the bounding-box diagonal."""
    sides, diag = boundary_sides(path, dim, samples)
    return np.concatenate([x for _, x in sides]), diag, len(sides)


def boundary_sides(path, dim, samples=None):
    """Per boundary side of `path`: (element index, its sample points, in lattice order); and
    the bounding-box diagonal."""
    import gmsh

    gmsh.initialize(["-nopopup"])
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(path)
    pts = []
    tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = np.asarray(coords).reshape(-1, 3)
    index = {int(t): i for i, t in enumerate(tags)}
    lo, hi = coords.min(axis=0), coords.max(axis=0)
    for etype in gmsh.model.mesh.getElementTypes(dim):
        _, enodes = gmsh.model.mesh.getElementsByType(etype)
        props = gmsh.model.mesh.getElementProperties(etype)
        nn = props[3]
        conn = np.array([index[int(t)] for t in enodes]).reshape(-1, nn)
        ncorner = 4 if dim == 2 else 8
        # Gmsh's reference element is [-1, 1]^d; corner c at the signs of its reference point.
        ref = np.asarray(props[4]).reshape(nn, dim)[:ncorner]
        s = samples or (17 if dim == 2 else 9)
        t = np.linspace(-1.0, 1.0, s)
        local, side_of = [], []
        for k in range(dim):
            for sgn in (-1.0, 1.0):
                grid = np.meshgrid(*([t] * (dim - 1)), indexing="ij")
                u = np.zeros((t.size ** (dim - 1), 3))
                others = [j for j in range(dim) if j != k]
                u[:, k] = sgn
                for j, g in zip(others, grid):
                    u[:, j] = g.ravel()
                local.append(u)
                side_of.append((k, sgn))
        u = np.concatenate(local)
        _, basis, _ = gmsh.model.mesh.getBasisFunctions(etype, u.ravel().tolist(), "Lagrange")
        basis = np.asarray(basis).reshape(len(u), nn)
        x = np.einsum("pn,enc->epc", basis, coords[conn])
        per_side = t.size ** (dim - 1)
        keys = {}
        for e in range(len(conn)):
            for si, (k, sgn) in enumerate(side_of):
                key = tuple(sorted(conn[e, c] for c in range(ncorner) if abs(ref[c, k] - sgn) < 1e-9))
                keys.setdefault(key, []).append((e, si))
        for key, owners in keys.items():
            if len(owners) == 1:
                e, si = owners[0]
                pts.append((e, x[e, si * per_side : (si + 1) * per_side]))
    gmsh.finalize()
    return pts, float(np.linalg.norm(hi - lo))


def curved(shape, x):
    """Mask of the points x nearest to a curved part of the shape's boundary."""
    if shape == "plate":
        return np.abs(np.hypot(x[:, 0], x[:, 1]) - 0.5) < distance(shape, x) + 1e-3
    if shape == "cylinder":
        rho, z = np.hypot(x[:, 0], x[:, 1]), x[:, 2]
        return np.abs(rho - 1.0) < np.minimum(np.abs(z), np.abs(z - 1.0))
    return np.ones(len(x), dtype=bool)


def measure(shape, path, only="all"):
    dim = DIM[shape]
    x, diag, sides = boundary_points(path, dim)
    if only == "curved":
        x = x[curved(shape, x)]
    d = distance(shape, x) / diag
    return {"file": path, "rms": float(np.sqrt(np.mean(d * d))), "max": float(d.max()), "sides": sides}


def locate(shape, path):
    """Where the boundary error of `path` is: per kind of lattice point (c corners, e edge
    midpoints in 3D, m side midpoint (2D) or f face centre (3D), i in between), max and RMS,
    separately for sides that interpolate their corners (|d| < 1e-13 there: Gmsh-with-CAD and
    our Q2 elements) and the others (our spline elements); and the worst point."""
    dim = DIM[shape]
    s = 17 if dim == 2 else 9
    sides, diag = boundary_sides(path, dim, s)
    k1 = ["c"] + ["i"] * (s // 2 - 1) + ["m"] + ["i"] * (s // 2 - 1) + ["c"]
    if dim == 2:
        kind = np.array(k1)
    else:
        names = {"cc": "c", "cm": "e", "mc": "e", "mm": "f"}
        kind = np.array([names.get(a + b, "i") for a in k1 for b in k1])
    d = np.array([distance(shape, x) / diag for _, x in sides])
    interp = d[:, kind == "c"].max(axis=1) < 1e-13
    out = {"file": path, "sides": len(sides), "interpolating_sides": int(interp.sum())}
    for name, sel in (("interpolating", interp), ("other", ~interp)):
        if sel.any():
            out[name] = {
                k: {"max": float(d[sel][:, kind == k].max()), "rms": float(np.sqrt(np.mean(d[sel][:, kind == k] ** 2)))}
                for k in ("c", "e", "m", "f", "i") if (kind == k).any()
            }
    j, p = np.unravel_index(d.argmax(), d.shape)
    out["worst"] = {"element": int(sides[j][0]), "kind": str(kind[p]), "at": sides[j][1][p].round(4).tolist(),
                    "interpolating": bool(interp[j]), "distance": float(d[j, p])}
    return out


def main(argv):
    if len(argv) >= 5 and argv[0] == "make":
        print(json.dumps(make(argv[1], int(argv[2]), argv[3], argv[4])))
    elif len(argv) >= 3 and argv[0] == "measure":
        only, files = "all", argv[2:]
        if files[0] == "--only":
            only, files = files[1], files[2:]
        for p in files:
            print(json.dumps(measure(argv[1], p, only)))
    elif len(argv) >= 3 and argv[0] == "locate":
        for p in argv[2:]:
            print(json.dumps(locate(argv[1], p)))
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main(sys.argv[1:])
