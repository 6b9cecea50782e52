//! Meshes between Rust and the Python layer as raw buffers (native-endian, read with
//! `numpy.frombuffer`): points `f64 × 3` per point, cells `i64` per node, tags `i32`.
//!
//! Input ([`raw_from_py`]): `(points, blocks, tag_names)` with `blocks` a list of
//! `(kind, nodes_per_cell, nodes, tags)`, `kind` a meshio cell type name (`quad`,
//! `hexahedron`, `line`, `triangle`, ...: linear cells in VTK's node order, which is also
//! polyspline's) and `tags` possibly empty; the result is checked like a file's by
//! `LinearMesh::from_raw`. Output ([`arrays`]): a high-order mesh's cells in the node order
//! asked for; [`raw_to_py`]: what a reader found, the same tuple as the input.

use polyspline::io::ordering::{gmsh_hex, gmsh_line, gmsh_quad, to_indices, vtk_hex, vtk_quad};
use polyspline::mesh::HighOrderMesh;
use polyspline::mesh::raw::{CellKind, RawBlock, RawMesh};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use std::collections::BTreeMap;

/// meshio's names of the linear cell kinds.
const KINDS: [(&str, CellKind); 8] = [
    ("vertex", CellKind::Vertex),
    ("line", CellKind::Line),
    ("triangle", CellKind::Triangle),
    ("quad", CellKind::Quad),
    ("tetra", CellKind::Tetra),
    ("hexahedron", CellKind::Hexahedron),
    ("wedge", CellKind::Wedge),
    ("pyramid", CellKind::Pyramid),
];

/// Values of type `T` from a buffer of native-endian bytes.
fn values<T: bytemuck::Pod>(bytes: &[u8], what: &str) -> PyResult<Vec<T>> {
    if !bytes.len().is_multiple_of(size_of::<T>()) {
        return Err(PyValueError::new_err(format!(
            "{what}: {} bytes is not a whole number of values",
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(size_of::<T>())
        .map(bytemuck::pod_read_unaligned)
        .collect())
}

/// The Python layer's mesh tuple: points, blocks `(kind, nodes_per_cell, nodes, tags)`,
/// tag names.
type PyRawMesh = (
    Vec<u8>,
    Vec<(String, usize, Vec<u8>, Vec<u8>)>,
    BTreeMap<i32, String>,
);

/// The [`RawMesh`] of the Python layer's tuple (module docs).
pub(crate) fn raw_from_py(obj: &Bound<'_, PyAny>) -> PyResult<RawMesh> {
    let (points, blocks, tag_names): PyRawMesh = obj.extract()?;
    let coords: Vec<f64> = values(&points, "points")?;
    if !coords.len().is_multiple_of(3) {
        return Err(PyValueError::new_err(
            "points: expected 3 coordinates per point",
        ));
    }
    let mut raw = RawMesh {
        points: coords.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        tag_names,
        ..Default::default()
    };
    for (name, nodes_per_cell, nodes, tags) in blocks {
        let kind = KINDS
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, k)| k.clone())
            .unwrap_or_else(|| CellKind::Other(format!("meshio {name}")));
        let mut block = RawBlock::new(kind, nodes_per_cell);
        block.nodes = values(&nodes, "cells")?;
        block.tags = values(&tags, "tags")?;
        if nodes_per_cell == 0 || !block.nodes.len().is_multiple_of(nodes_per_cell) {
            return Err(PyValueError::new_err(format!(
                "cells of type {name}: {} node ids is not a whole number of {nodes_per_cell}-node cells",
                block.nodes.len()
            )));
        }
        if !block.tags.is_empty() && block.tags.len() != block.len() {
            return Err(PyValueError::new_err(format!(
                "cells of type {name}: {} tags for {} cells",
                block.tags.len(),
                block.len()
            )));
        }
        raw.push_block(block);
    }
    Ok(raw)
}

fn bytes_of<'py, T: bytemuck::Pod>(py: Python<'py>, v: &[T]) -> Bound<'py, PyBytes> {
    PyBytes::new(py, bytemuck::cast_slice(v))
}

