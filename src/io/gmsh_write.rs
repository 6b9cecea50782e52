//! Gmsh MSH 4.1 and 2.2 output (ASCII or binary) of a [`HighOrderMesh`].
//!
//! Elements are Lagrange quads/hexes of the mesh's order (types 3/10/36/… and 5/12/92/…), the
//! boundary facets Lagrange lines/quads of the same order, nodes in Gmsh's order
//! ([`crate::sample::ordering`]). Boundary tags become physical groups of dimension d−1 (named
//! from the input, or `boundary_<tag>`); untagged boundary facets form a group named
//! `boundary` (when nothing is tagged) or `untagged`; elements form one physical group per
//! region tag (or one named `domain`). MSH 4.1 writes one geometric entity per physical group
//! in `$Entities`, as HOPR and other solvers' readers require.

use super::output::WriteBin;
use crate::sample::HighOrderMesh;
use crate::sample::ordering::{gmsh_hex, gmsh_line, gmsh_quad, gmsh_type, to_indices};
use std::collections::BTreeMap;
use std::io::{self, Write};

/// MSH format version to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MshVersion {
    V22,
    V41,
}

/// One physical group with its geometric entity.
struct Group {
    dim: usize,
    /// Entity tag (1-based per dimension).
    entity: i32,
    physical: i32,
    name: String,
    /// Element indices (into elements or boundary facets) in this group.
    members: Vec<usize>,
}

fn groups(mesh: &HighOrderMesh) -> Vec<Group> {
    let d = mesh.dim;
    let mut out = Vec::new();
    let mut make = |dim: usize, tags: &[i32], n: usize, untagged_name: &str| {
        let mut by_tag: BTreeMap<i32, Vec<usize>> = BTreeMap::new();
        for i in 0..n {
            by_tag
                .entry(tags.get(i).copied().unwrap_or(0))
                .or_default()
                .push(i);
        }
        let fresh = by_tag.keys().copied().max().unwrap_or(0).max(0) + 1;
        let only_untagged = by_tag.len() == 1 && by_tag.contains_key(&0);
        for (k, (tag, members)) in by_tag.into_iter().enumerate() {
            let (physical, name) = if tag == 0 {
                let name = if only_untagged {
                    untagged_name
                } else {
                    "untagged"
                };
                (fresh, name.to_string())
            } else {
                let name = mesh.tag_names.get(&tag).cloned().unwrap_or_else(|| {
                    format!("{}_{tag}", if dim == d { "region" } else { "boundary" })
                });
                (tag, name)
            };
            out.push(Group {
                dim,
                entity: k as i32 + 1,
                physical,
                name,
                members,
            });
        }
    };
    make(d - 1, &mesh.boundary_tags, mesh.n_boundary(), "boundary");
    make(d, &mesh.element_tags, mesh.n_elements(), "domain");
    out
}

