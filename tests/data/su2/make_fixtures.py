"""SU2 fixtures written by meshio (an independent writer). Run from this directory."""
import meshio
import numpy as np

# meshio 5.3.5's SU2 writer unpacks cell blocks as (type, data) pairs; make them iterable.
meshio.CellBlock.__iter__ = lambda self: iter((self.type, self.data))

# 2x2x2 block of hexes on [0,1]^3, the 24 boundary quads tagged by side 1..6 (one marker each).
n = 3
grid = np.array([[i / 2, j / 2, k / 2] for k in range(n) for j in range(n) for i in range(n)])
idx = lambda i, j, k: i + n * j + n * n * k
hexes = []
for k in range(2):
    for j in range(2):
        for i in range(2):
            hexes.append([idx(i, j, k), idx(i + 1, j, k), idx(i + 1, j + 1, k), idx(i, j + 1, k),
                          idx(i, j, k + 1), idx(i + 1, j, k + 1), idx(i + 1, j + 1, k + 1), idx(i, j + 1, k + 1)])
quads, qtags = [], []
for a in range(2):
    for b in range(2):
        quads += [[idx(0, a, b), idx(0, a + 1, b), idx(0, a + 1, b + 1), idx(0, a, b + 1)],
                  [idx(2, a, b), idx(2, a + 1, b), idx(2, a + 1, b + 1), idx(2, a, b + 1)],
                  [idx(a, 0, b), idx(a + 1, 0, b), idx(a + 1, 0, b + 1), idx(a, 0, b + 1)],
                  [idx(a, 2, b), idx(a + 1, 2, b), idx(a + 1, 2, b + 1), idx(a, 2, b + 1)],
                  [idx(a, b, 0), idx(a + 1, b, 0), idx(a + 1, b + 1, 0), idx(a, b + 1, 0)],
                  [idx(a, b, 2), idx(a + 1, b, 2), idx(a + 1, b + 1, 2), idx(a, b + 1, 2)]]
        qtags += [1, 2, 3, 4, 5, 6]
meshio.write(
    "meshio_hexes.su2",
    meshio.Mesh(grid, [("hexahedron", hexes), ("quad", quads)],
                cell_data={"su2:tag": [[0] * 8, qtags]}),
    file_format="su2",
)

# 2D: two quads and a triangle, three boundary lines with two tags.
pts = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1], [3, 0.5]], dtype=float)
meshio.write(
    "meshio_mixed2d.su2",
    meshio.Mesh(pts, [("quad", [[0, 1, 4, 3], [1, 2, 5, 4]]), ("triangle", [[2, 6, 5]]),
                      ("line", [[0, 1], [1, 2], [3, 0]])],
                cell_data={"su2:tag": [[0, 0], [0], [7, 7, 8]]}),
    file_format="su2",
)
