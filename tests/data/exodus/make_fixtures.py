"""Make the Exodus II reader fixtures with the netCDF4 Python library (netCDF-3 formats).

two_hex_classic.exo  CDF-1 (classic): 2 hexes in 2 blocks (ids 10, 20, named), HEX8,
                     coordx/coordy/coordz doubles, side sets 5 "xmin" and 7 "top".
quads_64bit.exo      CDF-2 (64-bit offset): 2D, combined `coord` variable of floats, a QUAD4
                     block (id 1) of 2 quads and a TRI3 block (id 2) of 2 triangles, one side
                     set (id 3, unnamed) with quad and triangle edges, and a record variable.
The script prints the values the unit tests check.
"""
import numpy as np
import netCDF4


def names_var(nc, var, dim, names):
    v = nc.createVariable(var, "S1", (dim, "len_name"))
    arr = np.zeros((len(names), 33), dtype="S1")
    for i, n in enumerate(names):
        arr[i, : len(n)] = list(n)
    v[:] = arr


def common(nc, title, dim, n_nodes, n_elem, n_blk, n_ss):
    nc.title = title
    nc.api_version = np.float32(8.03)
    nc.version = np.float32(8.03)
    nc.floating_point_word_size = np.int32(8)
    nc.file_size = np.int32(1)
    nc.createDimension("len_string", 33)
    nc.createDimension("len_name", 33)
    nc.createDimension("time_step", None)
    nc.createDimension("num_dim", dim)
    nc.createDimension("num_nodes", n_nodes)
    nc.createDimension("num_elem", n_elem)
    nc.createDimension("num_el_blk", n_blk)
    nc.createDimension("num_side_sets", n_ss)
    t = nc.createVariable("time_whole", "f8", ("time_step",))
    t[0:2] = [0.0, 1.0]


def block(nc, i, conn, elem_type):
    nc.createDimension(f"num_el_in_blk{i}", len(conn))
    nc.createDimension(f"num_nod_per_el{i}", len(conn[0]))
    v = nc.createVariable(f"connect{i}", "i4", (f"num_el_in_blk{i}", f"num_nod_per_el{i}"))
    v.elem_type = elem_type
    v[:] = np.array(conn) + 1


def side_set(nc, i, elems, sides):
    nc.createDimension(f"num_side_ss{i}", len(elems))
    nc.createVariable(f"elem_ss{i}", "i4", (f"num_side_ss{i}",))[:] = elems
    nc.createVariable(f"side_ss{i}", "i4", (f"num_side_ss{i}",))[:] = sides


# --- 2 hexes, classic ---
pts = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 0.5, 1.25)])
idx = lambda x, y, z: z * 6 + y * 3 + x
hexes = [[idx(i, 0, 0), idx(i + 1, 0, 0), idx(i + 1, 1, 0), idx(i, 1, 0),
          idx(i, 0, 1), idx(i + 1, 0, 1), idx(i + 1, 1, 1), idx(i, 1, 1)] for i in (0, 1)]
with netCDF4.Dataset("two_hex_classic.exo", "w", format="NETCDF3_CLASSIC") as nc:
    common(nc, "two hexes", 3, len(pts), 2, 2, 2)
    for k, name in enumerate(["coordx", "coordy", "coordz"]):
        nc.createVariable(name, "f8", ("num_nodes",))[:] = pts[:, k]
    nc.createVariable("eb_prop1", "i4", ("num_el_blk",))[:] = [10, 20]
    nc["eb_prop1"].setncattr("name", "ID")
    names_var(nc, "eb_names", "num_el_blk", ["left", "right"])
    block(nc, 1, hexes[:1], "HEX8")
    block(nc, 2, hexes[1:], "HEX")
    nc.createVariable("ss_prop1", "i4", ("num_side_sets",))[:] = [5, 7]
    names_var(nc, "ss_names", "num_side_sets", ["xmin", "top"])
    side_set(nc, 1, [1], [4])
    side_set(nc, 2, [1, 2], [6, 6])
hex_side = {4: [0, 4, 7, 3], 6: [4, 5, 6, 7]}
print("two_hex: points", pts.tolist())
print("  hexes", hexes)
print("  xmin facet", [hexes[0][i] for i in hex_side[4]],
      "top facets", [[h[i] for i in hex_side[6]] for h in hexes])

# --- quads and triangles in 2D, 64-bit offset ---
p2 = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1], [3, 0.5]], dtype=float)
quads = [[0, 1, 4, 3], [1, 2, 5, 4]]
tris = [[2, 6, 5], [0, 4, 3]]  # the second one overlaps: the reader does not judge
with netCDF4.Dataset("quads_64bit.exo", "w", format="NETCDF3_64BIT_OFFSET") as nc:
    common(nc, "quads and triangles", 2, len(p2), 4, 2, 1)
    nc.floating_point_word_size = np.int32(4)
    nc.createVariable("coord", "f4", ("num_dim", "num_nodes"))[:] = p2.T
    nc.createVariable("eb_prop1", "i4", ("num_el_blk",))[:] = [1, 2]
    block(nc, 1, quads, "QUAD4")
    block(nc, 2, tris, "TRI3")
    nc.createVariable("ss_prop1", "i4", ("num_side_sets",))[:] = [3]
    # quad 1 side 1 (bottom edge 0-1), quad 2 side 2 (right edge 2-5), triangle 3 side 2 (6-5)
    side_set(nc, 1, [1, 2, 3], [1, 2, 2])
print("quads: points", p2.tolist(), "quads", quads, "tris", tris)
print("  side edges", [[0, 1], [2, 5], [6, 5]])
