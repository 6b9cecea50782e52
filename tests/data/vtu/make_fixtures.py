"""Write the VTK XML UnstructuredGrid (.vtu) test fixtures in this directory.

Run from this directory: `python3 make_fixtures.py` (needs meshio, numpy and vtk; see tests/requirements.txt).

All files hold the mesh of ../vtk/make_fixtures.py: a 2x2x2 block of 8 hexahedra, 4 quads on
its bottom face and 1 vertex cell, with cell data `gmsh:physical` (hexes 1,1,1,1,2,2,2,2;
quads 10,10,11,11; vertex 5). meshio writes the ASCII, inline-binary (header and data in one
base64 stream) and zlib (header and blocks encoded separately) variants; `write_vtu` below
writes the variants meshio cannot: appended raw and appended base64 data, UInt64 headers,
big-endian data, small compression blocks, an <InformationKey> inside a DataArray, and two
pieces. VTK 9.7 itself writes `block_vtk97_*` (`write_with_vtk`).
"""

import base64
import json
import os
import re
import sys
import zlib

import meshio
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "vtk"))
from make_fixtures import (  # noqa: E402
    block_mesh,
    lagrange_grid,
    meshio_block,
    vtk_block_grid,
    vtk_cell_ids,
)


def encode_array(data, header_type, compression, block_size, b64, endian):
    """The bytes VTK stores for one binary array: header then (compressed) data."""
    hdt = np.dtype(endian + {"UInt32": "u4", "UInt64": "u8"}[header_type])
    raw = data.astype(data.dtype.newbyteorder(endian)).tobytes()
    if compression:
        blocks = [raw[i : i + block_size] for i in range(0, len(raw), block_size)]
        comp = [zlib.compress(b) for b in blocks]
        last = len(blocks[-1]) if blocks else 0
        header = np.array([len(blocks), block_size, last] + [len(c) for c in comp], dtype=hdt)
        body = b"".join(comp)
    else:
        header = np.array([len(raw)], dtype=hdt)
        body = raw
    if b64:
        # VTK encodes the header and the data separately.
        return base64.b64encode(header.tobytes()) + base64.b64encode(body)
    return header.tobytes() + body


VTU_TYPES = {
    np.dtype("float32"): "Float32",
    np.dtype("float64"): "Float64",
    np.dtype("int32"): "Int32",
    np.dtype("int64"): "Int64",
    np.dtype("uint8"): "UInt8",
    np.dtype("uint32"): "UInt32",
}


def write_vtu(path, pieces, mode, header_type="UInt32", compression=False, block_size=32768,
              endian="<", info_keys=False):
    """mode: 'appended-raw', 'appended-base64' or 'binary' (inline base64). info_keys: put
    an <InformationKey> element after the inline Points data, as VTK 9 does."""
    appended = bytearray()
    out = []
    order = "LittleEndian" if endian == "<" else "BigEndian"
    attrs = f'type="UnstructuredGrid" version="1.0" byte_order="{order}" header_type="{header_type}"'
    if compression:
        attrs += ' compressor="vtkZLibDataCompressor"'
    out.append('<?xml version="1.0"?>')
    out.append(f"<VTKFile {attrs}>")
    out.append("  <!-- written by make_fixtures.py -->")
    out.append("  <UnstructuredGrid>")

    def array(name, data, ncomp=None):
        t = VTU_TYPES[data.dtype]
        nc = f' NumberOfComponents="{ncomp}"' if ncomp else ""
        enc = encode_array(
            data.reshape(-1), header_type, compression, block_size, mode != "appended-raw", endian
        )
        if mode == "binary":
            info = ""
            if info_keys and name == "Points":
                info = (
                    '\n<InformationKey name="L2_NORM_RANGE" location="vtkDataArray" length="2">'
                    '<Value index="0">0</Value><Value index="1">3.9</Value></InformationKey>'
                )
            return f'<DataArray type="{t}" Name="{name}"{nc} format="binary">\n{enc.decode()}{info}\n</DataArray>'
        off = len(appended)
        appended.extend(enc)
        return f'<DataArray type="{t}" Name="{name}"{nc} format="appended" offset="{off}"/>'

    for pts, cells, types, tags in pieces:
        out.append(f'    <Piece NumberOfPoints="{len(pts)}" NumberOfCells="{len(types)}">')
        out.append("      <PointData>")
        out.append("        " + array("dist", np.arange(len(pts), dtype=np.float64)))
        out.append("      </PointData>")
        out.append('      <CellData Scalars="gmsh:physical">')
        out.append("        " + array("attribute", np.full(len(types), 42, dtype=np.int32)))
        out.append("        " + array("gmsh:physical", tags))
        out.append("      </CellData>")
        out.append("      <Points>")
        out.append("        " + array("Points", pts, 3))
        out.append("      </Points>")
        out.append("      <Cells>")
        conn = np.concatenate([np.asarray(c) for c in cells]).astype(np.int64)
        offs = np.cumsum([len(c) for c in cells]).astype(np.int64)
        out.append("        " + array("connectivity", conn))
        out.append("        " + array("offsets", offs))
        out.append("        " + array("types", np.array(types, dtype=np.uint8)))
        out.append("      </Cells>")
        out.append("    </Piece>")
    out.append("  </UnstructuredGrid>")
    text = "\n".join(out) + "\n"
    data = text.encode()
    if mode != "binary":
        enc = "raw" if mode == "appended-raw" else "base64"
        data += f'  <AppendedData encoding="{enc}">\n   _'.encode() + bytes(appended)
        data += b"\n  </AppendedData>\n"
    data += b"</VTKFile>\n"
    with open(path, "wb") as f:
        f.write(data)


