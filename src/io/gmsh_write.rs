//! Gmsh MSH 4.1 and 2.2 output (ASCII or binary) of a [`HighOrderMesh`].
//!
//! Input: a high-order mesh (orders 1–10 for quads, 1–9 for hexes). Output: elements as
//! Lagrange quads/hexes of the mesh's order (types 3/10/36/… and 5/12/92/…), the boundary facets
//! as Lagrange lines/quads of the same order, nodes in Gmsh's order
//! ([`crate::io::ordering`]). Invariants, so that solvers read the file unchanged (PyFR's
//! importer is the strictest): every element and facet is in exactly one physical group, every
//! group is named, physical ids are unique over all dimensions, and the volume group is named
//! `fluid` (or the caller's name) when the input names no region. Boundary tags become groups
//! of dimension d−1 named from the input (or `boundary_<tag>`); untagged facets form a group
//! named `boundary` (when nothing is tagged) or `untagged`. MSH 4.1 writes one geometric
//! entity per physical group in `$Entities`, as HOPR and other solvers' readers require.
//!
//! `Blocks` is the one MSH 4.1 encoding of `$Entities`, of node blocks and of element
//! blocks: the serial file here, and the distributed job's collective file and partitioned
//! parts, which hand it a rank's own nodes and elements with their global tags, so every MSH
//! 4.1 file is written by the same code.

use super::output::WriteBin;
use crate::io::ordering::{gmsh_hex, gmsh_line, gmsh_quad, gmsh_type, to_indices};
use crate::mesh::HighOrderMesh;
use std::collections::BTreeMap;
use std::io::{self, Write};

/// MSH format version to write (`--msh-version`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MshVersion {
    V41,
    V22,
}

/// One physical group with its geometric entity.
pub(crate) struct Group {
    pub(crate) dim: usize,
    /// Entity tag (1-based per dimension).
    pub(crate) entity: i32,
    pub(crate) physical: i32,
    pub(crate) name: String,
    /// The boundary or region tag whose members the group holds (0 = untagged).
    pub(crate) tag: i32,
    /// Element indices (into elements or boundary facets) in this group.
    pub(crate) members: Vec<usize>,
}

/// Name of the volume group when the input names no region (PyFR takes its volume from a
/// physical group of this name).
pub const DEFAULT_VOLUME_NAME: &str = "fluid";

/// The physical groups of `mesh`: boundary groups (dimension d−1) first, then volume groups.
/// Physical ids are unique over all dimensions (PyFR refuses a file where a boundary and a
/// volume group share an id, though Gmsh allows it) and every group is named. Boundary groups
/// keep the input's tags as ids and its names (else `boundary_<tag>`); untagged facets get the
/// next free id and the name `boundary` (nothing tagged) or `untagged`. Volume groups keep
/// region tags unless one clashes with a boundary id, then all are shifted past the boundary
/// ids; the unnamed regions (a region whose tag is also a boundary tag counts as unnamed) form
/// one group named `volume_name`, joined by a region of that name if the input has one. Groups
/// of one dimension and physical id are merged into one.
pub(crate) fn groups(mesh: &HighOrderMesh, volume_name: &str) -> Vec<Group> {
    let by_tag = |tags: &[i32], n: usize| {
        let mut by: BTreeMap<i32, Vec<usize>> = BTreeMap::new();
        for i in 0..n {
            // Non-positive tags are not ids a reader accepts: they count as untagged.
            let t = tags.get(i).copied().unwrap_or(0).max(0);
            by.entry(t).or_default().push(i);
        }
        by
    };
    let mut bnd = by_tag(&mesh.boundary_tags, mesh.n_boundary());
    let mut vol = by_tag(&mesh.element_tags, mesh.n_elements());
    let mut out: Vec<Group> = Vec::new();
    for g in group_plan(
        mesh.dim,
        bnd.keys().copied(),
        vol.keys().copied(),
        &mesh.tag_names,
        volume_name,
    ) {
        let members = if g.dim == mesh.dim {
            vol.remove(&g.tag)
        } else {
            bnd.remove(&g.tag)
        }
        .unwrap_or_default();
        match out
            .iter_mut()
            .find(|o| o.dim == g.dim && o.physical == g.physical)
        {
            Some(o) => {
                o.members.extend(members);
                o.members.sort_unstable();
            }
            None => out.push(Group {
                dim: g.dim,
                entity: g.entity,
                physical: g.physical,
                name: g.name,
                tag: g.tag,
                members,
            }),
        }
    }
    out
}

