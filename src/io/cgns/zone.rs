//! One zone of a CGNS base: its coordinates, its cells (unstructured sections or the cells of
//! a structured IJK block), its boundary conditions as tagged facets, and the vertex pairs its
//! grid connectivity names.
//!
//! Input: a `Zone_t` node. Output: a [`Zone`] in the zone's own 0-based vertex numbering.
//! Invariants: every node index is checked against the zone's vertex count here (errors name
//! the section's path and the element); every count is checked against the file's size before
//! anything is allocated for it; volume cells come in the file's corner order (orientation is
//! normalised later, by `LinearMesh::from_raw`).

use super::Tags;
use super::tree::Node;
use crate::io::glue;
use crate::math::reference::{HEX_SIDES, QUAD_SIDES};
use crate::mesh::periodic::Rigid;
use crate::mesh::raw::{CellKind, ParseError};
use std::collections::{BTreeMap, HashMap, HashSet};

/// Cells of one kind, nodes 0-based in the zone.
pub struct Cells {
    pub kind: CellKind,
    pub npc: usize,
    pub nodes: Vec<usize>,
    pub tags: Vec<i32>,
}

/// A vertex of this zone the connectivity identifies with a vertex of another zone.
pub struct Link {
    pub node: usize,
    pub donor: String,
    /// The donor's vertex: a 0-based index (unstructured) or 0-based IJK (structured).
    pub donor_node: DonorIndex,
    /// The connectivity node's path, for messages.
    pub path: std::rc::Rc<str>,
}

/// A donor vertex as the file names it.
#[derive(Clone, Copy)]
pub enum DonorIndex {
    Flat(usize),
    Ijk([usize; 3]),
}

/// A zone as read.
pub struct Zone {
    pub name: String,
    pub points: Vec<[f64; 3]>,
    pub blocks: Vec<Cells>,
    /// Vertex counts of a structured zone (1 in the directions it lacks).
    pub ijk: Option<[usize; 3]>,
    pub links: Vec<Link>,
    /// Whether the zone had any ZoneGridConnectivity entry (used or not).
    pub has_connectivity: bool,
    /// The zone's periodic connections.
    pub periodic: Vec<PeriodicClaim>,
}

/// A periodic connection (`GridConnectivityProperty/Periodic`): the rigid map from this
/// zone's side to the donor's, and this side's vertices where the file lists them.
pub struct PeriodicClaim {
    pub map: Rigid,
    /// Relative precision of the stored map (`f32::EPSILON` for `R4` data).
    pub precision: f64,
    /// This side's vertices (0-based in the zone; empty for face-located lists).
    pub own: Vec<usize>,
    /// The connection node's path, for messages.
    pub path: std::rc::Rc<str>,
}

impl Zone {
    /// The flat vertex index of a structured zone's 0-based IJK.
    pub fn flat(&self, ijk: [usize; 3]) -> Option<usize> {
        let n = self.ijk?;
        (ijk[0] < n[0] && ijk[1] < n[1] && ijk[2] < n[2])
            .then(|| ijk[0] + n[0] * (ijk[1] + n[1] * ijk[2]))
    }
}

/// CGNS element types: (name, nodes per element, kind) by type code.
pub fn element_type(code: i64) -> Option<(&'static str, usize, CellKind)> {
    let other = |s: &str| CellKind::Other(format!("{s} (CGNS)"));
    Some(match code {
        2 => ("NODE", 1, CellKind::Vertex),
        3 => ("BAR_2", 2, CellKind::Line),
        4 => ("BAR_3", 3, lagrange(1, 2)),
        5 => ("TRI_3", 3, CellKind::Triangle),
        6 => ("TRI_6", 6, other("TRI_6")),
        7 => ("QUAD_4", 4, CellKind::Quad),
        8 => ("QUAD_8", 8, other("QUAD_8")),
        9 => ("QUAD_9", 9, lagrange(2, 2)),
        10 => ("TETRA_4", 4, CellKind::Tetra),
        11 => ("TETRA_10", 10, other("TETRA_10")),
        12 => ("PYRA_5", 5, CellKind::Pyramid),
        13 => ("PYRA_14", 14, other("PYRA_14")),
        14 => ("PENTA_6", 6, CellKind::Wedge),
        15 => ("PENTA_15", 15, other("PENTA_15")),
        16 => ("PENTA_18", 18, other("PENTA_18")),
        17 => ("HEXA_8", 8, CellKind::Hexahedron),
        18 => ("HEXA_20", 20, other("HEXA_20")),
        19 => ("HEXA_27", 27, lagrange(3, 2)),
        21 => ("PYRA_13", 13, other("PYRA_13")),
        24 => ("BAR_4", 4, lagrange(1, 3)),
        26 => ("TRI_10", 10, other("TRI_10")),
        27 => ("QUAD_12", 12, other("QUAD_12")),
        28 => ("QUAD_16", 16, lagrange(2, 3)),
        30 => ("TETRA_20", 20, other("TETRA_20")),
        39 => ("HEXA_64", 64, lagrange(3, 3)),
        40 => ("BAR_5", 5, lagrange(1, 4)),
        44 => ("QUAD_25", 25, lagrange(2, 4)),
        56 => ("HEXA_125", 125, lagrange(3, 4)),
        _ => return None,
    })
}

