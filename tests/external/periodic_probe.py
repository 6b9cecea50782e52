#!/usr/bin/env python3
"""Periodic pairs of a high-order quad/hex MSH file, as Gmsh reads them.

usage: periodic_probe.py FILE.msh [STRAIGHT.msh]
Prints one JSON object:
  "diagonal": bounding-box diagonal of the nodes,
  "links": per boundary entity that Gmsh reports periodic (getPeriodicNodes with high-order
      nodes): {"entity", "master", "name", "master_name", "pairs", "entity_nodes",
      "unpaired" (nodes of the entity's elements without a pair), "affine" (16 numbers),
      "max_mismatch" (largest |A x_master - x_image|, absolute)},
  "seam_facets", "seam_angle_max", "seam_angle_mean": the angle in degrees, at the centre of
      each facet on an image side, between the derivative transversal to it of the element on
      the image side and that of the element on the master side carried over by the affine
      map's linear part (0 = C¹ across the seam),
  "interior_angle_max", "interior_angle_p99", "interior_angle_mean": the same across the
      interior facets.
With STRAIGHT (the straight-sided mesh of the same input, same elements in the same order):
  "regular_seam_facets", "regular_seam_angle_mean", "regular_interior_angle_mean",
  "regular_seam_input_angle_mean": the means over the facets where the input's grid is regular,
      the angle across the facet in STRAIGHT below REGULAR_DEG (the input's own kinks, which
      a curved mesh may keep where it holds the fit back, left out), and the input's mean
      over those seam facets; "min_scaled_jacobian", "straight_min_scaled_jacobian": the
      smallest scaled Jacobian det J / (|dx/du| |dx/dv| [|dx/dw|]) over the elements of FILE
      and of STRAIGHT, from Gmsh's Jacobians on a lattice of 2p + 1 points per direction
      (corners included: a straight quad's smallest sine of its corner angles).
Derivatives come from Gmsh's getJacobians at the reference facet centres; facets are matched
by their corner node tags (image corners mapped to their masters).
"""
import json
import sys

import gmsh
import numpy as np

REGULAR_DEG = 10.0


def measure(path):
    gmsh.open(path)
    dim = gmsh.model.getDimension()
    tags, coords, _ = gmsh.model.mesh.getNodes()
    coords = np.array(coords).reshape(-1, 3)
    pos = {int(t): coords[i] for i, t in enumerate(tags)}
    diagonal = float(np.linalg.norm(coords.max(axis=0) - coords.min(axis=0)))
    names = {}
    for d, p in gmsh.model.getPhysicalGroups(dim - 1):
        for ent in gmsh.model.getEntitiesForPhysicalGroup(d, p):
            names[int(ent)] = gmsh.model.getPhysicalName(d, p)
    links = []
    to_master = {}
    for _, ent in gmsh.model.getEntities(dim - 1):
        master, nodes, mnodes, affine = gmsh.model.mesh.getPeriodicNodes(dim - 1, ent, True)
        if master == ent or len(nodes) == 0:
            continue
        a = np.array(affine).reshape(4, 4)
        worst = 0.0
        for s, m in zip(nodes, mnodes):
            x = a[:3, :3] @ pos[int(m)] + a[:3, 3]
            worst = max(worst, float(np.linalg.norm(x - pos[int(s)])))
            to_master[int(s)] = (int(m), a[:3, :3])
        _, _, enodes = gmsh.model.mesh.getElements(dim - 1, ent)
        own = {int(n) for block in enodes for n in block}
        links.append({
            "entity": int(ent),
            "master": int(master),
            "name": names.get(int(ent), ""),
            "master_name": names.get(int(master), ""),
            "pairs": len(nodes),
            "entity_nodes": len(own),
            "unpaired": len(own - {int(n) for n in nodes}),
            "affine": [float(v) for v in affine],
            "max_mismatch": worst,
        })
    # Facet angles, interior and across the seams.
    types, etags, node_tags = gmsh.model.mesh.getElements(dim)
    etype = types[0]
    _, _, _, nnodes, ref, nprim = gmsh.model.mesh.getElementProperties(etype)
    ref = np.array(ref).reshape(-1, dim)[:nprim]
    conn = np.array(node_tags[0], dtype=np.int64).reshape(-1, nnodes)
    ne = conn.shape[0]
    facets = []
    for k in range(dim):
        for s in (-1.0, 1.0):
            corners = [i for i in range(nprim) if abs(ref[i][k] - s) < 1e-12]
            centre = [0.0, 0.0, 0.0]
            centre[k] = s
            facets.append((k, s, corners, centre))
    loc = [c for f in facets for c in f[3]]
    jac, _, _ = gmsh.model.mesh.getJacobians(etype, loc)
    jac = np.array(jac).reshape(ne, len(facets), 3, 3)

    def angle(d0, d):
        c = np.dot(d0, -d) / (np.linalg.norm(d0) * np.linalg.norm(d))
        return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))

    seen = {}
    image_facets = []
    interior = []
    interior_at = []
    for e in range(ne):
        for fi, (k, s, corners, _) in enumerate(facets):
            ids = [int(conn[e][c]) for c in corners]
            d = s * jac[e, fi, k, :]
            key = tuple(sorted(ids))
            if all(i in to_master for i in ids):
                r = to_master[ids[0]][1]
                image_facets.append((tuple(sorted(to_master[i][0] for i in ids)), r.T @ d, (e, fi)))
            if key in seen:
                interior.append(angle(seen.pop(key), d))
                interior_at.append((e, fi))
            else:
                seen[key] = d
    seam_at = [(key, at) for key, _, at in image_facets if key in seen]
    seam = [angle(seen[key], d) for key, d, _ in image_facets if key in seen]
    interior = np.array(interior) if interior else np.zeros(1)
    # Keyed by (element, facet): the straight mesh has the same elements in the same order.
    by_facet = {
        "seam": dict(zip((at for _, at in seam_at), seam)),
        "interior": dict(zip(interior_at, interior.tolist())),
    }
    return {
        "by_facet": by_facet,
        "file": path,
        "diagonal": diagonal,
        "links": links,
        "seam_facets": len(seam),
        "seam_angle_max": max(seam) if seam else 0.0,
        "seam_angle_mean": float(np.mean(seam)) if seam else 0.0,
        "interior_angle_max": float(interior.max()),
        "interior_angle_p99": float(np.percentile(interior, 99)),
        "interior_angle_mean": float(np.mean(interior)),
    }