/// One physical group of [`group_plan`]: the tag (boundary or region, 0 = untagged) whose
/// members it holds, and its dimension, entity tag, physical id and name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlannedGroup {
    pub dim: usize,
    pub tag: i32,
    pub entity: i32,
    pub physical: i32,
    pub name: String,
}

/// `$MeshFormat` (version `vstr`, ASCII or binary with its endianness marker) and
/// `$PhysicalNames` of `groups` as (dimension, physical id, name): the header of the serial
/// and of the collective (`distributed::write`) MSH writers alike.
pub(crate) fn write_format_and_names<'a>(
    w: &mut impl Write,
    vstr: &str,
    binary: bool,
    groups: impl Iterator<Item = (usize, i32, &'a str)>,
) -> io::Result<()> {
    // Several entities may share a physical group: its name is written once.
    let mut names: Vec<(usize, i32, &str)> = Vec::new();
    for g in groups {
        if !names.iter().any(|n| n.0 == g.0 && n.1 == g.1) {
            names.push(g);
        }
    }
    writeln!(w, "$MeshFormat\n{vstr} {} 8", binary as i32)?;
    if binary {
        w.i32(1)?;
        writeln!(w)?;
    }
    writeln!(w, "$EndMeshFormat")?;
    writeln!(w, "$PhysicalNames\n{}", names.len())?;
    for (dim, physical, name) in names {
        writeln!(w, "{dim} {physical} \"{}\"", name.replace('"', "'"))?;
    }
    writeln!(w, "$EndPhysicalNames")
}

/// The physical groups of a mesh of dimension `d` whose boundary facets carry the tags
/// `boundary_tags` and whose elements the tags `element_tags` (each non-negative, increasing,
/// 0 = untagged), in the order [`write_msh`] writes them (see `groups`). It needs only the
/// tags present, so ranks that each hold part of a mesh agree on it once they have agreed on
/// the tags.
pub fn group_plan(
    d: usize,
    boundary_tags: impl Iterator<Item = i32>,
    element_tags: impl Iterator<Item = i32>,
    tag_names: &BTreeMap<i32, String>,
    volume_name: &str,
) -> Vec<PlannedGroup> {
    let mut out = Vec::new();
    let bnd: Vec<i32> = boundary_tags.collect();
    let bnd_tags: std::collections::BTreeSet<i32> = bnd.iter().copied().collect();
    let bnd_fresh = bnd.iter().copied().max().unwrap_or(0) + 1;
    let only_untagged = bnd == [0];
    for (k, &tag) in bnd.iter().enumerate() {
        let (physical, name) = if tag == 0 {
            let name = if only_untagged {
                "boundary"
            } else {
                "untagged"
            };
            (bnd_fresh, name.to_string())
        } else {
            let name = tag_names
                .get(&tag)
                .cloned()
                .unwrap_or_else(|| format!("boundary_{tag}"));
            (tag, name)
        };
        out.push(PlannedGroup {
            dim: d - 1,
            tag,
            entity: k as i32 + 1,
            physical,
            name,
        });
    }
    let bnd_ids: std::collections::BTreeSet<i32> = out.iter().map(|g| g.physical).collect();
    let bnd_max = bnd_ids.iter().copied().max().unwrap_or(0);

    let vol: Vec<i32> = element_tags.collect();
    let clash = vol.iter().any(|t| *t > 0 && bnd_ids.contains(t));
    let shift = if clash { bnd_max } else { 0 };
    let vol_max = vol.iter().copied().max().unwrap_or(0);
    let vol_fresh = (vol_max + shift).max(bnd_max) + 1;
    // Tag names are one map for boundary and region tags: a name of a tag that is also a
    // boundary tag belongs to the boundary group.
    let named = |tag: i32| -> Option<String> {
        if tag == 0 || bnd_tags.contains(&tag) {
            None
        } else {
            tag_names.get(&tag).cloned()
        }
    };
    // The unnamed regions form one group named `volume_name` (PyFR reads its volume from one
    // group), with a named region of that name if there is one.
    let shared = vol
        .iter()
        .find(|&&t| named(t).as_deref() == Some(volume_name))
        .or_else(|| vol.iter().find(|&&t| named(t).is_none()))
        .map(|&t| if t == 0 { vol_fresh } else { t + shift });
    for (k, &tag) in vol.iter().enumerate() {
        let (physical, name) = match named(tag) {
            Some(n) if n != volume_name => (tag + shift, n),
            _ => (
                shared.expect("an unnamed region or one of that name"),
                volume_name.to_string(),
            ),
        };
        out.push(PlannedGroup {
            dim: d,
            tag,
            entity: k as i32 + 1,
            physical,
            name,
        });
    }
    out
}