fn lagrange(dim: usize, order: usize) -> CellKind {
    CellKind::Lagrange {
        dim,
        order,
        convention: crate::mesh::raw::NodeConvention::Cgns,
    }
}

/// Read zone `z` of a base of cell dimension `cell_dim`.
pub fn read(
    z: &Node<'_>,
    cell_dim: usize,
    file_len: usize,
    families: &BTreeMap<String, String>,
    tags: &mut Tags,
) -> Result<Zone, ParseError> {
    let zone_type = match z.child("ZoneType")? {
        Some(t) => t.string()?,
        None => return Err(z.error("no ZoneType node")),
    };
    let structured = match zone_type.as_str() {
        "Structured" => true,
        "Unstructured" => false,
        other => {
            return Err(z.error(format!(
                "zone type {other:?}; expected Structured or Unstructured"
            )));
        }
    };
    let (size, _) = z.ints()?;
    let idim = if structured { cell_dim } else { 1 };
    if size.len() < 2 * idim {
        return Err(z.error(format!(
            "zone size has {} values; a {} zone of dimension {cell_dim} needs {}",
            size.len(),
            zone_type.to_lowercase(),
            3 * idim
        )));
    }
    let mut ijk = [1usize; 3];
    for a in 0..idim {
        let n = size[a];
        if n < if structured { 2 } else { 1 } || n as u64 > file_len as u64 {
            return Err(z.error(format!(
                "vertex count {n} is impossible for a file of {file_len} bytes"
            )));
        }
        ijk[a] = n as usize;
    }
    let n_vertices = ijk
        .iter()
        .try_fold(1usize, |a, &b| a.checked_mul(b))
        .filter(|&n| n <= file_len);
    let Some(n_vertices) = n_vertices else {
        return Err(z.error(format!(
            "{ijk:?} vertices cannot be stored in a file of {file_len} bytes"
        )));
    };
    let points = coordinates(z, n_vertices)?;
    let mut zone = Zone {
        name: z.name.clone(),
        points,
        blocks: Vec::new(),
        ijk: structured.then_some(ijk),
        links: Vec::new(),
        has_connectivity: false,
        periodic: Vec::new(),
    };
    // A zone in a family is a region of that name.
    let region = match z.child("FamilyName")? {
        Some(f) if f.label()? == "FamilyName_t" => tags.tag(&family_name(&f.string()?, families)),
        _ => 0,
    };
    if structured {
        structured_cells(&mut zone, cell_dim, region);
        structured_bcs(z, &mut zone, cell_dim, families, tags)?;
    } else {
        let index = sections(z, &mut zone, n_vertices, file_len, region)?;
        unstructured_bcs(z, &mut zone, cell_dim, &index, families, tags)?;
    }
    connectivity(z, &mut zone, cell_dim)?;
    Ok(zone)
}

/// A family's name as a tag name: the family it belongs to (`FamilyName_t` child) if any.
pub fn family_name(name: &str, families: &BTreeMap<String, String>) -> String {
    families
        .get(name)
        .cloned()
        .unwrap_or_else(|| name.to_string())
}

fn coordinates(z: &Node<'_>, n: usize) -> Result<Vec<[f64; 3]>, ParseError> {
    let grids = z.labelled("GridCoordinates_t")?;
    let Some(g) = grids
        .iter()
        .find(|g| g.name == "GridCoordinates")
        .or(grids.first())
    else {
        return Err(z.error("no GridCoordinates node"));
    };
    let mut points = vec![[0.0; 3]; n];
    let mut found = 0;
    for (k, name) in ["CoordinateX", "CoordinateY", "CoordinateZ"]
        .iter()
        .enumerate()
    {
        let Some(c) = g.child(name)? else {
            if k < 2 {
                let others: Vec<String> = g.children()?.into_iter().map(|c| c.name).collect();
                return Err(g.error(format!(
                    "no {name}: only Cartesian coordinates (CoordinateX/Y/Z) are read; found {}",
                    others.join(", ")
                )));
            }
            continue;
        };
        let v = c.reals()?;
        if v.len() != n {
            return Err(c.error(format!("{} values; the zone has {n} vertices", v.len())));
        }
        for (p, x) in points.iter_mut().zip(v) {
            p[k] = x;
        }
        found += 1;
    }
    debug_assert!(found >= 2);
    Ok(points)
}

