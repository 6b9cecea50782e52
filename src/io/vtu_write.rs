//! VTK XML unstructured grid (`.vtu`) output of a [`HighOrderMesh`].
//!
//! Input: a high-order mesh. Output: one file holding either the volume cells only (the default
//! `.vtu`: MFEM refuses a file with cells of two dimensions) or the boundary facets only (a
//! companion file, `--vtu-boundary`). Elements of order ≥ 2 are Lagrange quadrilaterals (70) or
//! hexahedra (72) and boundary facets Lagrange curves (68) or quadrilaterals (70), nodes in
//! VTK ≥ 9 order ([`crate::io::ordering`]); order 1 uses the linear types 3/9/12. Both files
//! hold all the nodes, so node ids agree between them.
//!
//! File version: VTK ≥ 9 renumbers the edges of Lagrange hexahedra in files older than 2.1, so
//! a file with hexahedra of order ≥ 2 says `2.2`. meshio reads only versions 0.1 and 1.0 and
//! would keep the order of the nodes as written, so every other file (lines, quads, linear
//! hexes: node orders that no VTK version changed) says `1.0` and meshio reads it too; a 2.2
//! file is refused by meshio with an error, never misread.
//!
//! Cell data: `tag` (region tag of elements, boundary tag of facets, 0 = none). Encodings:
//! ASCII, inline base64 (`binary`) with UInt64 headers, or raw appended data.
//!
//! Field data (the grid's `<FieldData>`, after the piece, written only when the mesh has
//! periodic pairs: MFEM's VTU reader refuses a grid with any child besides its one piece),
//! numeric only, so that meshio (which refuses VTK's `String` arrays) reads the file:
//! * `tag_ids` (Int32) and `tag_names` (UInt8): the named tags and their names, UTF-8, each
//!   followed by a NUL byte, in the order of `tag_ids`;
//! * `periodic_tags` (Int32, 2 components): per periodic pair its master and image boundary
//!   tags; `periodic_affine` (Float64, 12 components): the map master → image, x' = R x + t,
//!   as the rows (R₀₀ R₀₁ R₀₂ t₀ R₁₀ … t₂), the first three rows of MSH `$Periodic`'s matrix.

use crate::io::ordering::{gmsh_line, to_indices, vtk_hex, vtk_quad};
use crate::mesh::HighOrderMesh;
use base64::Engine;
use std::io::{self, Write};

/// How the data arrays are stored (`--vtu-encoding`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VtuEncoding {
    Ascii,
    Base64,
    Appended,
}

/// One data array: little-endian bytes (binary encodings) or text (ASCII).
struct Array {
    name: &'static str,
    vtk_type: &'static str,
    components: usize,
    /// `NumberOfTuples`, which VTK needs for field data (no piece gives the count).
    tuples: Option<usize>,
    bytes: Vec<u8>,
    text: String,
}

/// Values that a data array holds.
trait Value: Copy + std::fmt::Display + Send + Sync {
    fn put_le(self, out: &mut Vec<u8>);
}

macro_rules! value {
    ($($t:ty),*) => {$(
        impl Value for $t {
            fn put_le(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes());
            }
        }
    )*};
}
value!(f64, i64, i32, u8);

/// The array in the form `encoding` needs: text (12 values a line) for ASCII, else bytes.
/// Text is formatted in parallel in fixed chunks and joined in order.
fn array<T: Value>(
    name: &'static str,
    vtk_type: &'static str,
    components: usize,
    values: &[T],
    encoding: VtuEncoding,
) -> Array {
    use rayon::prelude::*;
    use std::fmt::Write as _;
    let mut bytes = Vec::new();
    let mut text = String::new();
    if encoding == VtuEncoding::Ascii {
        const CHUNK: usize = 12 * 1024;
        let parts: Vec<String> = values
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                let mut s = String::with_capacity(chunk.len() * 8);
                for (k, &v) in chunk.iter().enumerate() {
                    let i = c * CHUNK + k;
                    if i > 0 {
                        s.push(if i.is_multiple_of(12) { '\n' } else { ' ' });
                    }
                    write!(s, "{v}").expect("formatting into a String");
                }
                s
            })
            .collect();
        text = parts.concat();
    } else {
        bytes.reserve(std::mem::size_of_val(values));
        for &v in values {
            v.put_le(&mut bytes);
        }
    }
    Array {
        name,
        vtk_type,
        components,
        tuples: None,
        bytes,
        text,
    }
}