/// Write `mesh` as MSH `version`, ASCII or binary, the volume group named
/// [`DEFAULT_VOLUME_NAME`] where the input names none.
pub fn write_msh(
    mesh: &HighOrderMesh,
    version: MshVersion,
    binary: bool,
    w: &mut impl Write,
) -> io::Result<()> {
    write_msh_named(mesh, version, binary, DEFAULT_VOLUME_NAME, w)
}

/// [`write_msh`] with `volume_name` for the volume group where the input names none.
pub fn write_msh_named(
    mesh: &HighOrderMesh,
    version: MshVersion,
    binary: bool,
    volume_name: &str,
    w: &mut impl Write,
) -> io::Result<()> {
    let msh = Msh::new(mesh, binary, volume_name)?;
    msh.header(version, w)?;
    match version {
        MshVersion::V41 => {
            msh.entities_v41(w)?;
            msh.nodes_v41(w)?;
            msh.elements_v41(w)?;
        }
        MshVersion::V22 => {
            msh.nodes_v22(w)?;
            msh.elements_v22(w)?;
        }
    }
    msh.periodic(version, w)
}

/// The MSH 4.1 encoding of one file's entities and blocks (ASCII or binary), with the Gmsh
/// types and node orders of its elements (dimension `d`, order p) and boundary facets
/// (dimension d − 1). Nodes are given in lattice order with the tag each has in the file less
/// a `base` (the serial mesh's 0-based indices have base 1; global tags base 0).
pub(crate) struct Blocks {
    pub(crate) binary: bool,
    /// Dimension of the elements (facets have `d - 1`).
    pub(crate) d: usize,
    vol_order: Vec<usize>,
    bnd_order: Vec<usize>,
    vol_type: i32,
    bnd_type: i32,
}

impl Blocks {
    /// The encoding of order-`p` elements of dimension `d`; an error when Gmsh has no such
    /// Lagrange element.
    pub(crate) fn new(d: usize, p: usize, binary: bool) -> io::Result<Self> {
        Ok(Blocks {
            binary,
            d,
            vol_order: to_indices(p, &if d == 2 { gmsh_quad(p) } else { gmsh_hex(p) }),
            bnd_order: to_indices(p, &if d == 2 { gmsh_line(p) } else { gmsh_quad(p) }),
            vol_type: gmsh_type(d, p).ok_or_else(|| unsupported(d, p))? as i32,
            bnd_type: gmsh_type(d - 1, p).ok_or_else(|| unsupported(d - 1, p))? as i32,
        })
    }

    /// The Gmsh element type of the elements (`dim == d`) or of the boundary facets.
    pub(crate) fn kind(&self, dim: usize) -> i32 {
        if dim == self.d {
            self.vol_type
        } else {
            self.bnd_type
        }
    }

    fn order(&self, dim: usize) -> &[usize] {
        if dim == self.d {
            &self.vol_order
        } else {
            &self.bnd_order
        }
    }

    /// Four `size_t` of a section's or block's header.
    pub(crate) fn four(&self, w: &mut impl Write, v: [u64; 4]) -> io::Result<()> {
        if self.binary {
            v.iter().try_for_each(|&x| w.u64(x))
        } else {
            writeln!(w, "{} {} {} {}", v[0], v[1], v[2], v[3])
        }
    }