/// Where element ids of an unstructured zone live: per section, its first id and, per
/// element, (block, cell index).
pub struct ElementIndex {
    ranges: Vec<(i64, Vec<(usize, usize)>)>,
}

impl ElementIndex {
    fn find(&self, id: i64) -> Option<(usize, usize)> {
        self.ranges.iter().find_map(|(start, cells)| {
            let i = id.checked_sub(*start)?;
            usize::try_from(i).ok().and_then(|i| cells.get(i).copied())
        })
    }
}

/// The block of `zone` for cells of `kind` with `npc` nodes, made if missing.
fn block_for(zone: &mut Zone, kind: &CellKind, npc: usize) -> usize {
    if let Some(i) = zone
        .blocks
        .iter()
        .position(|b| &b.kind == kind && b.npc == npc)
    {
        return i;
    }
    zone.blocks.push(Cells {
        kind: kind.clone(),
        npc,
        nodes: Vec::new(),
        tags: Vec::new(),
    });
    zone.blocks.len() - 1
}

fn sections(
    z: &Node<'_>,
    zone: &mut Zone,
    n_vertices: usize,
    file_len: usize,
    region: i32,
) -> Result<ElementIndex, ParseError> {
    let mut index = ElementIndex { ranges: Vec::new() };
    for s in z.labelled("Elements_t")? {
        let (head, _) = s.ints()?;
        let Some(&code) = head.first() else {
            return Err(s.error("no element type"));
        };
        let (range, _) = s.require("ElementRange")?.ints()?;
        if range.len() != 2 || range[0] < 1 || range[1] < range[0] {
            return Err(s.error(format!(
                "ElementRange {range:?} is not a range [first, last] of ids ≥ 1"
            )));
        }
        let count = (range[1] - range[0] + 1) as u64;
        if count > file_len as u64 {
            return Err(s.error(format!(
                "{count} elements cannot be stored in a file of {file_len} bytes"
            )));
        }
        let conn_node = s.require("ElementConnectivity")?;
        let (conn, _) = conn_node.ints()?;
        let node = |n: i64, e: u64| -> Result<usize, ParseError> {
            if n < 1 || n as u64 > n_vertices as u64 {
                return Err(conn_node.error(format!(
                    "element {} refers to vertex {n}; the zone has {n_vertices}",
                    range[0] as u64 + e
                )));
            }
            Ok(n as usize - 1)
        };
        let mut cells = Vec::with_capacity(count as usize);
        if code == 20 {
            // MIXED: each element is its type code, then its nodes.
            let mut at = 0usize;
            for e in 0..count {
                let Some(&t) = conn.get(at) else {
                    return Err(
                        conn_node.error(format!("ends inside element {}", range[0] as u64 + e))
                    );
                };
                let Some((_, npe, kind)) = element_type(t) else {
                    return Err(conn_node.error(format!(
                        "element {} has unknown type code {t}",
                        range[0] as u64 + e
                    )));
                };
                let Some(nodes) = conn.get(at + 1..at + 1 + npe) else {
                    return Err(
                        conn_node.error(format!("ends inside element {}", range[0] as u64 + e))
                    );
                };
                let b = block_for(zone, &kind, npe);
                for &n in nodes {
                    let v = node(n, e)?;
                    zone.blocks[b].nodes.push(v);
                }
                let dim_tag = if kind.dim() == Some(3) || kind.dim() == Some(2) {
                    region
                } else {
                    0
                };
                zone.blocks[b].tags.push(dim_tag);
                cells.push((b, zone.blocks[b].tags.len() - 1));
                at += 1 + npe;
            }
        } else {
            let Some((name, npe, kind)) = element_type(code) else {
                return Err(s.error(format!("element type code {code} is not one polyspline reads (NGON_n/NFACE_n polyhedra and other types are not)")));
            };
            if conn.len() as u64 != count * npe as u64 {
                return Err(conn_node.error(format!(
                    "{} values; {count} {name} elements need {}",
                    conn.len(),
                    count * npe as u64
                )));
            }
            let b = block_for(zone, &kind, npe);
            for (e, c) in conn.chunks(npe).enumerate() {
                for &n in c {
                    let v = node(n, e as u64)?;
                    zone.blocks[b].nodes.push(v);
                }
                zone.blocks[b].tags.push(region);
                cells.push((b, zone.blocks[b].tags.len() - 1));
            }
        }
        index.ranges.push((range[0], cells));
    }
    if zone.blocks.is_empty() {
        return Err(z.error("an unstructured zone without Elements_t sections"));
    }
    Ok(index)
}

