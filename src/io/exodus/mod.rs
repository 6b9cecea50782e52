//! Exodus II meshes stored as netCDF-3 (classic `CDF\x01` and 64-bit offset `CDF\x02`).
//!
//! The netCDF-3 container is parsed here directly from the bytes, with every count and offset
//! checked against the input size, so errors name byte offsets and a corrupt header cannot
//! cause a huge allocation. netCDF-4 (HDF5) and CDF-5 files are rejected with a message.
//!
//! Read:
//! * coordinates from `coordx`/`coordy`/`coordz`, or from `coord` (shape `[num_dim,
//!   num_nodes]`), as doubles or floats; `num_dim` becomes [`RawMesh::declared_dim`];
//! * element blocks `connect1..connectN` (1-based node indices; attribute `elem_type`):
//!   HEX/HEX8 → hexahedron, QUAD/QUAD4/SHELL/SHELL4 → quad (a SHELL block in a 3D file is a
//!   surface and is reported as quads all the same), TETRA/TET4 → tetrahedron, WEDGE →
//!   wedge, PYRAMID → pyramid, TRI/TRI3/TRISHELL → triangle, BAR/BEAM/TRUSS → line; any other
//!   type or node count (HEX20, HEX27, QUAD8, QUAD9, ...) → [`CellKind::Other`]. Exodus linear
//!   node orders equal VTK's. Each cell's location is the byte offset of its connectivity;
//! * element tags: the block id (`eb_prop1`, else the block number), named by `eb_names`;
//! * side sets `elem_ss<i>`/`side_ss<i>` (ids `ss_prop1`, names `ss_names`) → tagged facets
//!   built with the Exodus side numbering (hex: side 1 = nodes 1,2,6,5; 2 = 2,3,7,6;
//!   3 = 3,4,8,7; 4 = 1,5,8,4; 5 = 1,4,3,2; 6 = 5,6,7,8; 2D quad: side i = edge i→i+1; shell:
//!   sides 1/2 = the two faces, 3.. = edges; tetrahedron, wedge, pyramid as in the Exodus
//!   manual). Elements in side sets use the global element numbering (blocks in file order).
//!
//! When a block id and a side-set id are equal and both are named, the side-set name is kept
//! in [`RawMesh::tag_names`]. Node sets, maps (`node_num_map`, `elem_num_map`: connectivity
//! and side sets use internal numbering), attributes and results are ignored.
//!
//! Parts: `netcdf` parses the container and gives typed views of its variables;
//! `family` maps element types to kinds and side tables; this module reads the coordinates,
//! the element blocks and the side sets, in that order.
//!
//! [`CellKind`]: crate::mesh::raw::CellKind
//! [`CellKind::Other`]: crate::mesh::raw::CellKind::Other

mod family;
mod netcdf;

use crate::mesh::raw::{Location, ParseError, RawBlock, RawMesh};
use family::Family;
use netcdf::{NcType, NetCdf};
use std::collections::BTreeMap;

/// An element block as read (for side-set lookups).
struct Block {
    family: Family,
    elem_type: String,
    npe: usize,
    /// Global 0-based index of the block's first element.
    first: usize,
    /// Index into the mesh's blocks.
    raw: usize,
}

/// Read an Exodus II file held in memory.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    let nc = NetCdf::parse(data)?;
    let dim = dimension(&nc)?;
    let num_nodes = nc.dim("num_nodes").unwrap_or(0);
    let points = coordinates(&nc, dim, num_nodes)?;
    let mut mesh = RawMesh {
        points,
        declared_dim: (dim >= 2).then_some(dim),
        ..Default::default()
    };
    let mut tag_names = BTreeMap::new();
    let (blocks, n_elems) = element_blocks(&nc, dim, num_nodes, &mut mesh, &mut tag_names)?;
    let facets = side_sets(&nc, &blocks, n_elems, &mesh, &mut tag_names)?;
    let element_blocks = std::mem::take(&mut mesh.blocks);
    for b in element_blocks.into_iter().chain(facets) {
        mesh.push_block(b);
    }
    mesh.tag_names = tag_names;
    Ok(mesh)
}