    /// A block's header: the entity's dimension and tag, the element type (0 for a node
    /// block: no parametric coordinates) and the block's size.
    pub(crate) fn block_header(
        &self,
        w: &mut impl Write,
        dim: usize,
        entity: i32,
        kind: i32,
        count: u64,
    ) -> io::Result<()> {
        if self.binary {
            w.i32(dim as i32)?;
            w.i32(entity)?;
            w.i32(kind)?;
            w.u64(count)
        } else {
            writeln!(w, "{dim} {entity} {kind} {count}")
        }
    }

    /// The end of section `name` (`$End<name>`, after the binary data's newline).
    pub(crate) fn end(&self, w: &mut impl Write, name: &str) -> io::Result<()> {
        if self.binary {
            writeln!(w)?;
        }
        writeln!(w, "$End{name}")
    }

    /// `$Entities`: one entity of each `(dimension, tag, physical id)` of `groups`, with the
    /// box `bbox(i)` of the `i`-th, listed by dimension.
    pub(crate) fn entities(
        &self,
        w: &mut impl Write,
        groups: &[(usize, i32, i32)],
        bbox: impl Fn(usize) -> [f64; 6],
    ) -> io::Result<()> {
        let mut count = [0u64; 4];
        for g in groups {
            count[g.0] += 1;
        }
        writeln!(w, "$Entities")?;
        self.four(w, count)?;
        for dim in 1..=3 {
            for (i, &(_, entity, physical)) in groups.iter().enumerate().filter(|g| g.1.0 == dim) {
                let b = bbox(i);
                if self.binary {
                    w.i32(entity)?;
                    for v in b {
                        w.f64(v)?;
                    }
                    w.u64(1)?;
                    w.i32(physical)?;
                    w.u64(0)?;
                } else {
                    writeln!(
                        w,
                        "{entity} {} {} {} {} {} {} 1 {physical} 0",
                        b[0], b[1], b[2], b[3], b[4], b[5]
                    )?;
                }
            }
        }
        self.end(w, "Entities")
    }

    /// A node block of the `d`-dimensional entity `entity`: node `i` has tag `tag(i)` and
    /// position `coords[i]`.
    pub(crate) fn node_block(
        &self,
        w: &mut impl Write,
        entity: i32,
        tag: impl Fn(usize) -> u64 + Sync,
        coords: &[[f64; 3]],
    ) -> io::Result<()> {
        let n = coords.len();
        self.block_header(w, self.d, entity, 0, n as u64)?;
        if self.binary {
            for i in 0..n {
                w.u64(tag(i))?;
            }
            for x in coords {
                for &c in x {
                    w.f64(c)?;
                }
            }
            return Ok(());
        }
        write_lines(w, n, |i, out| {
            out.extend_from_slice(itoa::Buffer::new().format(tag(i)).as_bytes());
        })?;
        write_lines(w, n, |i, out| {
            for (k, &c) in coords[i].iter().enumerate() {
                if k > 0 {
                    out.push(b' ');
                }
                out.extend_from_slice(zmij::Buffer::new().format(c).as_bytes());
            }
        })
    }

    /// The records of `n` elements of dimension `dim` (the elements or the boundary facets),
    /// tagged `first_tag`, `first_tag + 1`, …: record `k` holds the nodes `nodes(k)` (lattice
    /// order, tags less `base`) in Gmsh's order. ASCII lines are formatted in parallel.
    pub(crate) fn records<'a, T: Copy + Into<u64> + Sync + 'a>(
        &self,
        w: &mut impl Write,
        dim: usize,
        first_tag: u64,
        n: usize,
        base: u64,
        nodes: impl Fn(usize) -> &'a [T] + Sync,
    ) -> io::Result<()> {
        if self.binary {
            return (0..n)
                .try_for_each(|k| self.record(w, dim, first_tag + k as u64, nodes(k), base));
        }
        let order = self.order(dim);
        write_lines(w, n, |k, out| {
            ascii_record(out, first_tag + k as u64, order, nodes(k), base);
        })
    }

