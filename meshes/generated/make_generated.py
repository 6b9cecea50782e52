#!/usr/bin/env python3
"""Write the small generated test meshes of this folder as Gmsh MSH 2.2 ASCII files.

Names follow <shape>_<element><nodes>_<count>.msh. Boundary lines (2D) and quads (3D) carry
physical groups with names, so readers and boundary tagging are exercised too.
Run from this folder: python3 make_generated.py
"""
import math


def write_msh(path, dim, points, cells, boundary, names):
    """points: [(x,y,z)], cells: [[v..]] 0-based, boundary: [(tag, [v..])], names: {tag: name}."""
    cell_type = 3 if dim == 2 else 5
    facet_type = 1 if dim == 2 else 3
    vol_tag = max(names) + 1
    with open(path, "w") as f:
        f.write("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n")
        f.write("$PhysicalNames\n%d\n" % (len(names) + 1))
        for t, n in sorted(names.items()):
            f.write('%d %d "%s"\n' % (dim - 1, t, n))
        f.write('%d %d "domain"\n' % (dim, vol_tag))
        f.write("$EndPhysicalNames\n$Nodes\n%d\n" % len(points))
        for i, p in enumerate(points):
            f.write("%d %.17g %.17g %.17g\n" % (i + 1, p[0], p[1], p[2]))
        f.write("$EndNodes\n$Elements\n%d\n" % (len(boundary) + len(cells)))
        k = 1
        for t, vs in boundary:
            f.write("%d %d 2 %d %d %s\n" % (k, facet_type, t, t, " ".join(str(v + 1) for v in vs)))
            k += 1
        for vs in cells:
            f.write("%d %d 2 %d %d %s\n" % (k, cell_type, vol_tag, vol_tag, " ".join(str(v + 1) for v in vs)))
            k += 1
        f.write("$EndElements\n")


def grid2(nx, ny, keep=lambda i, j: True):
    pid = lambda i, j: j * (nx + 1) + i
    pts = [(float(i), float(j), 0.0) for j in range(ny + 1) for i in range(nx + 1)]
    cells = [[pid(i, j), pid(i + 1, j), pid(i + 1, j + 1), pid(i, j + 1)]
             for j in range(ny) for i in range(nx) if keep(i, j)]
    return pts, cells


def boundary_edges(cells):
    count = {}
    for c in cells:
        for a, b in zip(c, c[1:] + c[:1]):
            count.setdefault(tuple(sorted((a, b))), []).append((a, b))
    return [v[0] for v in count.values() if len(v) == 1]


def compact(pts, cells):
    used = sorted({v for c in cells for v in c})
    m = {v: i for i, v in enumerate(used)}
    return [pts[v] for v in used], [[m[v] for v in c] for c in cells]


def main():
    # 3x3 uniform grid on [0,3]^2, sides tagged left/right/bottom/top.
    pts, cells = grid2(3, 3)
    side = lambda a, b: (1 if pts[a][0] == 0 and pts[b][0] == 0 else
                         2 if pts[a][0] == 3 and pts[b][0] == 3 else
                         3 if pts[a][1] == 0 and pts[b][1] == 0 else 4)
    bnd = [(side(a, b), [a, b]) for a, b in boundary_edges(cells)]
    write_msh("grid_quad4_9.msh", 2, pts, cells, bnd, {1: "left", 2: "right", 3: "bottom", 4: "top"})

    # L-shape: 4x4 square without its top-right 2x2 quarter; re-entrant corner at (2,2).
    pts, cells = grid2(4, 4, keep=lambda i, j: not (i >= 2 and j >= 2))
    pts, cells = compact(pts, cells)
    bnd = [(1, [a, b]) for a, b in boundary_edges(cells)]
    write_msh("lshape_quad4_12.msh", 2, pts, cells, bnd, {1: "wall"})

    # Stars: a centre vertex with k quads around it and a ring of 3k quads (valence 3 and 5).
    for k in (3, 5):
        w = 2 * math.pi / k
        polar = lambda r, t: (r * math.cos(t), r * math.sin(t), 0.0)
        pts = [(0.0, 0.0, 0.0)]
        for i in range(k):
            t = i * w
            pts += [polar(1.0, t), polar(1.4, t + w / 2), polar(2.5, t), polar(2.6, t + w / 4),
                    polar(3.0, t + w / 2), polar(2.6, t + 3 * w / 4)]
        v = lambda i, s: 1 + 6 * (i % k) + s
        cells = []
        for i in range(k):
            j = i + 1
            cells += [[0, v(i, 0), v(i, 1), v(j, 0)], [v(i, 0), v(i, 2), v(i, 3), v(i, 1)],
                      [v(i, 1), v(i, 3), v(i, 4), v(i, 5)], [v(i, 1), v(i, 5), v(j, 2), v(j, 0)]]
        bnd = [(1, [a, b]) for a, b in boundary_edges(cells)]
        write_msh("star%d_quad4_%d.msh" % (k, 4 * k), 2, pts, cells, bnd, {1: "outer"})

    # 2x2x2 hex block on [0,2]^3, the six sides tagged.
    n = 2
    pid = lambda i, j, l: (l * (n + 1) + j) * (n + 1) + i
    pts = [(float(i), float(j), float(l)) for l in range(n + 1) for j in range(n + 1) for i in range(n + 1)]
    cells = [[pid(i, j, l), pid(i + 1, j, l), pid(i + 1, j + 1, l), pid(i, j + 1, l),
              pid(i, j, l + 1), pid(i + 1, j, l + 1), pid(i + 1, j + 1, l + 1), pid(i, j + 1, l + 1)]
             for l in range(n) for j in range(n) for i in range(n)]
    bnd = []
    for a in range(3):
        for s, at in enumerate((0, n)):
            for u in range(n):
                for w_ in range(n):
                    def p(du, dw):
                        ijk = [0, 0, 0]
                        ijk[a], ijk[(a + 1) % 3], ijk[(a + 2) % 3] = at, u + du, w_ + dw
                        return pid(*ijk)
                    bnd.append((2 * a + s + 1, [p(0, 0), p(1, 0), p(1, 1), p(0, 1)]))
    names = {1: "xmin", 2: "xmax", 3: "ymin", 4: "ymax", 5: "zmin", 6: "zmax"}
    write_msh("block_hex8_8.msh", 3, pts, cells, bnd, names)


if __name__ == "__main__":
    main()
