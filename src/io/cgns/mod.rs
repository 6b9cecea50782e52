//! CGNS input and output (read: CGNS/HDF5 and the older ADF container; write: CGNS/HDF5).
//!
//! Read ([`read`]): the one `CGNSBase_t` that holds zones (cell dimension 2 or 3), and each of
//! its `Zone_t`s:
//! * unstructured zones: `Elements_t` sections of any linear type (`QUAD_4`, `HEXA_8`, `BAR_2`
//!   boundary sections, ...; `MIXED` sections element by element; the Lagrange types
//!   `QUAD_9/16/25` and `HEXA_27/64/125` as high-order cells in CGNS node order, which
//!   `LinearMesh::from_raw` refuses and `HighOrderMesh::from_raw` reads); `NGON_n`/`NFACE_n`
//!   polyhedra are refused;
//! * structured zones: the IJK block's cells as quadrilaterals (2D) or hexahedra (3D), vertex
//!   (i, j, k) at index i + ni (j + nj k);
//! * coordinates: `CoordinateX/Y[/Z]` of the zone's `GridCoordinates` (single or double);
//! * boundary conditions (`ZoneBC` → `BC_t`): by `PointRange`/`PointList` of vertices (the
//!   facets whose vertices all lie in the patch), of faces (`GridLocation` `FaceCenter`,
//!   `EdgeCenter`, `IFaceCenter`, ...) or of elements (`ElementRange`/`ElementList`), tagged with
//!   the BC's `FamilyName` (resolved through the family's own `FamilyName`, as Gmsh writes
//!   physical names), else the BC's name; a BC naming volume elements names a region, as does
//!   a zone's `FamilyName`;
//! * several zones are merged into one mesh: by their `ZoneGridConnectivity` (1-to-1
//!   `PointRange`/`PointRangeDonor`/`Transform`, or `Abutting1to1` vertex `PointList`s) when
//!   every zone has some, the joined vertices checked to coincide within [`crate::io::glue::TOLERANCE`] of the
//!   local edge length; otherwise by coincident vertices on the zones' outer facets within the
//!   same tolerance. Overset and non-matching interfaces are refused;
//! * periodic connections (`GridConnectivityProperty/Periodic`) are not glued: each map
//!   (`RotationCenter`, `RotationAngle`, `Translation`; one per map and its inverse) becomes a
//!   [`DeclaredPeriodic`] claim whose sides are the boundary groups the map carries onto each
//!   other, found and verified on the mesh ([`crate::mesh::periodic::resolve`]). A side that
//!   carries no boundary condition becomes a group named after its connection node, where the
//!   connection lists its vertices.
//!
//! Errors are one line naming the node's path (`/Base/Zone1/GridCoordinates: ...`).
//! Write: [`mod@write`] (the curved mesh as one unstructured zone, its periodic pairs as
//! grid connectivity with `Periodic_t`, `periodic`).
//!
//! Parts: `tree` the node tree (HDF5 or ADF) and its memory bound, `adf` the ADF container,
//! `zone` one zone, `ordering` the CGNS node orders, `write` the writer; this module the base,
//! the families and the merge.

mod adf;
pub mod ordering;
mod periodic;
mod tree;
pub mod write;
mod zone;

#[cfg(test)]
mod tests;

pub use tree::container;

use crate::io::glue::{Glue, Part};
use crate::mesh::periodic::Rigid;
use crate::mesh::raw::{DeclaredPeriodic, Location, ParseError, RawBlock, RawMesh};
use std::collections::{BTreeMap, HashMap};
use zone::{DonorIndex, Zone};

/// Tag ids of names, shared by boundary conditions and regions (1, 2, ... in order of use).
#[derive(Default)]
pub struct Tags {
    ids: BTreeMap<String, i32>,
}

impl Tags {
    /// The tag of `name`, made on first use.
    pub fn tag(&mut self, name: &str) -> i32 {
        let next = self.ids.len() as i32 + 1;
        *self.ids.entry(name.to_string()).or_insert(next)
    }
}

/// Read a CGNS file (HDF5 or ADF) held in memory.
pub fn read(data: &[u8]) -> Result<RawMesh, ParseError> {
    let t = tree::Tree::open(data)?;
    let root = t.root()?;
    let mut bases = Vec::new();
    for b in root.labelled("CGNSBase_t")? {
        if !b.labelled("Zone_t")?.is_empty() {
            bases.push(b);
        }
    }
    let base = match bases.len() {
        0 => return Err(root.error("no CGNSBase_t node with a zone")),
        1 => bases.remove(0),
        _ => {
            let names: Vec<&str> = bases.iter().map(|b| b.name.as_str()).collect();
            return Err(root.error(format!(
                "{} bases with zones ({}); polyspline reads one mesh, so keep one base",
                names.len(),
                names.join(", ")
            )));
        }
    };
    let (dims, _) = base.ints()?;
    let cell_dim = match dims.first() {
        Some(&d @ (2 | 3)) => d as usize,
        d => {
            return Err(base.error(format!(
                "cell dimension {d:?}; polyspline reads quadrilateral (2) and hexahedral (3) meshes"
            )));
        }
    };
    // Family → the family it belongs to (Gmsh's physical name), where it names one.
    let mut families = BTreeMap::new();
    for f in base.labelled("Family_t")? {
        for c in f.children()? {
            if c.label()? == "FamilyName_t" {
                families.insert(f.name.clone(), c.string()?);
                break;
            }
        }
    }
    let mut tags = Tags::default();
    let mut zones = Vec::new();
    for z in base.labelled("Zone_t")? {
        zones.push(zone::read(&z, cell_dim, data.len(), &families, &mut tags)?);
    }
    let mut claims = Vec::new();
    for z in &mut zones {
        for c in std::mem::take(&mut z.periodic) {
            let name = c.path.rsplit('/').next().unwrap_or("periodic").to_string();
            zone::tag_periodic_side(z, cell_dim, &c.own, || tags.tag(&name));
            claims.push(c);
        }
    }
    let mut mesh = glue(&zones, cell_dim)?;
    mesh.periodic = declared_periodic(claims, cell_dim);
    mesh.declared_dim = dims.get(1).map(|&d| d.clamp(1, 3) as usize);
    mesh.tag_names = tags.ids.into_iter().map(|(n, t)| (t, n)).collect();
    Ok(mesh)
}