    /// One record of [`Blocks::records`]; with no nodes, its tag alone (the share of a
    /// record's size its tag takes).
    pub(crate) fn record<T: Copy + Into<u64>>(
        &self,
        w: &mut impl Write,
        dim: usize,
        tag: u64,
        nodes: &[T],
        base: u64,
    ) -> io::Result<()> {
        let order = if nodes.is_empty() {
            &[]
        } else {
            self.order(dim)
        };
        if self.binary {
            w.u64(tag)?;
            return order
                .iter()
                .try_for_each(|&k| w.u64(nodes[k].into() + base));
        }
        let mut line = Vec::with_capacity(16 * (order.len() + 1));
        ascii_record(&mut line, tag, order, nodes, base);
        line.push(b'\n');
        w.write_all(&line)
    }
}

/// An ASCII record without its newline: the tag, then the nodes in `order`, plus `base`.
fn ascii_record<T: Copy + Into<u64>>(
    out: &mut Vec<u8>,
    tag: u64,
    order: &[usize],
    nodes: &[T],
    base: u64,
) {
    let mut b = itoa::Buffer::new();
    out.extend_from_slice(b.format(tag).as_bytes());
    for &k in order {
        out.push(b' ');
        out.extend_from_slice(b.format(nodes[k].into() + base).as_bytes());
    }
}

/// What every section of one output file needs: the mesh, its physical groups, and the
/// encoding of its blocks.
struct Msh<'m> {
    mesh: &'m HighOrderMesh,
    binary: bool,
    groups: Vec<Group>,
    /// Dimension of the elements (facets have `d - 1`).
    d: usize,
    blocks: Blocks,
}

impl<'m> Msh<'m> {
    fn new(mesh: &'m HighOrderMesh, binary: bool, volume_name: &str) -> io::Result<Self> {
        Ok(Msh {
            mesh,
            binary,
            groups: groups(mesh, volume_name),
            d: mesh.dim,
            blocks: Blocks::new(mesh.dim, mesh.order, binary)?,
        })
    }