def block_cells():
    pts, hexes, quads, verts, tags = block_mesh()
    cells = list(hexes) + list(quads) + list(verts)
    types = [12] * len(hexes) + [9] * len(quads) + [1] * len(verts)
    return pts, cells, types, np.concatenate(tags).astype(np.int32)


def main():
    meshio.write("block_ascii.vtu", meshio_block(), file_format="vtu", binary=False)
    meshio.write("block_binary.vtu", meshio_block(), binary=True, compression=None)
    meshio.write("block_zlib.vtu", meshio_block(), binary=True, compression="zlib")
    one = [block_cells()]
    write_vtu("block_appended_raw.vtu", one, "appended-raw", header_type="UInt64")
    write_vtu(
        "block_appended_base64_be_zlib.vtu",
        one,
        "appended-base64",
        compression=True,
        block_size=64,
        endian=">",
    )
    write_vtu(
        "block_binary_be_uint64.vtu", one, "binary", header_type="UInt64", endian=">", info_keys=True
    )
    # Two pieces: the hexes in the first, quads and vertex in the second (with its own,
    # renumbered copy of the points they use), so the reader must offset point indices.
    pts, cells, types, tags = block_cells()
    p2_nodes = sorted({int(n) for c in cells[8:] for n in c})
    renum = {n: i for i, n in enumerate(p2_nodes)}
    piece1 = (pts, cells[:8], types[:8], tags[:8])
    piece2 = (
        pts[p2_nodes],
        [[renum[int(n)] for n in c] for c in cells[8:]],
        types[8:],
        tags[8:],
    )
    write_vtu("two_pieces_appended_raw_zlib.vtu", [piece1, piece2], "appended-raw",
              compression=True, block_size=100)


def write_with_vtk():
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

    grid = vtk_block_grid()
    for name, mode, encode, zlib_on in [
        ("block_vtk97_appended_raw_zlib.vtu", "appended", False, True),
        ("block_vtk97_appended_base64.vtu", "appended", True, False),
        ("block_vtk97_binary_zlib.vtu", "binary", False, True),
        ("block_vtk97_ascii.vtu", "ascii", False, False),
    ]:
        w = vtkXMLUnstructuredGridWriter()
        w.SetInputData(grid)
        w.SetFileName(name)
        {"appended": w.SetDataModeToAppended, "binary": w.SetDataModeToBinary,
         "ascii": w.SetDataModeToAscii}[mode]()
        w.SetEncodeAppendedData(encode)
        if zlib_on:
            w.SetCompressorTypeToZLib()
        else:
            w.SetCompressorTypeToNone()
        w.Write()


def write_lagrange():
    """Lagrange cells written by VTK (file version 2.3), and the same file relabelled as
    version 1.0, whose Lagrange hexahedra VTK reads in the VTK 8 numbering. The node ids
    VTK's reader returns for each file go to lagrange_expected.json."""
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

    w = vtkXMLUnstructuredGridWriter()
    w.SetInputData(lagrange_grid())
    w.SetFileName("lagrange_vtk97.vtu")
    w.SetDataModeToAscii()
    w.Write()
    text = open("lagrange_vtk97.vtu").read()
    old = re.sub(r'(<VTKFile[^>]*) version="[0-9.]+"', r'\1 version="1.0"', text, count=1)
    assert old != text
    with open("lagrange_v10.vtu", "w") as f:
        f.write(old)
    expected = {name: vtk_cell_ids(name) for name in ["lagrange_vtk97.vtu", "lagrange_v10.vtu"]}
    with open("lagrange_expected.json", "w") as f:
        json.dump(expected, f)


if __name__ == "__main__":
    main()
    write_with_vtk()
    write_lagrange()