/// The name a boundary condition's facets are tagged with: its family's, else its own.
fn bc_name(bc: &Node<'_>, families: &BTreeMap<String, String>) -> Result<String, ParseError> {
    for c in bc.children()? {
        if c.label()? == "FamilyName_t" {
            return Ok(family_name(&c.string()?, families));
        }
    }
    Ok(bc.name.clone())
}

fn grid_location(n: &Node<'_>) -> Result<String, ParseError> {
    Ok(match n.child("GridLocation")? {
        Some(l) => l.string()?,
        None => "Vertex".into(),
    })
}

/// The index data of a BC or connectivity node: (name of the child, values).
fn indices(n: &Node<'_>, names: &[&str]) -> Result<Option<(String, Vec<i64>)>, ParseError> {
    for name in names {
        if let Some(c) = n.child(name)? {
            let (v, _) = c.ints()?;
            return Ok(Some((name.to_string(), v)));
        }
    }
    Ok(None)
}

/// The facets of the zone's volume cells that no other cell of the zone shares.
fn exterior_facets(zone: &Zone, cell_dim: usize) -> Vec<Vec<usize>> {
    let (kind, faces): (CellKind, Vec<&[usize]>) = if cell_dim == 3 {
        (
            CellKind::Hexahedron,
            HEX_SIDES.iter().map(|f| &f[..]).collect(),
        )
    } else {
        (CellKind::Quad, QUAD_SIDES.iter().map(|f| &f[..]).collect())
    };
    let mut count: HashMap<Vec<usize>, (usize, Vec<usize>)> = HashMap::new();
    for b in zone.blocks.iter().filter(|b| b.kind == kind) {
        for c in b.nodes.chunks(b.npc) {
            for f in &faces {
                let nodes: Vec<usize> = f.iter().map(|&i| c[i]).collect();
                let mut key = nodes.clone();
                key.sort_unstable();
                count.entry(key).or_insert((0, nodes)).0 += 1;
            }
        }
    }
    let mut out: Vec<Vec<usize>> = count
        .into_values()
        .filter(|(n, _)| *n == 1)
        .map(|(_, f)| f)
        .collect();
    out.sort_unstable();
    out
}

fn facet_kind(cell_dim: usize) -> (CellKind, usize) {
    if cell_dim == 3 {
        (CellKind::Quad, 4)
    } else {
        (CellKind::Line, 2)
    }
}

/// Tag the facets whose vertices all lie in `set`: the zone's facet cells if it has any,
/// else the exterior facets of its volume cells (added as tagged facets).
fn tag_vertex_set(zone: &mut Zone, cell_dim: usize, set: &HashSet<usize>, tag: i32) {
    let (kind, npf) = facet_kind(cell_dim);
    let mut hit = false;
    for b in zone.blocks.iter_mut().filter(|b| b.kind == kind) {
        for (c, t) in b.nodes.chunks(npf).zip(b.tags.iter_mut()) {
            if c.iter().all(|v| set.contains(v)) {
                *t = tag;
                hit = true;
            }
        }
    }
    if hit || zone.blocks.iter().any(|b| b.kind == kind) {
        return;
    }
    let facets = exterior_facets_within(zone, cell_dim, set);
    add_facets(zone, cell_dim, facets, tag);
}

/// The zone's exterior facets whose vertices all lie in `set`: the faces of a side that the
/// file names only by its vertices.
fn exterior_facets_within(zone: &Zone, cell_dim: usize, set: &HashSet<usize>) -> Vec<Vec<usize>> {
    exterior_facets(zone, cell_dim)
        .into_iter()
        .filter(|f| f.iter().all(|v| set.contains(v)))
        .collect()
}