/// Write `mesh` as MSH `version`, ASCII or binary.
pub fn write_msh(
    mesh: &HighOrderMesh,
    version: MshVersion,
    binary: bool,
    w: &mut impl Write,
) -> io::Result<()> {
    let d = mesh.dim;
    let p = mesh.order;
    let groups = groups(mesh);
    let vol_order = to_indices(p, &if d == 2 { gmsh_quad(p) } else { gmsh_hex(p) });
    let bnd_order = to_indices(p, &if d == 2 { gmsh_line(p) } else { gmsh_quad(p) });
    let vol_type = gmsh_type(d, p).ok_or_else(|| unsupported(d, p))? as i32;
    let bnd_type = gmsh_type(d - 1, p).ok_or_else(|| unsupported(d - 1, p))? as i32;
    let nodes_of = |g: &Group, i: usize| -> Vec<u32> {
        if g.dim == d {
            let e = mesh.element(i);
            vol_order.iter().map(|&k| e[k]).collect()
        } else {
            let n = mesh.nodes_per_facet();
            let f = &mesh.boundary[i * n..(i + 1) * n];
            bnd_order.iter().map(|&k| f[k]).collect()
        }
    };
    let type_of = |g: &Group| if g.dim == d { vol_type } else { bnd_type };
    let n_elements = mesh.n_elements() + mesh.n_boundary();

    let (vstr, ftype) = match version {
        MshVersion::V22 => ("2.2", binary as i32),
        MshVersion::V41 => ("4.1", binary as i32),
    };
    writeln!(w, "$MeshFormat\n{vstr} {ftype} 8")?;
    if binary {
        w.i32(1)?;
        writeln!(w)?;
    }
    writeln!(w, "$EndMeshFormat")?;
    writeln!(w, "$PhysicalNames\n{}", groups.len())?;
    for g in &groups {
        writeln!(
            w,
            "{} {} \"{}\"",
            g.dim,
            g.physical,
            g.name.replace('"', "'")
        )?;
    }
    writeln!(w, "$EndPhysicalNames")?;

    match version {
        MshVersion::V41 => {
            // Entities with bounding boxes of their elements' nodes.
            // In parallel: min and max are exact, so the result does not depend on the split.
            let bbox = |g: &Group| {
                use rayon::prelude::*;
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
            };
            let mut count = [0u64; 4];
            for g in &groups {
                count[g.dim] += 1;
            }
            writeln!(w, "$Entities")?;
            if binary {
                for c in count {
                    w.u64(c)?;
                }
                for dim in 1..=3 {
                    for g in groups.iter().filter(|g| g.dim == dim) {
                        w.i32(g.entity)?;
                        for v in bbox(g) {
                            w.f64(v)?;
                        }
                        w.u64(1)?;
                        w.i32(g.physical)?;
                        w.u64(0)?;
                    }
                }
                writeln!(w)?;
            } else {
                writeln!(w, "{} {} {} {}", count[0], count[1], count[2], count[3])?;
                for dim in 1..=3 {
                    for g in groups.iter().filter(|g| g.dim == dim) {
                        let b = bbox(g);
                        writeln!(
                            w,
                            "{} {} {} {} {} {} {} 1 {} 0",
                            g.entity, b[0], b[1], b[2], b[3], b[4], b[5], g.physical
                        )?;
                    }
                }
            }
            writeln!(w, "$EndEntities")?;

            // All nodes in one block on the first volume entity.
            let nn = mesh.nodes.len() as u64;
            let vol_entity = groups.iter().find(|g| g.dim == d).map_or(1, |g| g.entity);
            writeln!(w, "$Nodes")?;
            if binary {
                for v in [1, nn, 1.min(nn), nn] {
                    w.u64(v)?;
                }
                w.i32(d as i32)?;
                w.i32(vol_entity)?;
                w.i32(0)?;
                w.u64(nn)?;
                for i in 1..=nn {
                    w.u64(i)?;
                }
                for x in &mesh.nodes {
                    for &c in x {
                        w.f64(c)?;
                    }
                }
                writeln!(w)?;
            } else {
                writeln!(w, "1 {nn} {} {nn}", 1.min(nn))?;
                writeln!(w, "{d} {vol_entity} 0 {nn}")?;
                write_lines(w, mesh.nodes.len(), |i, out| {
                    out.extend_from_slice(itoa::Buffer::new().format(i + 1).as_bytes());
                })?;
                write_lines(w, mesh.nodes.len(), |i, out| {
                    for (k, &c) in mesh.nodes[i].iter().enumerate() {
                        if k > 0 {
                            out.push(b' ');
                        }
                        out.extend_from_slice(zmij::Buffer::new().format(c).as_bytes());
                    }
                })?;
            }
            writeln!(w, "$EndNodes")?;

            writeln!(w, "$Elements")?;
            let ne = n_elements as u64;
            if binary {
                for v in [groups.len() as u64, ne, 1.min(ne), ne] {
                    w.u64(v)?;
                }
            } else {
                writeln!(w, "{} {ne} {} {ne}", groups.len(), 1.min(ne))?;
            }
            let mut tag = 1u64;
            for g in &groups {
                if binary {
                    w.i32(g.dim as i32)?;
                    w.i32(g.entity)?;
                    w.i32(type_of(g))?;
                    w.u64(g.members.len() as u64)?;
                } else {
                    writeln!(
                        w,
                        "{} {} {} {}",
                        g.dim,
                        g.entity,
                        type_of(g),
                        g.members.len()
                    )?;
                }
                if binary {
                    for &i in &g.members {
                        w.u64(tag)?;
                        for n in nodes_of(g, i) {
                            w.u64(n as u64 + 1)?;
                        }
                        tag += 1;
                    }
                } else {
                    write_lines(w, g.members.len(), |k, out| {
                        let mut b = itoa::Buffer::new();
                        out.extend_from_slice(b.format(tag + k as u64).as_bytes());
                        for n in nodes_of(g, g.members[k]) {
                            out.push(b' ');
                            out.extend_from_slice(b.format(n as u64 + 1).as_bytes());
                        }
                    })?;
                    tag += g.members.len() as u64;
                }
            }
            if binary {
                writeln!(w)?;
            }
            writeln!(w, "$EndElements")?;
        }
        MshVersion::V22 => {
            writeln!(w, "$Nodes\n{}", mesh.nodes.len())?;
            for (i, x) in mesh.nodes.iter().enumerate() {
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
            writeln!(w, "$EndNodes\n$Elements\n{n_elements}")?;
            let mut tag = 1i32;
            for g in &groups {
                if binary && !g.members.is_empty() {
                    w.i32(type_of(g))?;
                    w.i32(g.members.len() as i32)?;
                    w.i32(2)?;
                }
                for &i in &g.members {
                    let nodes = nodes_of(g, i);
                    if binary {
                        w.i32(tag)?;
                        w.i32(g.physical)?;
                        w.i32(g.entity)?;
                        for n in nodes {
                            w.i32(n as i32 + 1)?;
                        }
                    } else {
                        write!(w, "{tag} {} 2 {} {}", type_of(g), g.physical, g.entity)?;
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
            writeln!(w, "$EndElements")?;
        }
    }
    Ok(())
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