/// Node ids of every cell of `ids` (`n` per cell, lattice order), in the order `perm`
/// (format node → lattice index).
fn reorder(ids: &[u32], n: usize, perm: &[usize]) -> Vec<i64> {
    ids.chunks_exact(n)
        .flat_map(|cell| perm.iter().map(move |&s| i64::from(cell[s])))
        .collect()
}

/// The mesh's buffers with cells in node order `ordering` (`gmsh`, `vtk` or `lattice`).
pub(crate) fn arrays<'py>(
    py: Python<'py>,
    ho: &HighOrderMesh,
    ordering: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let p = ho.order;
    let (cell, facet) = match (ordering, ho.dim) {
        ("gmsh", 2) => (gmsh_quad(p), gmsh_line(p)),
        ("gmsh", _) => (gmsh_hex(p), gmsh_quad(p)),
        ("vtk", 2) => (vtk_quad(p), gmsh_line(p)),
        ("vtk", _) => (vtk_hex(p), vtk_quad(p)),
        ("lattice", _) => (Vec::new(), Vec::new()),
        _ => {
            return Err(PyValueError::new_err(format!(
                "ordering {ordering:?}: expected 'gmsh', 'vtk' or 'lattice'"
            )));
        }
    };
    let identity = |n: usize| (0..n).collect::<Vec<_>>();
    let cell = if ordering == "lattice" {
        identity(ho.nodes_per_element())
    } else {
        to_indices(p, &cell)
    };
    let facet = if ordering == "lattice" {
        identity(ho.nodes_per_facet())
    } else {
        to_indices(p, &facet)
    };
    let points: Vec<f64> = ho.nodes.iter().flatten().copied().collect();
    let d = PyDict::new(py);
    d.set_item("points", bytes_of(py, &points))?;
    d.set_item(
        "cells",
        bytes_of(py, &reorder(&ho.elements, ho.nodes_per_element(), &cell)),
    )?;
    d.set_item("cell_tags", bytes_of(py, &ho.element_tags))?;
    d.set_item(
        "facets",
        bytes_of(py, &reorder(&ho.boundary, ho.nodes_per_facet(), &facet)),
    )?;
    d.set_item("facet_tags", bytes_of(py, &ho.boundary_tags))?;
    d.set_item("tag_names", ho.tag_names.clone())?;
    d.set_item("dim", ho.dim)?;
    d.set_item("order", ho.order)?;
    d.set_item("nodes_per_cell", ho.nodes_per_element())?;
    d.set_item("nodes_per_facet", ho.nodes_per_facet())?;
    Ok(d)
}

/// What a reader found: `("linear", (points, blocks, tag_names))` when every block is a
/// linear kind, else `("high_order", arrays)` of the high-order mesh in Gmsh's node order.
pub(crate) fn raw_to_py<'py>(py: Python<'py>, raw: &RawMesh) -> PyResult<Bound<'py, PyAny>> {
    let linear = raw
        .blocks
        .iter()
        .all(|b| KINDS.iter().any(|(_, k)| k == b.kind()));
    if !linear {
        let ho = HighOrderMesh::from_raw(raw.clone())
            .map_err(|e| super::error(py, "InputError", e.to_string()))?;
        return ("high_order", arrays(py, &ho, "gmsh")?)
            .into_pyobject(py)
            .map(Bound::into_any);
    }
    let points: Vec<f64> = raw.points.iter().flatten().copied().collect();
    let blocks = PyList::empty(py);
    for b in &raw.blocks {
        let name = KINDS
            .iter()
            .find(|(_, k)| k == b.kind())
            .map(|(n, _)| *n)
            .unwrap_or("?");
        blocks.append((
            name,
            b.nodes_per_cell,
            bytes_of(py, &b.nodes),
            bytes_of(py, &b.tags),
        ))?;
    }
    let mesh = (bytes_of(py, &points), blocks, raw.tag_names.clone());
    ("linear", mesh).into_pyobject(py).map(Bound::into_any)
}