def min_scaled_jacobian():
    """The smallest scaled Jacobian of the current model's volume elements on a lattice of
    2p + 1 points per reference direction."""
    dim = gmsh.model.getDimension()
    worst = np.inf
    for etype in gmsh.model.mesh.getElementTypes(dim):
        order = gmsh.model.mesh.getElementProperties(etype)[2]
        t = np.linspace(-1.0, 1.0, 2 * order + 1)
        grid = np.meshgrid(*([t] * dim), indexing="ij")
        pts = np.zeros((grid[0].size, 3))
        for k in range(dim):
            pts[:, k] = grid[k].ravel()
        jac, _, _ = gmsh.model.mesh.getJacobians(etype, pts.ravel().tolist())
        # Per element and point, row k: d x / d u_k.
        jac = np.array(jac).reshape(-1, len(pts), 3, 3)[:, :, :dim, :dim]
        det = np.linalg.det(jac)
        norms = np.prod(np.linalg.norm(jac, axis=3), axis=2)
        worst = min(worst, float(np.min(det / norms)))
    return worst


def main():
    gmsh.initialize(["-nopopup"])
    gmsh.option.setNumber("General.Terminal", 0)
    # Gmsh skips the MSH 2.2 periodic section unless told otherwise.
    gmsh.option.setNumber("Mesh.IgnorePeriodicity", 0)
    out = measure(sys.argv[1])
    curved = out.pop("by_facet")
    if len(sys.argv) > 2:
        out["min_scaled_jacobian"] = min_scaled_jacobian()
        gmsh.clear()
        straight = measure(sys.argv[2]).pop("by_facet")
        out["straight_min_scaled_jacobian"] = min_scaled_jacobian()
        for what in ("seam", "interior"):
            regular = [f for f, a in straight[what].items() if a < REGULAR_DEG]
            if not regular or any(f not in curved[what] for f in regular):
                sys.exit(f"{sys.argv[2]}: its {what} facets are not those of {sys.argv[1]}")
            out[f"regular_{what}_angle_mean"] = float(np.mean([curved[what][f] for f in regular]))
            if what == "seam":
                out["regular_seam_facets"] = len(regular)
                out["regular_seam_input_angle_mean"] = float(
                    np.mean([straight[what][f] for f in regular])
                )
    gmsh.finalize()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
