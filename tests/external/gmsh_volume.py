"""Gmsh set-up shared by the checkers of this folder: a Gmsh session, the volume elements of
a mesh file as Gmsh reads them, and Gmsh's determinants over a Gauss rule, signed in 2D.

Gmsh's own 2D determinant is the length of the cross product (never negative), so a quad's is
taken here from the first two rows of Gmsh's Jacobian matrix (dx/du dy/dv - dy/du dx/dv),
which is negative for a mirrored (clockwise) quad. Determinants are with respect to Gmsh's
reference element [-1,1]^d.
"""
import contextlib

import gmsh
import numpy as np


@contextlib.contextmanager
def session():
    """An initialised, quiet Gmsh, finalised on leaving."""
    gmsh.initialize(["-nopopup"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        yield
    finally:
        gmsh.finalize()


class Volume:
    """The volume elements (quads in 2D, hexes in 3D) of the file `path`, opened in the
    current session: `dim`, `etype`, `name`, `order`, `nnodes`, `ref` (the reference
    coordinates of the primary nodes), `nprim`, `tags` (element tags in file order), `conn`
    (node tags, one row per element) and `coords(rows)` (node coordinates of node tags)."""

    def __init__(self, path):
        gmsh.clear()
        gmsh.open(path)
        self.dim = gmsh.model.getDimension()
        types, tags, node_tags = gmsh.model.mesh.getElements(self.dim)
        assert len(types) == 1, "one volume element type expected"
        self.etype = types[0]
        name, _, order, nnodes, ref, nprim = gmsh.model.mesh.getElementProperties(self.etype)
        self.name, self.order, self.nnodes, self.nprim = name, int(order), nnodes, nprim
        self.ref = np.array(ref).reshape(-1, self.dim)[:nprim]
        self.tags = tags[0]
        self.conn = np.array(node_tags[0], dtype=np.int64).reshape(-1, nnodes)
        all_tags, xyz, _ = gmsh.model.mesh.getNodes()
        all_tags = np.asarray(all_tags, dtype=np.int64)
        self._where = np.zeros(int(all_tags.max()) + 1, dtype=np.int64)
        self._where[all_tags] = np.arange(len(all_tags))
        self._xyz = np.asarray(xyz).reshape(-1, 3)

    def coords(self, node_tags):
        """Coordinates of `node_tags` (any shape), one more axis of 3."""
        return self._xyz[self._where[np.asarray(node_tags, dtype=np.int64)]]

    def local(self, points):
        """Points given in [-1,1]^k (k <= 3) as Gmsh's flat list of 3D local coordinates."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        out = np.zeros((len(points), 3))
        out[:, :points.shape[1]] = points
        return out.ravel()

    def signed(self, jacs, dets):
        """Gmsh's determinants, with the sign of the in-plane Jacobian in 2D."""
        if self.dim == 3:
            return np.asarray(dets)
        j = np.asarray(jacs).reshape(-1, 9)
        return j[:, 0] * j[:, 4] - j[:, 1] * j[:, 3]

    def gauss_dets(self, signed=True):
        """det J of every element at the points of a Gauss rule of degree 2p+2, signed (or, with
        `signed=False`, Gmsh's own, unsigned in 2D): [element][point]."""
        loc, _ = gmsh.model.mesh.getIntegrationPoints(self.etype, "Gauss%d" % (2 * self.order + 2))
        jacs, dets, _ = gmsh.model.mesh.getJacobians(self.etype, loc)
        dets = self.signed(jacs, dets) if signed else np.asarray(dets)
        return dets.reshape(len(self.tags), -1)