/// The grid's field data (module docs): tag names and periodic pairs, empty without pairs.
fn field_data(mesh: &HighOrderMesh, encoding: VtuEncoding) -> Vec<Array> {
    // MFEM's VTU reader refuses a grid with any child besides its one piece, so a mesh
    // without pairs (nothing a solver needs) stays readable there.
    if mesh.periodic.is_empty() {
        return Vec::new();
    }
    let with_tuples = |mut a: Array, n: usize| {
        a.tuples = Some(n);
        a
    };
    let mut out = Vec::new();
    if !mesh.tag_names.is_empty() {
        let ids: Vec<i32> = mesh.tag_names.keys().copied().collect();
        let mut names: Vec<u8> = Vec::new();
        for n in mesh.tag_names.values() {
            names.extend_from_slice(n.as_bytes());
            names.push(0);
        }
        out.push(with_tuples(
            array("tag_ids", "Int32", 1, &ids, encoding),
            ids.len(),
        ));
        out.push(with_tuples(
            array("tag_names", "UInt8", 1, &names, encoding),
            names.len(),
        ));
    }
    if !mesh.periodic.is_empty() {
        let tags: Vec<i32> = mesh
            .periodic
            .iter()
            .flat_map(|l| [l.master_tag, l.slave_tag])
            .collect();
        let affine: Vec<f64> = mesh
            .periodic
            .iter()
            .flat_map(|l| l.transform.affine().into_iter().take(12))
            .collect();
        let n = mesh.periodic.len();
        out.push(with_tuples(
            array("periodic_tags", "Int32", 2, &tags, encoding),
            n,
        ));
        out.push(with_tuples(
            array("periodic_affine", "Float64", 12, &affine, encoding),
            n,
        ));
    }
    out
}

/// Which cells a VTU file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VtuCells {
    /// The elements (quads in 2D, hexes in 3D).
    Volume,
    /// The boundary facets (lines in 2D, quads in 3D).
    Boundary,
}

/// The VTU file version for the cells of `mesh` in `cells` (see the module docs).
pub fn vtu_version(mesh: &HighOrderMesh, cells: VtuCells) -> &'static str {
    if mesh.dim == 3 && mesh.order >= 2 && cells == VtuCells::Volume {
        "2.2"
    } else {
        "1.0"
    }
}

/// Write the elements of `mesh` as a VTU file.
pub fn write_vtu(
    mesh: &HighOrderMesh,
    encoding: VtuEncoding,
    w: &mut impl Write,
) -> io::Result<()> {
    write_vtu_cells(mesh, encoding, VtuCells::Volume, w)
}

