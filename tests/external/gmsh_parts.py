"""Gmsh's own view of partitioned MSH files, for tests/distributed.rs.

  gmsh_parts.py compare SERIAL PART_1 ... PART_N
      Opens SERIAL, then merges the parts into an empty model (how Gmsh reads split files)
      and prints JSON: node counts (all, distinct tags, the serial file's), how many tags
      appear twice with different coordinates, element counts by type in both, the largest
      distance between the nodes of the element with the same tag in both (node by node, in
      Gmsh's order), element tags missing on either side, the number of partitions, the
      physical groups (dim, tag, name, number of elements) of both, the smallest minDetJac
      of the merged mesh's volume elements, how many boundary facets are not in the part of
      an element they bound, and the serial mesh's bounding-box diagonal.
  gmsh_parts.py partition IN N OUT BINARY
      Opens IN, partitions it into N parts with Gmsh's partitioner and writes them as split
      MSH 4.1 files OUT_1 ... OUT_N (BINARY = 1: binary).
  gmsh_parts.py convert IN OUT
      Opens IN and writes it as one binary MSH 4.1 file OUT (what the ranks read by offsets).
"""

import json
import sys

import gmsh
import numpy as np


def elements_by_tag():
    """{element tag: (type, [node tags])} and counts by type name."""
    out = {}
    counts = {}
    types, tags, nodes = gmsh.model.mesh.getElements()
    for t, et, en in zip(types, tags, nodes):
        name = gmsh.model.mesh.getElementProperties(t)[0]
        counts[name] = counts.get(name, 0) + len(et)
        k = len(en) // max(len(et), 1)
        for i, tag in enumerate(et):
            out[int(tag)] = (int(t), en[i * k:(i + 1) * k])
    return out, counts


def coordinates():
    """{node tag: xyz} (the first occurrence), all tags, and tags seen with two positions."""
    tags, xyz, _ = gmsh.model.mesh.getNodes()
    xyz = xyz.reshape(-1, 3)
    seen = {}
    mismatch = 0
    for t, x in zip(tags, xyz):
        t = int(t)
        if t in seen:
            if not np.array_equal(seen[t], x):
                mismatch += 1
        else:
            seen[t] = x
    return seen, len(tags), mismatch


def groups():
    """(dim, tag, name, distinct elements) of every physical group."""
    out = []
    for dim, tag in gmsh.model.getPhysicalGroups():
        members = set()
        for e in set(int(e) for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)):
            _, et, _ = gmsh.model.mesh.getElements(dim, e)
            for x in et:
                members.update(int(t) for t in x)
        out.append([dim, tag, gmsh.model.getPhysicalName(dim, tag), len(members)])
    return sorted(out)


def compare(serial, parts):
    gmsh.open(serial)
    s_elems, s_counts = elements_by_tag()
    s_xyz, s_all, _ = coordinates()
    s_groups = groups()
    pts = np.array(list(s_xyz.values()))
    diag = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    gmsh.clear()
    for p in parts:
        gmsh.merge(p)
    elems, counts = elements_by_tag()
    xyz, n_all, mismatch = coordinates()
    worst = 0.0
    for tag, (t, nodes) in elems.items():
        if tag not in s_elems or s_elems[tag][0] != t:
            continue
        a = np.array([xyz[int(n)] for n in nodes])
        b = np.array([s_xyz[int(n)] for n in s_elems[tag][1]])
        worst = max(worst, float(np.linalg.norm(a - b, axis=1).max()))
    dim = gmsh.model.getDimension()
    # Each boundary facet in the part of an element it bounds: its nodes among the nodes of
    # that part's volume elements.
    part_nodes = {}
    for _, e in gmsh.model.getEntities(dim):
        for p in gmsh.model.getPartitions(dim, e):
            for en in gmsh.model.mesh.getElements(dim, e)[2]:
                part_nodes.setdefault(int(p), set()).update(int(n) for n in en)
    facets_off_part = 0
    for _, e in gmsh.model.getEntities(dim - 1):
        parts = gmsh.model.getPartitions(dim - 1, e)
        if len(parts) != 1:
            continue
        own = part_nodes.get(int(parts[0]), set())
        _, tags, nodes = gmsh.model.mesh.getElements(dim - 1, e)
        for t, ns in zip(tags, nodes):
            k = len(ns) // max(len(t), 1)
            facets_off_part += sum(
                not set(int(n) for n in ns[i * k:(i + 1) * k]) <= own for i in range(len(t))
            )
    min_det = float("inf")
    for t, et, _ in zip(*gmsh.model.mesh.getElements(dim)):
        if len(et):
            q = gmsh.model.mesh.getElementQualities(et, "minDetJac")
            min_det = min(min_det, float(q.min()))
    print(json.dumps({
        "nodes": n_all,
        "distinct_nodes": len(xyz),
        "serial_nodes": len(s_xyz),
        "mismatched_duplicates": mismatch,
        "counts": counts,
        "serial_counts": s_counts,
        "max_distance": worst,
        "missing": len(set(s_elems) - set(elems)),
        "extra": len(set(elems) - set(s_elems)),
        "partitions": gmsh.model.getNumberOfPartitions(),
        "groups": groups(),
        "serial_groups": s_groups,
        "min_det_jac": min_det,
        "facets_off_part": facets_off_part,
        "diagonal": diag,
    }))


def partition(src, n, out, binary):
    gmsh.open(src)
    gmsh.model.mesh.partition(n)
    gmsh.option.setNumber("Mesh.PartitionSplitMeshFiles", 1)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.Binary", binary)
    gmsh.write(out)


def main():
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    if sys.argv[1] == "compare":
        compare(sys.argv[2], sys.argv[3:])
    elif sys.argv[1] == "convert":
        gmsh.open(sys.argv[2])
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.option.setNumber("Mesh.Binary", 1)
        gmsh.write(sys.argv[3])
    else:
        partition(sys.argv[2], int(sys.argv[3]), sys.argv[4], int(sys.argv[5]))
    gmsh.finalize()


if __name__ == "__main__":
    main()