fn add_facets(zone: &mut Zone, cell_dim: usize, facets: Vec<Vec<usize>>, tag: i32) {
    if facets.is_empty() {
        return;
    }
    let (kind, npf) = facet_kind(cell_dim);
    let b = block_for(zone, &kind, npf);
    for f in facets {
        zone.blocks[b].nodes.extend_from_slice(&f);
        zone.blocks[b].tags.push(tag);
    }
}

fn unstructured_bcs(
    z: &Node<'_>,
    zone: &mut Zone,
    cell_dim: usize,
    index: &ElementIndex,
    families: &BTreeMap<String, String>,
    tags: &mut Tags,
) -> Result<(), ParseError> {
    for zbc in z.labelled("ZoneBC_t")? {
        for bc in zbc.labelled("BC_t")? {
            let tag = tags.tag(&bc_name(&bc, families)?);
            let location = grid_location(&bc)?;
            let Some((what, v)) = indices(
                &bc,
                &["PointRange", "PointList", "ElementRange", "ElementList"],
            )?
            else {
                return Err(bc.error("no PointRange, PointList, ElementRange or ElementList"));
            };
            let ids: Vec<i64> = if what.ends_with("Range") {
                if v.len() != 2 || v[1] < v[0] || (v[1] - v[0]) as u64 > zone_count(zone) {
                    return Err(bc.error(format!("{what} {v:?} is not a range of this zone")));
                }
                (v[0]..=v[1]).collect()
            } else {
                v
            };
            if location == "Vertex" && what.starts_with("Point") {
                let n = zone.points.len() as i64;
                let mut set = HashSet::with_capacity(ids.len());
                for id in ids {
                    if id < 1 || id > n {
                        return Err(bc.error(format!("{what} names vertex {id}; the zone has {n}")));
                    }
                    set.insert(id as usize - 1);
                }
                tag_vertex_set(zone, cell_dim, &set, tag);
            } else {
                for id in ids {
                    let Some((b, c)) = index.find(id) else {
                        return Err(
                            bc.error(format!("{what} names element {id}, which no section holds"))
                        );
                    };
                    zone.blocks[b].tags[c] = tag;
                }
            }
        }
    }
    Ok(())
}

/// Cells of the zone (an upper bound for a range's length).
fn zone_count(zone: &Zone) -> u64 {
    zone.blocks.iter().map(|b| b.tags.len() as u64).sum::<u64>() + zone.points.len() as u64
}

fn structured_cells(zone: &mut Zone, cell_dim: usize, region: i32) {
    let nodes = glue::structured_cells(zone.ijk.expect("structured"), cell_dim);
    let (kind, npc) = if cell_dim == 3 {
        (CellKind::Hexahedron, 8)
    } else {
        (CellKind::Quad, 4)
    };
    zone.blocks.push(Cells {
        kind,
        npc,
        tags: vec![region; nodes.len() / npc],
        nodes,
    });
}

