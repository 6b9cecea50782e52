"""Make the Plot3D fixture: two 3x3x3 grids side by side, x in [0, 1] and [1, 2], y and z in
[0, 1], y bent by 0.05 sin(pi x) z, so the grids meet at the face x = 1 (imax of grid 1,
imin of grid 2). Multi-grid whole format, formatted (ASCII), i fastest.
"""
import numpy as np


def grid(x0, n=3):
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    x = x0 + i / (n - 1)
    y = j / (n - 1) + 0.05 * np.sin(np.pi * (x0 + i / (n - 1))) * (k / (n - 1))
    z = k / (n - 1)
    return [a.transpose(2, 1, 0).ravel() for a in (x, y, z)]


with open("two_blocks.xyz", "w") as f:
    f.write("2\n3 3 3\n3 3 3\n")
    for x0 in (0.0, 1.0):
        for a in grid(x0):
            f.write(" ".join(f"{v:.17g}" for v in a) + "\n")
