"""Medit fixtures written by meshio (an independent writer). Run from this directory."""
import meshio
import numpy as np

# Mixed cells: one unit hex, a prism and a tet beside it, a pyramid on top, tagged faces.
pts = np.array(
    [
        [0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
        [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1],
        [2, 0, 0], [2, 0, 1], [2, 1, 0], [2, 1, 1],
    ],
    dtype=float,
)
cells = [
    ("hexahedron", [[0, 1, 2, 3, 4, 5, 6, 7]]),
    ("wedge", [[1, 8, 2, 5, 9, 6]]),
    ("tetra", [[8, 10, 2, 9]]),
    ("pyramid", [[4, 5, 6, 7, 11]]),
    ("quad", [[0, 3, 2, 1], [4, 5, 6, 7]]),
    ("triangle", [[1, 8, 9]]),
]
refs = [[3], [4], [5], [6], [21, 22], [23]]
meshio.write(
    "meshio_mixed.mesh",
    meshio.Mesh(pts, cells, cell_data={"medit:ref": refs}),
    file_format="medit",
)

# A 2x2x2 block of hexes on [0,1]^3 with all 24 boundary quads tagged by side (1..6).
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
    "meshio_hexes.mesh",
    meshio.Mesh(grid, [("hexahedron", hexes), ("quad", quads)],
                cell_data={"medit:ref": [[7] * 8, qtags]}),
    file_format="medit",
)