fn structured_bcs(
    z: &Node<'_>,
    zone: &mut Zone,
    cell_dim: usize,
    families: &BTreeMap<String, String>,
    tags: &mut Tags,
) -> Result<(), ParseError> {
    let n = zone.ijk.expect("structured");
    for zbc in z.labelled("ZoneBC_t")? {
        for bc in zbc.labelled("BC_t")? {
            let tag = tags.tag(&bc_name(&bc, families)?);
            let location = grid_location(&bc)?;
            let Some((what, v)) = indices(&bc, &["PointRange", "PointList"])? else {
                return Err(bc.error("no PointRange or PointList"));
            };
            if what == "PointList" {
                if location != "Vertex" {
                    return Err(bc.error(format!(
                        "a PointList at {location}; only vertex lists are read on structured zones"
                    )));
                }
                let mut set = HashSet::new();
                for p in v.chunks(cell_dim) {
                    let ijk = ijk0(p, cell_dim).and_then(|q| zone.flat(q));
                    let Some(f) = ijk else {
                        return Err(bc.error(format!(
                            "PointList names vertex {p:?} outside the zone's {:?}",
                            &n[..cell_dim]
                        )));
                    };
                    set.insert(f);
                }
                let facets: Vec<Vec<usize>> = exterior_facets(zone, cell_dim)
                    .into_iter()
                    .filter(|f| f.iter().all(|v| set.contains(v)))
                    .collect();
                add_facets(zone, cell_dim, facets, tag);
                continue;
            }
            if v.len() != 2 * cell_dim {
                return Err(bc.error(format!(
                    "PointRange has {} values; expected {}",
                    v.len(),
                    2 * cell_dim
                )));
            }
            let (begin, end) = (&v[..cell_dim], &v[cell_dim..]);
            let face_dir = match location.as_str() {
                "IFaceCenter" => Some(0),
                "JFaceCenter" => Some(1),
                "KFaceCenter" => Some(2),
                "Vertex" | "FaceCenter" => None,
                other => {
                    return Err(bc.error(format!(
                        "GridLocation {other} is not read for boundary conditions"
                    )));
                }
            };
            let d = match face_dir {
                Some(d) if d < cell_dim => d,
                Some(d) => {
                    return Err(bc.error(format!(
                        "GridLocation {location} in a {cell_dim}D zone ({d})"
                    )));
                }
                None => {
                    let Some(d) = (0..cell_dim).find(|&a| {
                        begin[a] == end[a] && (begin[a] == 1 || begin[a] == n[a] as i64)
                    }) else {
                        return Err(bc.error(format!(
                            "PointRange {begin:?}–{end:?} is not a face of the block {:?}",
                            &n[..cell_dim]
                        )));
                    };
                    d
                }
            };
            let c = begin[d];
            if begin[d] != end[d] || (c != 1 && c != n[d] as i64) {
                return Err(bc.error(format!(
                    "PointRange {begin:?}–{end:?} is not on the block's boundary"
                )));
            }
            let (mut lo, mut hi) = ([0usize; 3], [0usize; 3]);
            for a in (0..cell_dim).filter(|&a| a != d) {
                let (x, y) = (begin[a].min(end[a]), begin[a].max(end[a]));
                // Vertex ranges span vertices x..=y, hence cells x..y; face-centre ranges cells.
                let (l, h) = if face_dir.is_some() || location == "FaceCenter" {
                    (x - 1, y)
                } else {
                    (x - 1, y - 1)
                };
                if x < 1 || h > n[a] as i64 - 1 || l >= h {
                    return Err(bc.error(format!(
                        "PointRange {begin:?}–{end:?} lies outside the block {:?}",
                        &n[..cell_dim]
                    )));
                }
                lo[a] = l as usize;
                hi[a] = h as usize;
            }
            let n = zone.ijk.expect("structured");
            let npf = if cell_dim == 3 { 4 } else { 2 };
            let facets = glue::structured_face(n, cell_dim, d, c as usize - 1, lo, hi)
                .chunks(npf)
                .map(<[usize]>::to_vec)
                .collect();
            add_facets(zone, cell_dim, facets, tag);
        }
    }
    Ok(())
}

/// 1-based IJK values → 0-based, if all are ≥ 1.
fn ijk0(p: &[i64], cell_dim: usize) -> Option<[usize; 3]> {
    let mut q = [0usize; 3];
    for a in 0..cell_dim {
        let v = *p.get(a)?;
        if v < 1 {
            return None;
        }
        q[a] = v as usize - 1;
    }
    Some(q)
}

fn connectivity(z: &Node<'_>, zone: &mut Zone, cell_dim: usize) -> Result<(), ParseError> {
    for zgc in z.labelled("ZoneGridConnectivity_t")? {
        for gc in zgc.children()? {
            let label = gc.label()?;
            if label != "GridConnectivity1to1_t" && label != "GridConnectivity_t" {
                continue;
            }
            zone.has_connectivity = true;
            // A periodic interface joins faces that do not coincide: not glued, but kept as
            // the file's claim of a periodic pair.
            let periodic = match gc.child("GridConnectivityProperty")? {
                Some(p) => p.child("Periodic")?,
                None => None,
            };
            let links = connection_links(&gc, zone, cell_dim, &label)?;
            match (periodic, links) {
                (Some(p), links) => {
                    let claim = periodic_claim(&gc, &p, links.unwrap_or_default())?;
                    zone.periodic.push(claim);
                }
                (None, Some(links)) => zone.links.extend(links),
                // Face-located lists: the zones are glued at coincident vertices instead.
                (None, None) => zone.has_connectivity = false,
            }
        }
    }
    Ok(())
}