/// Write the elements or the boundary facets of `mesh` as a VTU file.
pub fn write_vtu_cells(
    mesh: &HighOrderMesh,
    encoding: VtuEncoding,
    which: VtuCells,
    w: &mut impl Write,
) -> io::Result<()> {
    let d = mesh.dim;
    let p = mesh.order;
    let (vol_type, bnd_type): (u8, u8) = match (d, p) {
        (2, 1) => (9, 3),
        (3, 1) => (12, 9),
        (2, _) => (70, 68),
        _ => (72, 70),
    };
    let vol_order = to_indices(p, &if d == 2 { vtk_quad(p) } else { vtk_hex(p) });
    let bnd_order = to_indices(p, &if d == 2 { gmsh_line(p) } else { vtk_quad(p) });
    let npf = mesh.nodes_per_facet();
    let (n_cells, cell_type, order, cells): (usize, u8, Vec<usize>, Vec<&[u32]>) = match which {
        VtuCells::Volume => (
            mesh.n_elements(),
            vol_type,
            vol_order,
            (0..mesh.n_elements()).map(|e| mesh.element(e)).collect(),
        ),
        VtuCells::Boundary => (
            mesh.n_boundary(),
            bnd_type,
            bnd_order,
            mesh.boundary.chunks(npf).collect(),
        ),
    };
    let mut connectivity: Vec<i64> = Vec::with_capacity(n_cells * order.len());
    let mut offsets: Vec<i64> = Vec::with_capacity(n_cells);
    for nodes in &cells {
        connectivity.extend(order.iter().map(|&k| nodes[k] as i64));
        offsets.push(connectivity.len() as i64);
    }
    let types: Vec<u8> = vec![cell_type; n_cells];
    let tags: Vec<i32> = match which {
        VtuCells::Volume if mesh.element_tags.is_empty() => vec![0; n_cells],
        VtuCells::Volume => mesh.element_tags.clone(),
        VtuCells::Boundary if mesh.boundary_tags.is_empty() => vec![0; n_cells],
        VtuCells::Boundary => mesh.boundary_tags.clone(),
    };
    let points: Vec<f64> = mesh.nodes.iter().flat_map(|x| x.iter().copied()).collect();

    let points = array("Points", "Float64", 3, &points, encoding);
    let cells = [
        array("connectivity", "Int64", 1, &connectivity, encoding),
        array("offsets", "Int64", 1, &offsets, encoding),
        array("types", "UInt8", 1, &types, encoding),
    ];
    let cell_data = [array("tag", "Int32", 1, &tags, encoding)];
    let field_data = field_data(mesh, encoding);

    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"UnstructuredGrid\" version=\"{}\" byte_order=\"LittleEndian\" header_type=\"UInt64\">",
        vtu_version(mesh, which)
    )?;
    writeln!(w, "<UnstructuredGrid>")?;
    let mut appended: Vec<u8> = Vec::new();
    let mut put = |w: &mut dyn Write, a: &Array| -> io::Result<()> {
        let mut comps = if a.components > 1 {
            format!(" NumberOfComponents=\"{}\"", a.components)
        } else {
            String::new()
        };
        if let Some(n) = a.tuples {
            comps += &format!(" NumberOfTuples=\"{n}\"");
        }
        match encoding {
            VtuEncoding::Ascii => {
                writeln!(
                    w,
                    "<DataArray type=\"{}\" Name=\"{}\"{comps} format=\"ascii\">",
                    a.vtk_type, a.name
                )?;
                writeln!(w, "{}", a.text)?;
                writeln!(w, "</DataArray>")
            }
            VtuEncoding::Base64 => {
                let mut block = (a.bytes.len() as u64).to_le_bytes().to_vec();
                block.extend_from_slice(&a.bytes);
                writeln!(
                    w,
                    "<DataArray type=\"{}\" Name=\"{}\"{comps} format=\"binary\">",
                    a.vtk_type, a.name
                )?;
                writeln!(
                    w,
                    "{}",
                    base64::engine::general_purpose::STANDARD.encode(&block)
                )?;
                writeln!(w, "</DataArray>")
            }
            VtuEncoding::Appended => {
                writeln!(
                    w,
                    "<DataArray type=\"{}\" Name=\"{}\"{comps} format=\"appended\" offset=\"{}\"/>",
                    a.vtk_type,
                    a.name,
                    appended.len()
                )?;
                appended.extend_from_slice(&(a.bytes.len() as u64).to_le_bytes());
                appended.extend_from_slice(&a.bytes);
                Ok(())
            }
        }
    };
    writeln!(
        w,
        "<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">",
        mesh.nodes.len(),
        n_cells
    )?;
    writeln!(w, "<Points>")?;
    put(w, &points)?;
    writeln!(w, "</Points>\n<Cells>")?;
    for a in &cells {
        put(w, a)?;
    }
    writeln!(w, "</Cells>\n<CellData Scalars=\"tag\">")?;
    for a in &cell_data {
        put(w, a)?;
    }
    writeln!(w, "</CellData>\n</Piece>")?;
    // After the piece, as VTK's own writer puts it; VTK and meshio find it anywhere among the
    // grid's children.
    if !field_data.is_empty() {
        writeln!(w, "<FieldData>")?;
        for a in &field_data {
            put(w, a)?;
        }
        writeln!(w, "</FieldData>")?;
    }
    writeln!(w, "</UnstructuredGrid>")?;
    if encoding == VtuEncoding::Appended {
        write!(w, "<AppendedData encoding=\"raw\">\n_")?;
        w.write_all(&appended)?;
        writeln!(w, "\n</AppendedData>")?;
    }
    writeln!(w, "</VTKFile>")
}
