"""Independent checks of polyspline's CGNS and Abaqus output, with Gmsh as the oracle.

    formats_check.py cgns OUT.cgns REF.msh   Gmsh reads both files (its CGNS reader converts CGNS
                                             node order to its own); prints JSON with, per
                                             dimension, the element count, the largest distance
                                             between the nodes of matching elements (matched by
                                             centroid, compared slot by slot in Gmsh order),
                                             Gmsh's min/max det J of the volume elements, and
                                             the physical group and entity names.
    formats_check.py inp OUT.inp REF.msh     Gmsh writes REF.msh as Abaqus itself (its own
                                             C3D27/M3D9 node order); both .inp files are parsed
                                             the way Trixi.jl's standard-Abaqus reader parses
                                             them (one element a line split at ", ", node sets
                                             `*NSET,NSET=` with a trailing comma a line); prints
                                             the largest slot-by-slot node distance between
                                             matching elements and the node sets found.
    formats_check.py abaqus REF.msh OUT.inp  Gmsh writes REF.msh as Abaqus (its own export, the
                                             oracle for our Abaqus reader); prints JSON with the
                                             element count per dimension it saw.
"""
import json
import re
import sys
import tempfile

import gmsh
import numpy as np


def elements_of(path, dim):
    """Per element of dimension `dim`: its nodes' coordinates in Gmsh order."""
    gmsh.clear()
    gmsh.open(path)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    pos = dict(zip(tags, coords.reshape(-1, 3)))
    out = []
    det = [np.inf, -np.inf]
    types, etags, enodes = gmsh.model.mesh.getElements(dim)
    for t, et, en in zip(types, etags, enodes):
        n = len(en) // len(et)
        for k in range(len(et)):
            out.append(np.array([pos[x] for x in en[k * n:(k + 1) * n]]))
        if dim == gmsh.model.getDimension():
            q = gmsh.model.mesh.getElementQualities(et, "minDetJac")
            Q = gmsh.model.mesh.getElementQualities(et, "maxDetJac")
            det = [min(det[0], float(q.min())), max(det[1], float(Q.max()))]
    names = sorted(gmsh.model.getPhysicalName(d, t) for d, t in gmsh.model.getPhysicalGroups())
    entities = sorted({gmsh.model.getEntityName(d, t) for d, t in gmsh.model.getEntities()} - {""})
    return out, det, names, entities


def largest_gap(a, b):
    """Largest slot-by-slot distance between elements of `a` and `b` matched by centroid."""
    if len(a) != len(b):
        return float("inf")
    key = lambda e: tuple(np.round(e.mean(axis=0), 9))
    bb = {key(e): e for e in b}
    gap = 0.0
    for e in a:
        f = bb.get(key(e))
        if f is None or f.shape != e.shape:
            return float("inf")
        gap = max(gap, float(np.abs(e - f).max()))
    return gap


def cgns(out, ref):
    gmsh.open(ref)
    dim = gmsh.model.getDimension()
    result = {}
    for d in (dim, dim - 1):
        a, det, names, entities = elements_of(out, d)
        b = elements_of(ref, d)[0]
        result[str(d)] = {"count": len(a), "ref_count": len(b), "gap": largest_gap(a, b)}
        if d == dim:
            result["min_det_jac"], result["max_det_jac"] = det
            result["names"] = names
            result["entities"] = entities
    print(json.dumps(result))


def parse_inp(path, continued=False):
    """Elements (node coordinates per slot) and node sets, as Trixi.jl reads them (or, with
    `continued`, element lines continued after a trailing comma, as Gmsh writes them)."""
    lines = [l.rstrip() for l in open(path).read().splitlines()]
    if continued:
        joined = []
        for line in lines:
            if joined and joined[-1].endswith(",") and not joined[-1].startswith("*") \
                    and not line.startswith("*") and "E L E M" not in joined[-1]:
                joined[-1] += " " + line
            else:
                joined.append(line)
        lines = [l.rstrip(",") if not l.startswith("*") else l for l in joined]
    nodes, elements, sets = {}, [], {}
    kind = "C3D27" if any("TYPE=C3D27" in l.upper() for l in lines) else "M3D9"
    section, current = None, None
    start = lines.index("******* E L E M E N T S *************")
    for i, line in enumerate(lines):
        if line.startswith("*"):
            section = line.upper()
            current = None
            m = re.match(r"\*NSET,NSET=(.+)$", line)
            if m:
                current = m.group(1)
                sets[current] = set()
            continue
        if section == "*NODE" and i < start:
            parts = line.split(",")
            nodes[int(parts[0])] = np.array([float(x) for x in parts[1:4]])
        elif section and section.startswith("*ELEMENT") and re.search(f"TYPE={kind}", section):
            ids = [int(x) for x in re.split(r",\s+", line)]
            elements.append(ids[1:])
        elif current is not None and not continued:
            fields = line.split(",")
            assert fields[-1] == "", f"{path}: node set line without a trailing comma"
            sets[current].update(int(x) for x in fields[:-1])
    coords = [np.array([nodes[n] for n in e]) for e in elements]
    return coords, sets


def inp(out, ref):
    tmp = tempfile.mkdtemp()
    gmsh.open(ref)
    gmsh.write(f"{tmp}/ref.inp")
    a, sets = parse_inp(out)
    b, _ = parse_inp(f"{tmp}/ref.inp", continued=True)
    print(json.dumps({"count": len(a), "ref_count": len(b), "gap": largest_gap(a, b),
                      "sets": {k: len(v) for k, v in sets.items()}}))


def abaqus(ref, out):
    gmsh.open(ref)
    counts = {str(d): sum(len(t) for t in gmsh.model.mesh.getElements(d)[1]) for d in (1, 2, 3)}
    gmsh.write(out)
    print(json.dumps(counts))


gmsh.initialize()
gmsh.option.setNumber("General.Terminal", 0)
{"cgns": cgns, "inp": inp, "abaqus": abaqus}[sys.argv[1]](sys.argv[2], sys.argv[3])
gmsh.finalize()