/// `num_dim`, which must be 1, 2 or 3 (its absence means the file is not an Exodus mesh).
fn dimension(nc: &NetCdf) -> Result<usize, ParseError> {
    let dim = nc.dim("num_dim").ok_or_else(|| {
        ParseError::new(
            Location::File,
            "netCDF file without the dimension num_dim: not an Exodus II mesh",
        )
    })?;
    if !(1..=3).contains(&dim) {
        return Err(ParseError::new(
            Location::File,
            format!("num_dim is {dim}; expected 1, 2 or 3"),
        ));
    }
    Ok(dim)
}

/// The node coordinates, from `coordx`/`coordy`/`coordz` or from `coord`; each variable must
/// hold `num_nodes` values.
fn coordinates(nc: &NetCdf, dim: usize, num_nodes: usize) -> Result<Vec<[f64; 3]>, ParseError> {
    let mut points = vec![[0.0f64; 3]; 0];
    if num_nodes > 0 {
        let mut axes: Vec<Vec<f64>> = Vec::new();
        if nc.var("coordx").is_some() {
            for name in ["coordx", "coordy", "coordz"].iter().take(dim) {
                let v = nc.var(name).ok_or_else(|| {
                    ParseError::new(
                        Location::File,
                        format!("num_dim is {dim} but the variable {name} is missing"),
                    )
                })?;
                axes.push(nc.floats(v)?);
            }
        } else if let Some(v) = nc.var("coord") {
            let all = nc.floats(v)?;
            if all.len() < dim * num_nodes {
                return Err(ParseError::at_byte(
                    v.header_at,
                    format!(
                        "variable coord holds {} values, expected num_dim × num_nodes = {}",
                        all.len(),
                        dim * num_nodes
                    ),
                ));
            }
            axes = all
                .chunks(num_nodes)
                .take(dim)
                .map(|c| c.to_vec())
                .collect();
        } else {
            return Err(ParseError::new(
                Location::File,
                "no coordinates: expected the variables coordx/coordy/coordz or coord",
            ));
        }
        for (k, a) in axes.iter().enumerate() {
            if a.len() != num_nodes {
                return Err(ParseError::new(
                    Location::File,
                    format!(
                        "coordinate variable {} holds {} values, expected num_nodes = {num_nodes}",
                        ["coordx", "coordy", "coordz"][k],
                        a.len()
                    ),
                ));
            }
        }
        points = (0..num_nodes)
            .map(|i| {
                let mut p = [0.0; 3];
                for (k, a) in axes.iter().enumerate() {
                    p[k] = a[i];
                }
                p
            })
            .collect();
    }
    Ok(points)
}

/// The element blocks `connect1..connectN`, pushed unmerged to `mesh.blocks` (side sets find
/// their element's block by index); returns the blocks as read and the number of elements.
fn element_blocks(
    nc: &NetCdf,
    dim: usize,
    num_nodes: usize,
    mesh: &mut RawMesh,
    tag_names: &mut BTreeMap<i32, String>,
) -> Result<(Vec<Block>, usize), ParseError> {
    let n_blocks = nc.dim("num_el_blk").unwrap_or(0);
    let block_ids = nc.ids("eb_prop1");
    let block_names = nc.names("eb_names");
    let mut blocks: Vec<Block> = Vec::new();
    let mut n_elems = 0usize;
    // Exodus leaves out the connectivity of empty blocks.
    for (k, v) in nc.numbered("connect", n_blocks) {
        let (b, name) = (k - 1, &v.name);
        let shape = nc.shape(v);
        let (&[n_cells, npe], true) = (&shape[..], shape.get(1).is_some_and(|&n| n > 0)) else {
            return Err(ParseError::at_byte(
                v.header_at,
                format!(
                    "variable {name} has shape {shape:?}, expected [elements, nodes per element]"
                ),
            ));
        };
        let elem_type = v
            .attrs
            .iter()
            .find(|a| a.name.eq_ignore_ascii_case("elem_type") && a.ty == NcType::Char)
            .map(|a| {
                let end = a
                    .value
                    .iter()
                    .position(|&c| c == 0)
                    .unwrap_or(a.value.len());
                String::from_utf8_lossy(&a.value[..end]).trim().to_string()
            })
            .ok_or_else(|| {
                ParseError::at_byte(
                    v.header_at,
                    format!("variable {name} has no elem_type attribute"),
                )
            })?;
        let family = Family::of(&elem_type, dim);
        let (conn, start) = nc.ints(v)?;
        let id = block_ids.get(b).copied().unwrap_or(b as i64 + 1);
        let tag = i32::try_from(id).map_err(|_| {
            ParseError::new(
                Location::File,
                format!("element block id {id} does not fit a 32-bit tag"),
            )
        })?;
        if let Some(n) = block_names.get(b).filter(|n| !n.is_empty()) {
            tag_names.insert(tag, n.clone());
        }
        let mut rb = RawBlock::new(family.kind(npe, &elem_type), npe);
        rb.nodes.reserve(conn.len());
        for (k, &c) in conn.iter().enumerate() {
            if c < 1 || c as usize > num_nodes {
                return Err(ParseError::at_byte(
                    start + k * v.ty.size(),
                    format!(
                        "block {id} ({elem_type}), element {}: node index {c} is out of range 1..={num_nodes}",
                        k / npe.max(1) + 1
                    ),
                ));
            }
            rb.nodes.push(c - 1);
        }
        rb.tags = vec![tag; n_cells];
        rb.locations = (0..n_cells)
            .map(|c| Location::Byte(start + c * npe * v.ty.size()))
            .collect();
        blocks.push(Block {
            family,
            elem_type,
            npe,
            first: n_elems,
            raw: mesh.blocks.len(),
        });
        n_elems += n_cells;
        // Kept unmerged so that side sets can find their element's block.
        mesh.blocks.push(rb);
    }

    Ok((blocks, n_elems))
}