    /// Node indices (0-based) of member `i` of group `g`, in lattice order.
    fn lattice_nodes(&self, g: &Group, i: usize) -> &'m [u32] {
        let mesh = self.mesh;
        if g.dim == self.d {
            mesh.element(i)
        } else {
            let n = mesh.nodes_per_facet();
            &mesh.boundary[i * n..(i + 1) * n]
        }
    }

    /// Node indices (0-based) of member `i` of group `g`, in Gmsh's order.
    fn nodes_of(&self, g: &Group, i: usize) -> Vec<u32> {
        let nodes = self.lattice_nodes(g, i);
        self.blocks.order(g.dim).iter().map(|&k| nodes[k]).collect()
    }

    fn type_of(&self, g: &Group) -> i32 {
        self.blocks.kind(g.dim)
    }

    fn n_elements(&self) -> usize {
        self.mesh.n_elements() + self.mesh.n_boundary()
    }

    /// `$MeshFormat` and `$PhysicalNames`.
    fn header(&self, version: MshVersion, w: &mut impl Write) -> io::Result<()> {
        let vstr = match version {
            MshVersion::V22 => "2.2",
            MshVersion::V41 => "4.1",
        };
        let names = self
            .groups
            .iter()
            .map(|g| (g.dim, g.physical, g.name.as_str()));
        write_format_and_names(w, vstr, self.binary, names)
    }

    /// Bounding box `[min x, y, z, max x, y, z]` of the nodes of group `g`'s members. In
    /// parallel: min and max are exact, so the result does not depend on the split.
    fn bbox(&self, g: &Group) -> [f64; 6] {
        use rayon::prelude::*;
        let mesh = self.mesh;
        let d = self.d;
        let npf = mesh.nodes_per_facet();
        let empty = || ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let (lo, hi) = g
            .members
            .par_iter()
            .fold(empty, |(mut lo, mut hi), &i| {
                let ids = if g.dim == d {
                    mesh.element(i)
                } else {
                    &mesh.boundary[i * npf..(i + 1) * npf]
                };
                for &n in ids {
                    let x = mesh.nodes[n as usize];
                    for k in 0..3 {
                        lo[k] = lo[k].min(x[k]);
                        hi[k] = hi[k].max(x[k]);
                    }
                }
                (lo, hi)
            })
            .reduce(empty, |(a, b), (c, e)| {
                (
                    std::array::from_fn(|k| a[k].min(c[k])),
                    std::array::from_fn(|k| b[k].max(e[k])),
                )
            });
        [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]]
    }

    /// MSH 4.1 `$Entities`: one entity per physical group, with the bounding box of its
    /// elements' nodes.
    fn entities_v41(&self, w: &mut impl Write) -> io::Result<()> {
        let groups: Vec<(usize, i32, i32)> = self
            .groups
            .iter()
            .map(|g| (g.dim, g.entity, g.physical))
            .collect();
        self.blocks
            .entities(w, &groups, |i| self.bbox(&self.groups[i]))
    }

    /// The boundary entity (dimension d−1) of boundary tag `tag`.
    fn boundary_entity(&self, tag: i32) -> io::Result<i32> {
        self.groups
            .iter()
            .find(|g| g.dim + 1 == self.d && g.tag == tag)
            .map(|g| g.entity)
            .ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("periodic boundary tag {tag} has no facets in the mesh"),
                )
            })
    }

    /// `$Periodic` (when the mesh has periodic pairs): [`write_periodic_section`] with the
    /// node pairs' 0-based indices written as 1-based tags.
    fn periodic(&self, version: MshVersion, w: &mut impl Write) -> io::Result<()> {
        let links = &self.mesh.periodic;
        if links.is_empty() {
            return Ok(());
        }
        let pairs: Vec<_> = links
            .iter()
            .map(|l| move |i: usize| l.node_pairs[i].map(|n| n as u64 + 1))
            .collect();
        let mut records = Vec::with_capacity(links.len());
        for (l, pair) in links.iter().zip(&pairs) {
            records.push(PeriodicRecord {
                slave_entity: self.boundary_entity(l.slave_tag)?,
                master_entity: self.boundary_entity(l.master_tag)?,
                affine: l.transform.affine(),
                n: l.node_pairs.len(),
                pair,
            });
        }
        write_periodic_section(w, version, self.binary, self.d as i32 - 1, &records)
    }

    /// MSH 4.1 `$Nodes`: all nodes in one block on the first volume entity.
    fn nodes_v41(&self, w: &mut impl Write) -> io::Result<()> {
        let nodes = &self.mesh.nodes;
        let nn = nodes.len() as u64;
        let vol_entity = self
            .groups
            .iter()
            .find(|g| g.dim == self.d)
            .map_or(1, |g| g.entity);
        writeln!(w, "$Nodes")?;
        self.blocks.four(w, [1, nn, 1.min(nn), nn])?;
        self.blocks
            .node_block(w, vol_entity, |i| i as u64 + 1, nodes)?;
        self.blocks.end(w, "Nodes")
    }

    /// MSH 4.1 `$Elements`: one block per physical group, element tags 1, 2, ... in group
    /// order.
    fn elements_v41(&self, w: &mut impl Write) -> io::Result<()> {
        let blocks = &self.blocks;
        writeln!(w, "$Elements")?;
        let ne = self.n_elements() as u64;
        blocks.four(w, [self.groups.len() as u64, ne, 1.min(ne), ne])?;
        let mut tag = 1u64;
        for g in &self.groups {
            let n = g.members.len();
            blocks.block_header(w, g.dim, g.entity, self.type_of(g), n as u64)?;
            blocks.records(w, g.dim, tag, n, 1, |k| self.lattice_nodes(g, g.members[k]))?;
            tag += n as u64;
        }
        blocks.end(w, "Elements")
    }

    /// MSH 2.2 `$Nodes`.
    fn nodes_v22(&self, w: &mut impl Write) -> io::Result<()> {
        let binary = self.binary;
        writeln!(w, "$Nodes\n{}", self.mesh.nodes.len())?;
        for (i, x) in self.mesh.nodes.iter().enumerate() {
            if binary {
                w.i32(i as i32 + 1)?;
                for &c in x {
                    w.f64(c)?;
                }
            } else {
                writeln!(w, "{} {} {} {}", i + 1, x[0], x[1], x[2])?;
            }
        }
        if binary {
            writeln!(w)?;
        }
        writeln!(w, "$EndNodes")
    }

    /// MSH 2.2 `$Elements`: tags (physical, entity) on every element; in binary one block
    /// header per group.
    fn elements_v22(&self, w: &mut impl Write) -> io::Result<()> {
        let binary = self.binary;
        writeln!(w, "$Elements\n{}", self.n_elements())?;
        let mut tag = 1i32;
        for g in &self.groups {
            if binary && !g.members.is_empty() {
                w.i32(self.type_of(g))?;
                w.i32(g.members.len() as i32)?;
                w.i32(2)?;
            }
            for &i in &g.members {
                let nodes = self.nodes_of(g, i);
                if binary {
                    w.i32(tag)?;
                    w.i32(g.physical)?;
                    w.i32(g.entity)?;
                    for n in nodes {
                        w.i32(n as i32 + 1)?;
                    }
                } else {
                    write!(w, "{tag} {} 2 {} {}", self.type_of(g), g.physical, g.entity)?;
                    for n in nodes {
                        write!(w, " {}", n + 1)?;
                    }
                    writeln!(w)?;
                }
                tag += 1;
            }
        }
        if binary {
            writeln!(w)?;
        }
        writeln!(w, "$EndElements")
    }
}