/// The periodic map of connection `gc` (its `Periodic_t` node `p`): x' = R (x − c) + c + T
/// from `RotationCenter` c, `RotationAngle` (about x, then y, then z; radians unless a
/// `DimensionalUnits` child of the angle or of `Periodic_t` says degrees) and `Translation` T.
fn periodic_claim(
    gc: &Node<'_>,
    p: &Node<'_>,
    links: Vec<Link>,
) -> Result<PeriodicClaim, ParseError> {
    let mut precision = f64::EPSILON;
    let mut vector = |name: &str| -> Result<([f64; 3], Option<Node<'_>>), ParseError> {
        let Some(n) = p.child(name)? else {
            return Ok(([0.0; 3], None));
        };
        let v = n.reals()?;
        if v.len() > 3 || v.iter().any(|x| !x.is_finite()) {
            return Err(n.error(format!("{v:?} is not a vector of up to 3 finite reals")));
        }
        if n.data_type()? == "R4" {
            precision = f64::from(f32::EPSILON);
        }
        Ok((
            std::array::from_fn(|i| v.get(i).copied().unwrap_or(0.0)),
            Some(n),
        ))
    };
    let (center, _) = vector("RotationCenter")?;
    let (mut angles, angle_node) = vector("RotationAngle")?;
    let (translation, _) = vector("Translation")?;
    let degrees = |n: &Node<'_>| -> Result<bool, ParseError> {
        Ok(match n.child("DimensionalUnits")? {
            Some(u) => u.string()?.contains("Degree"),
            None => false,
        })
    };
    if degrees(p)? || angle_node.as_ref().map(degrees).transpose()? == Some(true) {
        angles = angles.map(f64::to_radians);
    }
    Ok(PeriodicClaim {
        map: Rigid::from_center_angles_translation(center, angles, translation),
        precision,
        own: links.iter().map(|l| l.node).collect(),
        path: gc.path.clone().into(),
    })
}

/// Give the facets of a periodic side a boundary group where the file leaves them without
/// one: the facet cells whose vertices all lie in `own` when none of them is tagged, or the
/// zone's exterior facets there when it has no facet cells there. Sides that carry a boundary
/// condition keep it.
pub fn tag_periodic_side(
    zone: &mut Zone,
    cell_dim: usize,
    own: &[usize],
    tag: impl FnOnce() -> i32,
) {
    let set: HashSet<usize> = own.iter().copied().collect();
    let (kind, npf) = facet_kind(cell_dim);
    let mut covered = Vec::new();
    for (b, block) in zone
        .blocks
        .iter()
        .enumerate()
        .filter(|(_, b)| b.kind == kind)
    {
        for (i, c) in block.nodes.chunks(npf).enumerate() {
            if c.iter().all(|v| set.contains(v)) {
                covered.push((b, i));
            }
        }
    }
    if covered.iter().any(|&(b, i)| zone.blocks[b].tags[i] != 0) {
        return;
    }
    if !covered.is_empty() {
        let t = tag();
        for (b, i) in covered {
            zone.blocks[b].tags[i] = t;
        }
        return;
    }
    let facets = exterior_facets_within(zone, cell_dim, &set);
    if !facets.is_empty() {
        add_facets(zone, cell_dim, facets, tag());
    }
}