/// The side sets `elem_ss<i>`/`side_ss<i>` as tagged facet blocks, one per facet kind.
fn side_sets(
    nc: &NetCdf,
    blocks: &[Block],
    n_elems: usize,
    mesh: &RawMesh,
    tag_names: &mut BTreeMap<i32, String>,
) -> Result<Vec<RawBlock>, ParseError> {
    let n_sets = nc.dim("num_side_sets").unwrap_or(0);
    let set_ids = nc.ids("ss_prop1");
    let set_names = nc.names("ss_names");
    let mut facets: Vec<RawBlock> = Vec::new();
    for (k, ev) in nc.numbered("elem_ss", n_sets) {
        let s = k - 1;
        let Some(sv) = nc.var(&format!("side_ss{k}")) else {
            continue;
        };
        let id = set_ids.get(s).copied().unwrap_or(s as i64 + 1);
        let tag = i32::try_from(id).map_err(|_| {
            ParseError::new(
                Location::File,
                format!("side set id {id} does not fit a 32-bit tag"),
            )
        })?;
        if let Some(n) = set_names.get(s).filter(|n| !n.is_empty()) {
            tag_names.insert(tag, n.clone());
        }
        let (elems, estart) = nc.ints(ev)?;
        let (sides, sstart) = nc.ints(sv)?;
        if elems.len() != sides.len() {
            return Err(ParseError::at_byte(
                sv.header_at,
                format!(
                    "side set {id}: {} elements but {} sides",
                    elems.len(),
                    sides.len()
                ),
            ));
        }
        for (k, (&e, &side)) in elems.iter().zip(&sides).enumerate() {
            let eloc = estart + k * ev.ty.size();
            if e < 1 || e as usize > n_elems {
                return Err(ParseError::at_byte(
                    eloc,
                    format!("side set {id}: element {e} is out of range 1..={n_elems}"),
                ));
            }
            let g = e as usize - 1;
            let bi = blocks.partition_point(|b| b.first <= g) - 1;
            let b = &blocks[bi];
            let face = b
                .family
                .side(side)
                .filter(|(_, f)| f.iter().all(|&i| i < b.npe));
            let Some((fkind, local)) = face else {
                return Err(ParseError::at_byte(
                    sstart + k * sv.ty.size(),
                    format!(
                        "side set {id}: element {e} ({}) has no side {side}",
                        b.elem_type
                    ),
                ));
            };
            let cell = g - b.first;
            let nodes = &mesh.blocks[b.raw].nodes[cell * b.npe..(cell + 1) * b.npe];
            let fb = match facets.iter().position(|f| f.kind() == &fkind) {
                Some(i) => &mut facets[i],
                None => {
                    facets.push(RawBlock::new(fkind.clone(), local.len()));
                    facets.last_mut().expect("just pushed")
                }
            };
            fb.nodes.extend(local.iter().map(|&i| nodes[i]));
            fb.tags.push(tag);
            fb.locations.push(Location::Byte(eloc));
        }
    }
    Ok(facets)
}

#[cfg(test)]
mod tests;