/// One pair of a `$Periodic` section: the image and master entities, the affine map master →
/// image (4×4 by rows) and `n` node pairs, `pair(i)` = (image node tag, master node tag).
pub(crate) struct PeriodicRecord<'a> {
    pub slave_entity: i32,
    pub master_entity: i32,
    pub affine: [f64; 16],
    pub n: usize,
    pub pair: &'a (dyn Fn(usize) -> [u64; 2] + Sync),
}

/// `$Periodic` of the serial and the collective (`distributed::write`) MSH writers: per pair
/// the image entity, its master entity, the affine map and the node pairs (entities of
/// dimension `dim`). MSH 4.1 writes it binary in a binary file; MSH 2.2 always in ASCII
/// (Gmsh reads the 2.2 section as text in binary files too, and only with
/// `Mesh.IgnorePeriodicity=0`, its default being to skip it).
pub(crate) fn write_periodic_section(
    w: &mut impl Write,
    version: MshVersion,
    binary: bool,
    dim: i32,
    links: &[PeriodicRecord],
) -> io::Result<()> {
    let binary = version == MshVersion::V41 && binary;
    writeln!(w, "$Periodic")?;
    if binary {
        w.u64(links.len() as u64)?;
    } else {
        writeln!(w, "{}", links.len())?;
    }
    for l in links {
        if binary {
            w.i32(dim)?;
            w.i32(l.slave_entity)?;
            w.i32(l.master_entity)?;
            w.u64(16)?;
            for a in l.affine {
                w.f64(a)?;
            }
            w.u64(l.n as u64)?;
            for i in 0..l.n {
                let [s, m] = (l.pair)(i);
                w.u64(s)?;
                w.u64(m)?;
            }
            continue;
        }
        let values: Vec<String> = l
            .affine
            .iter()
            .map(|&a| zmij::Buffer::new().format(a).to_string())
            .collect();
        writeln!(w, "{dim} {} {}", l.slave_entity, l.master_entity)?;
        match version {
            MshVersion::V41 => writeln!(w, "16 {}", values.join(" "))?,
            MshVersion::V22 => writeln!(w, "Affine {}", values.join(" "))?,
        }
        writeln!(w, "{}", l.n)?;
        write_lines(w, l.n, |i, out| {
            let [s, m] = (l.pair)(i);
            out.extend_from_slice(itoa::Buffer::new().format(s).as_bytes());
            out.push(b' ');
            out.extend_from_slice(itoa::Buffer::new().format(m).as_bytes());
        })?;
    }
    if binary {
        writeln!(w)?;
    }
    writeln!(w, "$EndPeriodic")
}