/// The vertex links of one connection node (`GridConnectivity_t` or `GridConnectivity1to1_t`):
/// `None` where the file gives them by faces (or without a donor list).
fn connection_links(
    gc: &Node<'_>,
    zone: &Zone,
    cell_dim: usize,
    label: &str,
) -> Result<Option<Vec<Link>>, ParseError> {
    let path: std::rc::Rc<str> = gc.path.clone().into();
    let mut links = Vec::new();
    let donor = gc.string()?;
    if label == "GridConnectivity_t" {
        let kind = match gc.child("GridConnectivityType")? {
            Some(t) => t.string()?,
            None => "Overset".into(),
        };
        match kind.as_str() {
            "Abutting1to1" => {}
            "Overset" => return Err(gc.error("an overset interface; overlapping zones cannot be merged into one conforming mesh")),
            other => return Err(gc.error(format!("a {other} interface; only point-matched (Abutting1to1) zones can be merged into one conforming mesh"))),
        }
        if grid_location(gc)? != "Vertex" {
            // Face-located lists: the zones are glued at coincident vertices instead.
            return Ok(None);
        }
        let (own, _) = gc.require("PointList")?.ints()?;
        let Some(d) = gc.child("PointListDonor")? else {
            return Ok(None);
        };
        let (other, _) = d.ints()?;
        let per = if zone.ijk.is_some() { cell_dim } else { 1 };
        if own.len() != other.len() || own.len() % per != 0 {
            return Err(gc.error(format!(
                "PointList has {} values, PointListDonor {}",
                own.len(),
                other.len()
            )));
        }
        for (a, b) in own.chunks(per).zip(other.chunks(per)) {
            let node = local(zone, a, cell_dim).ok_or_else(|| {
                gc.error(format!("PointList names vertex {a:?} outside the zone"))
            })?;
            let donor_node = if per == 1 {
                if b[0] < 1 {
                    return Err(gc.error(format!("PointListDonor names vertex {}", b[0])));
                }
                DonorIndex::Flat(b[0] as usize - 1)
            } else {
                DonorIndex::Ijk(
                    ijk0(b, cell_dim)
                        .ok_or_else(|| gc.error(format!("PointListDonor names vertex {b:?}")))?,
                )
            };
            links.push(Link {
                node,
                donor: donor.clone(),
                donor_node,
                path: path.clone(),
            });
        }
        return Ok(Some(links));
    }
    // 1-to-1: PointRange ↦ PointRangeDonor through Transform.
    if zone.ijk.is_none() {
        return Err(gc.error("a 1-to-1 connection in an unstructured zone"));
    }
    let (r, _) = gc.require("PointRange")?.ints()?;
    let (rd, _) = gc.require("PointRangeDonor")?.ints()?;
    let t: Vec<i64> = match gc.child("Transform")? {
        Some(t) => t.ints()?.0,
        None => (1..=cell_dim as i64).collect(),
    };
    if r.len() != 2 * cell_dim || rd.len() != 2 * cell_dim || t.len() != cell_dim {
        return Err(
            gc.error("PointRange, PointRangeDonor and Transform do not match the zone's dimension")
        );
    }
    let mut used = [false; 3];
    for &ta in &t {
        let b = ta.unsigned_abs() as usize;
        if b == 0 || b > cell_dim || used[b - 1] {
            return Err(gc.error(format!("Transform {t:?} is not a signed permutation")));
        }
        used[b - 1] = true;
    }
    let (b0, e0) = (&r[..cell_dim], &r[cell_dim..]);
    let (db, de) = (&rd[..cell_dim], &rd[cell_dim..]);
    for a in 0..cell_dim {
        let b = t[a].unsigned_abs() as usize - 1;
        if (e0[a] - b0[a]).abs() != (de[b] - db[b]).abs() {
            return Err(gc.error(format!(
                "PointRange {r:?} and PointRangeDonor {rd:?} differ in size under Transform {t:?}"
            )));
        }
    }
    let span = |a: usize| -> Vec<i64> {
        let s = if e0[a] >= b0[a] { 1 } else { -1 };
        (0..=(e0[a] - b0[a]).abs()).map(|k| b0[a] + s * k).collect()
    };
    let ranges: Vec<Vec<i64>> = (0..3)
        .map(|a| if a < cell_dim { span(a) } else { vec![1] })
        .collect();
    if ranges.iter().map(|x| x.len() as u64).product::<u64>() > zone.points.len() as u64 {
        return Err(gc.error("PointRange is larger than the zone"));
    }
    for &k in &ranges[2] {
        for &j in &ranges[1] {
            for &i in &ranges[0] {
                let idx = [i, j, k];
                let node = local(zone, &idx[..cell_dim], cell_dim).ok_or_else(|| {
                    gc.error(format!(
                        "PointRange names vertex {:?} outside the zone",
                        &idx[..cell_dim]
                    ))
                })?;
                let mut dn = [1i64; 3];
                for a in 0..cell_dim {
                    let b = t[a].unsigned_abs() as usize - 1;
                    dn[b] = db[b] + t[a].signum() * (idx[a] - b0[a]);
                }
                let donor_node =
                    DonorIndex::Ijk(ijk0(&dn[..cell_dim], cell_dim).ok_or_else(|| {
                        gc.error(format!(
                            "PointRangeDonor names vertex {:?}",
                            &dn[..cell_dim]
                        ))
                    })?);
                links.push(Link {
                    node,
                    donor: donor.clone(),
                    donor_node,
                    path: path.clone(),
                });
            }
        }
    }
    Ok(Some(links))
}

/// A zone's vertex from 1-based indices (IJK for structured zones, one id otherwise).
fn local(zone: &Zone, idx: &[i64], cell_dim: usize) -> Option<usize> {
    if zone.ijk.is_some() {
        zone.flat(ijk0(idx, cell_dim)?)
    } else {
        let id = *idx.first()?;
        (id >= 1 && id as usize <= zone.points.len()).then(|| id as usize - 1)
    }
}

/// The vertices on the zone's outer facets (a structured zone's six faces, or the exterior
/// facets of an unstructured zone's volume cells).
pub fn outer_vertices(zone: &Zone, cell_dim: usize) -> Vec<usize> {
    let mut out: Vec<usize> = exterior_facets(zone, cell_dim)
        .into_iter()
        .flatten()
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}