/// The periodic maps the connections declare, one per map: a connection whose map (or its
/// inverse, the donor's view of the same pair) was already kept adds nothing. Which boundary
/// groups each map pairs is found on the mesh ([`crate::mesh::periodic::resolve`]).
fn declared_periodic(claims: Vec<zone::PeriodicClaim>, cell_dim: usize) -> Vec<DeclaredPeriodic> {
    let mut kept: Vec<zone::PeriodicClaim> = Vec::new();
    for c in claims {
        let same = |a: &Rigid, b: &Rigid| {
            let scale = 1.0 + b.translation.iter().map(|x| x.abs()).fold(0.0, f64::max);
            let tol = 1e3 * c.precision.max(f64::EPSILON);
            (0..3).all(|i| {
                (a.translation[i] - b.translation[i]).abs() <= tol * scale
                    && (0..3).all(|j| (a.rotation[i][j] - b.rotation[i][j]).abs() <= tol)
            })
        };
        if !kept
            .iter()
            .any(|k| same(&k.map, &c.map) || same(&k.map.inverse(), &c.map))
        {
            kept.push(c);
        }
    }
    kept.into_iter()
        .map(|c| DeclaredPeriodic {
            dim: cell_dim - 1,
            sides: None,
            source: format!("CGNS periodic connection {}", c.path),
            affine: Some(c.map.affine()),
            precision: c.precision,
            location: Location::Tree,
        })
        .collect()
}

/// Merge the zones into one mesh (module docs).
fn glue(zones: &[Zone], cell_dim: usize) -> Result<RawMesh, ParseError> {
    let corners = if cell_dim == 3 { 8 } else { 4 };
    let parts: Vec<Part<'_>> = zones
        .iter()
        .map(|z| Part {
            points: &z.points,
            cells: z
                .blocks
                .iter()
                .filter(|b| b.kind.dim() == Some(cell_dim) && b.npc >= corners)
                .flat_map(|b| b.nodes.chunks(b.npc).map(|c| &c[..corners]))
                .collect(),
            outer: if zones.len() > 1 {
                zone::outer_vertices(z, cell_dim)
            } else {
                Vec::new()
            },
        })
        .collect();
    let mut glue = Glue::new(&parts);
    if zones.len() > 1 {
        let by_name: HashMap<&str, usize> = zones
            .iter()
            .enumerate()
            .map(|(i, z)| (z.name.as_str(), i))
            .collect();
        for (zi, z) in zones.iter().enumerate() {
            for l in &z.links {
                // Gmsh writes donor names with blanks where its zone names have underscores.
                let d = by_name
                    .get(l.donor.as_str())
                    .or_else(|| by_name.get(l.donor.replace(' ', "_").as_str()));
                let Some(&d) = d else {
                    return Err(tree::error(
                        &l.path,
                        format!("donor zone {:?} is not in the base", l.donor),
                    ));
                };
                let dn = match l.donor_node {
                    DonorIndex::Flat(n) => (n < zones[d].points.len()).then_some(n),
                    DonorIndex::Ijk(ijk) => zones[d].flat(ijk),
                };
                let Some(dn) = dn else {
                    return Err(tree::error(
                        &l.path,
                        format!("names a vertex outside zone {}", zones[d].name),
                    ));
                };
                let (a, b) = (glue.global(zi, l.node), glue.global(d, dn));
                glue.join_checked(a, b).map_err(|g| {
                    tree::error(
                        &l.path,
                        format!(
                            "joins vertex {} of zone {} to vertex {} of zone {}, {:.3e} apart (shortest edge there {:.3e})",
                            l.node + 1,
                            z.name,
                            dn + 1,
                            zones[d].name,
                            g.gap,
                            g.edge
                        ),
                    )
                })?;
            }
        }
        if zones.iter().any(|z| !z.has_connectivity) {
            glue.coincident();
        }
    }
    let offsets: Vec<usize> = (0..zones.len()).map(|k| glue.global(k, 0)).collect();
    let (id, points) = glue.numbering();
    let mut mesh = RawMesh {
        points,
        ..Default::default()
    };
    // One block per kind over all zones.
    let mut kinds = Vec::new();
    for z in zones {
        for b in &z.blocks {
            if !kinds.contains(&(b.kind.clone(), b.npc)) {
                kinds.push((b.kind.clone(), b.npc));
            }
        }
    }
    for (kind, npc) in kinds {
        let mut raw = RawBlock::new(kind.clone(), npc);
        for (z, o) in zones.iter().zip(&offsets) {
            for b in z.blocks.iter().filter(|b| b.kind == kind && b.npc == npc) {
                raw.nodes.extend(b.nodes.iter().map(|&v| id[o + v] as i64));
                raw.tags.extend_from_slice(&b.tags);
            }
        }
        if raw.tags.iter().all(|&t| t == 0) {
            raw.tags.clear();
        }
        mesh.blocks.push(raw);
    }
    if mesh.blocks.is_empty() {
        return Err(ParseError::new(
            Location::Tree,
            "/: the zones hold no cells",
        ));
    }
    Ok(mesh)
}