/// Write `n` lines, line `i` made by `line(i, buffer)` (without its newline): formatted in
/// parallel in chunks, written in order, so the bytes are those of a serial loop. At most
/// 64 chunks are held at once.
pub(crate) fn write_lines(
    w: &mut impl Write,
    n: usize,
    line: impl Fn(usize, &mut Vec<u8>) + Sync,
) -> io::Result<()> {
    use rayon::prelude::*;
    const CHUNK: usize = 8192;
    let starts: Vec<usize> = (0..n).step_by(CHUNK).collect();
    for batch in starts.chunks(64) {
        let buffers: Vec<Vec<u8>> = batch
            .par_iter()
            .map(|&s| {
                let mut out = Vec::with_capacity(64 * CHUNK);
                for i in s..(s + CHUNK).min(n) {
                    line(i, &mut out);
                    out.push(b'\n');
                }
                out
            })
            .collect();
        for b in buffers {
            w.write_all(&b)?;
        }
    }
    Ok(())
}

fn unsupported(dim: usize, p: usize) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("Gmsh has no Lagrange element of dimension {dim} and order {p}"),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2D order-1 mesh of `ne` quads (no real nodes needed for the groups) with the given tags.
    fn mesh(
        element_tags: Vec<i32>,
        boundary_tags: Vec<i32>,
        names: &[(i32, &str)],
    ) -> HighOrderMesh {
        HighOrderMesh {
            dim: 2,
            order: 1,
            nodes: vec![[0.0; 3]; 4],
            elements: vec![0; 4 * element_tags.len().max(1)],
            element_tags,
            boundary: vec![0; 2 * boundary_tags.len()],
            boundary_tags,
            tag_names: names.iter().map(|(t, n)| (*t, n.to_string())).collect(),
            periodic: Vec::new(),
        }
    }

    fn summary(m: &HighOrderMesh) -> Vec<(usize, i32, String)> {
        groups(m, DEFAULT_VOLUME_NAME)
            .into_iter()
            .map(|g| (g.dim, g.physical, g.name))
            .collect()
    }

    #[test]
    fn untagged_mesh_gets_boundary_and_fluid_with_distinct_ids() {
        let m = mesh(vec![], vec![0, 0, 0], &[]);
        assert_eq!(
            summary(&m),
            vec![(1, 1, "boundary".into()), (2, 2, "fluid".into())]
        );
    }

    #[test]
    fn region_tag_clashing_with_a_boundary_id_is_shifted() {
        // Region 1 and boundary tags 1, 2 (named), plus untagged facets.
        let m = mesh(vec![1, 1], vec![1, 2, 0], &[(1, "wall"), (2, "inlet")]);
        let s = summary(&m);
        assert_eq!(
            s,
            vec![
                (1, 3, "untagged".into()),
                (1, 1, "wall".into()),
                (1, 2, "inlet".into()),
                (2, 4, "fluid".into()),
            ]
        );
        let ids: std::collections::BTreeSet<i32> = s.iter().map(|g| g.1).collect();
        assert_eq!(ids.len(), s.len());
    }

    /// Several unnamed regions are one volume group of the volume name, as PyFR needs.
    #[test]
    fn unnamed_regions_merge_into_the_volume_group() {
        let m = mesh(vec![3, 4, 3], vec![1], &[]);
        let g = groups(&m, "air");
        let vol: Vec<_> = g.iter().filter(|g| g.dim == 2).collect();
        assert_eq!(vol.len(), 1);
        assert_eq!(vol[0].name, "air");
        assert_eq!(vol[0].members, vec![0, 1, 2]);
        let mut out = Vec::new();
        write_msh_named(&m, MshVersion::V41, false, "air", &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(text.matches("\"air\"").count(), 1, "{text}");
    }

    #[test]
    fn named_and_several_regions_keep_their_names() {
        let m = mesh(vec![5, 6], vec![1], &[(5, "solid")]);
        assert_eq!(
            summary(&m),
            vec![
                (1, 1, "boundary_1".into()),
                (2, 5, "solid".into()),
                (2, 6, "fluid".into()),
            ]
        );
        let one = mesh(vec![7, 7], vec![1], &[]);
        assert_eq!(
            groups(&one, "air")
                .into_iter()
                .map(|g| g.name)
                .collect::<Vec<_>>(),
            vec!["boundary_1", "air"]
        );
    }
}
