//! VTK XML unstructured grid (`.vtu`, file version 2.2) output of a [`HighOrderMesh`].
//!
//! Elements of order ≥ 2 are Lagrange quadrilaterals (70) or hexahedra (72) and boundary facets
//! Lagrange curves (68) or quadrilaterals (70), nodes in VTK ≥ 9 order
//! ([`crate::sample::ordering`]); order 1 uses the linear types 3/9/12. Version 2.2 matters:
//! VTK ≥ 9 renumbers the hexahedron edges of files older than 2.1. Cell data: `tag` (region tag
//! of elements, boundary tag of facets, 0 = none) and `boundary` (1 on boundary facets).
//! Encodings: ASCII, inline base64 (`binary`) with UInt64 headers, or raw appended data.

use crate::sample::HighOrderMesh;
use crate::sample::ordering::{gmsh_line, to_indices, vtk_hex, vtk_quad};
use base64::Engine;
use std::io::{self, Write};

/// How the data arrays are stored.
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
        bytes,
        text,
    }
}

/// Write `mesh` as a VTU file.
pub fn write_vtu(
    mesh: &HighOrderMesh,
    encoding: VtuEncoding,
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
    let (ne, nb) = (mesh.n_elements(), mesh.n_boundary());
    let npf = mesh.nodes_per_facet();

    let mut connectivity: Vec<i64> = Vec::with_capacity(mesh.elements.len() + mesh.boundary.len());
    let mut offsets: Vec<i64> = Vec::with_capacity(ne + nb);
    let mut types: Vec<u8> = Vec::with_capacity(ne + nb);
    for e in 0..ne {
        let nodes = mesh.element(e);
        connectivity.extend(vol_order.iter().map(|&k| nodes[k] as i64));
        offsets.push(connectivity.len() as i64);
        types.push(vol_type);
    }
    for f in mesh.boundary.chunks(npf) {
        connectivity.extend(bnd_order.iter().map(|&k| f[k] as i64));
        offsets.push(connectivity.len() as i64);
        types.push(bnd_type);
    }
    let mut tags: Vec<i32> = if mesh.element_tags.is_empty() {
        vec![0; ne]
    } else {
        mesh.element_tags.clone()
    };
    tags.extend_from_slice(&mesh.boundary_tags);
    let boundary: Vec<u8> = (0..ne + nb).map(|i| (i >= ne) as u8).collect();
    let points: Vec<f64> = mesh.nodes.iter().flat_map(|x| x.iter().copied()).collect();

    let points = array("Points", "Float64", 3, &points, encoding);
    let cells = [
        array("connectivity", "Int64", 1, &connectivity, encoding),
        array("offsets", "Int64", 1, &offsets, encoding),
        array("types", "UInt8", 1, &types, encoding),
    ];
    let cell_data = [
        array("tag", "Int32", 1, &tags, encoding),
        array("boundary", "UInt8", 1, &boundary, encoding),
    ];

    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"UnstructuredGrid\" version=\"2.2\" byte_order=\"LittleEndian\" header_type=\"UInt64\">"
    )?;
    writeln!(w, "<UnstructuredGrid>")?;
    writeln!(
        w,
        "<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">",
        mesh.nodes.len(),
        ne + nb
    )?;
    let mut appended: Vec<u8> = Vec::new();
    let mut put = |w: &mut dyn Write, a: &Array| -> io::Result<()> {
        let comps = if a.components > 1 {
            format!(" NumberOfComponents=\"{}\"", a.components)
        } else {
            String::new()
        };
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
    writeln!(w, "</CellData>\n</Piece>\n</UnstructuredGrid>")?;
    if encoding == VtuEncoding::Appended {
        write!(w, "<AppendedData encoding=\"raw\">\n_")?;
        w.write_all(&appended)?;
        writeln!(w, "\n</AppendedData>")?;
    }
    writeln!(w, "</VTKFile>")
}
