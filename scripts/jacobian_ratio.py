#!/usr/bin/env python3
"""Jacobian ratio (min det J / max det J per element, Gmsh's Bézier bounds) of MSH files.

Usage: jacobian_ratio.py FILE.msh [FILE.msh ...]
Prints one JSON object per file: elements, min, p1 (1st percentile), p50, and the worst
elements (index in file order, ratio, centroid). Gmsh's minDetJac/maxDetJac are bounds from
its Bézier expansion of det J; planar 2D elements may carry Gmsh's sign convention, so an
element whose bounds are both negative is measured as |max| / |min|.
"""
import json
import sys

import gmsh
import numpy as np


def ratio_from_bounds(lo, hi):
    """Per-element ratio min det J / max det J from Gmsh's bounds; both negative (Gmsh's sign
    convention for planar elements) gives |max| / |min|. A ratio <= 0 is an invalid element."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return np.where(hi < 0, hi / np.where(lo == 0, -1e-300, lo), lo / np.where(hi == 0, 1e-300, hi))


def model_ratios():
    """Element tags and ratios of the highest-dimensional elements of the current Gmsh model."""
    dim = max(d for d, _ in gmsh.model.getEntities())
    tags = []
    for t in gmsh.model.mesh.getElementTypes(dim):
        et, _ = gmsh.model.mesh.getElementsByType(t)
        tags.extend(int(x) for x in et)
    tags = np.array(tags, dtype=np.uint64)
    lo = gmsh.model.mesh.getElementQualities(tags, "minDetJac")
    hi = gmsh.model.mesh.getElementQualities(tags, "maxDetJac")
    return dim, tags, ratio_from_bounds(lo, hi)


def ratios(path):
    gmsh.initialize(["-nopopup"])
    gmsh.option.setNumber("General.Terminal", 0)
    try:
        gmsh.open(path)
        dim, tags, r = model_ratios()
        order = np.argsort(r)
        worst = []
        for i in order[:5]:
            _, nodes, _, _ = gmsh.model.mesh.getElement(int(tags[i]))
            xyz = np.array([gmsh.model.mesh.getNode(int(n))[0] for n in nodes[: 4 if dim == 2 else 8]])
            worst.append({"element": int(i), "ratio": float(r[i]), "centroid": xyz.mean(axis=0).tolist()})
        return {
            "file": path,
            "elements": int(len(r)),
            "min": float(r.min()),
            "p1": float(np.percentile(r, 1)),
            "p50": float(np.percentile(r, 50)),
            "worst": worst,
        }
    finally:
        gmsh.finalize()


if __name__ == "__main__":
    for p in sys.argv[1:]:
        print(json.dumps(ratios(p)))
