//! A rank's share of a binary MSH 4.1 file: runs of elements, ghost rings, and its ghosted
//! sub-mesh.
//!
//! Input: the path of a binary MSH 4.1 file of linear hexes (3D) or quads (2D)
//! ([`MshFile::open`]). Outputs: a contiguous run of the file's elements ([`MshFile::run`]);
//! the elements within g vertex rings of a set of elements ([`MshFile::ghosts`]); the
//! coordinates of a set of nodes; and a [`LocalMesh`]: given own elements, ghosts and the
//! ghosts' owners, the tagged boundary facets whose vertices are all present and only the
//! nodes these use, with the global id of every element (its index among the file's elements)
//! and vertex (its node tag), and the file's `$Periodic` links (every rank reads the section
//! at its offset with the serial parser, `Indexed::declared_periodic`). [`super::share`]
//! decides which elements a rank owns.
//!
//! How it reads: the file is parsed by the MSH parser family's offset-indexed reader
//! (`io::gmsh::stream`: one pass over the section headers, then runs read at their
//! offsets and streamed passes in chunks); this module adds what is distributed: each ghost
//! ring is one streamed pass keeping the elements that touch a node of the previous rings; the
//! tagged facets one streamed pass; the coordinates one pass keeping the needed tags. No rank
//! ever holds more than its elements, ghosts and their nodes, plus one chunk.
//!
//! Invariant: the local mesh is what the serial reader ([`crate::io::read_mesh`]) makes of
//! the file restricted to these elements: the same element tags (the entity's first physical
//! tag), the same facet tags and group names, the same orientation fix per element.

use crate::io::gmsh::stream::{Head, Indexed};
use crate::mesh::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};
use crate::mesh::{LinearMesh, MeshOptions};
use std::collections::{HashMap, HashSet};
use std::path::Path;

/// A rank's elements and ghosts (see the module docs).
pub struct LocalMesh {
    /// Own elements first (`0..n_owned`), then the ghosts; nodes in file order.
    pub mesh: LinearMesh,
    pub n_owned: usize,
    /// Global element id (index among the file's elements) of each local element.
    pub global_element: Vec<u64>,
    /// Rank owning each local element (this rank for the own ones).
    pub owner: Vec<u32>,
    /// Global vertex id (node tag) of each local vertex.
    pub global_vertex: Vec<u64>,
    /// Elements in the whole file.
    pub n_global: u64,
    /// The share glued along its translation seams, when the job glues them
    /// (`super::periodic::glue_share`): the graded knots are surveyed on it
    /// ([`super::knots`]), their surfaces running on across the seams.
    pub glued: Option<std::sync::Arc<crate::spline::seam::Glued>>,
}

impl LocalMesh {
    /// First global element of each rank, and N at the end (`size + 1` entries).
    pub fn starts(n_global: u64, size: usize) -> Vec<u64> {
        (0..=size as u64)
            .map(|r| (r as u128 * n_global as u128 / size as u128) as u64)
            .collect()
    }

    /// The rank whose run under [`LocalMesh::starts`] holds global element `g`.
    pub fn run_of(starts: &[u64], g: u64) -> usize {
        starts.partition_point(|&s| s <= g) - 1
    }
}

fn err(what: impl Into<String>) -> ParseError {
    ParseError::new(Location::File, what)
}

/// Elements read from the file: global index, physical tag and node tags of each.
#[derive(Debug, Default)]
pub struct Elements {
    pub global: Vec<u64>,
    pub tags: Vec<i32>,
    /// `npe` node tags per element.
    pub nodes: Vec<u64>,
}

impl Elements {
    fn push(&mut self, g: u64, p: i32, v: &[u64]) {
        self.global.push(g);
        self.tags.push(p);
        self.nodes.extend_from_slice(v);
    }
}

/// An indexed binary MSH 4.1 file of hexes (3D) or quads (2D), read by offsets.
pub struct MshFile {
    ix: Indexed,
    /// Gmsh types of the cells and of their facets.
    kind: i32,
    facet_kind: i32,
    /// Nodes per cell.
    pub npe: usize,
    dim: usize,
    /// Cells in the whole file.
    pub n_global: u64,
}

impl MshFile {
    /// Index the file (binary MSH 4.1, not one of Gmsh's partitions) and check it holds only
    /// quads or only hexes among its cells.
    pub fn open(path: &Path) -> Result<MshFile, ParseError> {
        let head = Head::open(path)?;
        if !head.header.is_binary_41() {
            return Err(err(format!(
                "the rank-local reader reads binary MSH 4.1; this file is {} (convert it with gmsh -format msh41 -bin, or run on one process)",
                head.header.describe_format()
            )));
        }
        if head.header.entities.partitions().is_some() {
            return Err(err(
                "a partitioned MSH file: give the partition files IN_1.msh … IN_N.msh as IN.msh (one per rank)",
            ));
        }
        let ix = head.index()?;
        let count = |k: i32| -> u64 {
            ix.elements
                .iter()
                .filter(|b| b.gmsh_type == k)
                .map(|b| b.n)
                .sum()
        };
        let (kind, facet_kind, npe, dim) = if count(5) > 0 {
            (5, 3, 8, 3)
        } else if count(3) > 0 {
            (3, 1, 4, 2)
        } else {
            return Err(err("no hexahedra or quadrilaterals in the file"));
        };
        // Cells of the mesh's dimension of another type (tets, prisms, high-order hexes...).
        for b in &ix.elements {
            if b.dim == dim as i32 && b.gmsh_type != kind && b.n > 0 {
                return Err(err(format!(
                    "element type {} next to the {}: polyspline curves linear quad (2D) and hex (3D) meshes",
                    b.gmsh_type,
                    if dim == 3 {
                        "hexahedra"
                    } else {
                        "quadrilaterals"
                    }
                )));
            }
        }
        let n_global = count(kind);
        Ok(MshFile {
            ix,
            kind,
            facet_kind,
            npe,
            dim,
            n_global,
        })
    }

    /// Cells `lo..hi` (file order), read at their offsets.
    pub fn run(&mut self, lo: u64, hi: u64) -> Result<Elements, ParseError> {
        let mut out = Elements::default();
        self.ix
            .range(self.kind, lo, hi, |g, p, v| out.push(g, p, v))?;
        Ok(out)
    }

    /// The cells within `depth` vertex rings of `own` and not in it: one streamed pass over
    /// the cell blocks per ring, keeping the cells that touch a node of the previous rings.
    /// With `seams` (node tag → its representative, for the image nodes of glued periodic
    /// seams) the rings are those of the glued mesh: they run on across the seams.
    pub fn ghosts(
        &mut self,
        own: &Elements,
        depth: usize,
        seams: Option<&HashMap<u64, u64>>,
    ) -> Result<Elements, ParseError> {
        let glued = |t: &u64| seams.and_then(|m| m.get(t)).copied().unwrap_or(*t);
        let mut have: HashSet<u64> = own.nodes.iter().map(glued).collect();
        let mut seen: HashSet<u64> = own.global.iter().copied().collect();
        let mut out = Elements::default();
        for _ in 0..depth {
            let before = out.global.len();
            self.ix.for_each(self.kind, |g, p, v| {
                if !seen.contains(&g) && v.iter().any(|t| have.contains(&glued(t))) {
                    seen.insert(g);
                    out.push(g, p, v);
                }
            })?;
            if out.global.len() == before {
                break;
            }
            have.extend(out.nodes[self.npe * before..].iter().map(glued));
        }
        Ok(out)
    }

    /// The coordinates of the nodes in `have`, in file order; fails when a needed node is not
    /// defined.
    pub fn coordinates(
        &mut self,
        have: &HashSet<u64>,
    ) -> Result<(Vec<u64>, Vec<[f64; 3]>), ParseError> {
        self.ix.coordinates(have)
    }

    /// The [`LocalMesh`] of `own` then `ghosts` (`owner`: the rank of each ghost), with the
    /// tagged facets whose nodes are all present and the coordinates of the nodes used.
    pub fn local_mesh(
        &mut self,
        own: Elements,
        ghosts: Elements,
        owner: Vec<u32>,
        rank: usize,
        options: &MeshOptions,
    ) -> Result<LocalMesh, ParseError> {
        let n_owned = own.global.len();
        let (mut global_element, mut tags, mut nodes) = (own.global, own.tags, own.nodes);
        global_element.extend_from_slice(&ghosts.global);
        tags.extend_from_slice(&ghosts.tags);
        nodes.extend_from_slice(&ghosts.nodes);
        drop(ghosts);
        let mut owners = vec![rank as u32; n_owned];
        owners.extend_from_slice(&owner);
        let have: HashSet<u64> = nodes.iter().copied().collect();

        // Tagged facets among the present nodes.
        let mut facets: Vec<u64> = Vec::new();
        let mut facet_tags: Vec<i32> = Vec::new();
        self.ix.for_each(self.facet_kind, |_, p, v| {
            if p != 0 && v.iter().all(|t| have.contains(t)) {
                facets.extend_from_slice(v);
                facet_tags.push(p);
            }
        })?;

        let (global_vertex, points) = self.ix.coordinates(&have)?;
        drop(have);
        // Named by the file's node tag (the mesh check below knows only local indices).
        for (p, &t) in points.iter().zip(&global_vertex) {
            if let Some(k) = p.iter().position(|c| !c.is_finite()) {
                return Err(err(format!(
                    "node {t} has a non-finite {} coordinate ({})",
                    ["x", "y", "z"][k],
                    p[k]
                )));
            }
        }
        let local: HashMap<u64, i64> = global_vertex
            .iter()
            .enumerate()
            .map(|(i, &t)| (t, i as i64))
            .collect();
        let (cell, facet) = if self.dim == 3 {
            (CellKind::Hexahedron, CellKind::Quad)
        } else {
            (CellKind::Quad, CellKind::Line)
        };
        let mut block = RawBlock::new(cell, self.npe);
        block.nodes = nodes.iter().map(|t| local[t]).collect();
        block.tags = tags;
        drop(nodes);
        let mut fblock = RawBlock::new(facet, self.npe / 2);
        fblock.nodes = facets.iter().map(|t| local[t]).collect();
        fblock.tags = facet_tags;
        let raw = RawMesh {
            points,
            point_locations: Vec::new(),
            declared_dim: Some(3),
            blocks: vec![block, fblock],
            // Every rank reads the whole section (its links; the node pairs are checked, not
            // kept: the pairing is found again from the positions, as serially).
            periodic: self.ix.declared_periodic()?,
            tag_names: self.ix.header.tag_names.clone(),
        };
        let mesh = LinearMesh::from_raw(raw, options)?;
        debug_assert_eq!(mesh.unused_vertices, 0);
        Ok(LocalMesh {
            mesh,
            n_owned,
            global_element,
            owner: owners,
            global_vertex,
            n_global: self.n_global,
            glued: None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::gmsh_write::{MshVersion, write_msh};
    use crate::mesh::Topology;
    use crate::mesh::generate::{Kind, generate};
    use std::fs::File;

    /// A generated cylinder written as binary MSH 4.1, and the serial reader's mesh of it.
    fn cylinder(name: &str) -> (std::path::PathBuf, LinearMesh) {
        let mesh = generate(Kind::Cylinder, 6000);
        let topo = Topology::build(&mesh);
        let linear = crate::sample::sample(&mesh, &mesh, &topo, 1);
        let dir = std::env::temp_dir().join(format!("polyspline-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(name);
        let mut f = std::io::BufWriter::new(File::create(&path).unwrap());
        write_msh(&linear, MshVersion::V41, true, &mut f).unwrap();
        drop(f);
        let serial = crate::io::read_mesh(&path, &MeshOptions::default()).unwrap();
        (path, serial)
    }

    /// Rank `rank`'s run of `size` with `depth` rings of ghosts, the ghosts' owners by runs.
    fn read_run(path: &Path, rank: usize, size: usize, depth: usize) -> LocalMesh {
        let mut f = MshFile::open(path).unwrap();
        let starts = LocalMesh::starts(f.n_global, size);
        let own = f.run(starts[rank], starts[rank + 1]).unwrap();
        let ghosts = f.ghosts(&own, depth, None).unwrap();
        let owner = ghosts
            .global
            .iter()
            .map(|&g| LocalMesh::run_of(&starts, g) as u32)
            .collect();
        f.local_mesh(own, ghosts, owner, rank, &MeshOptions::default())
            .unwrap()
    }

    #[test]
    fn shares_partition_the_elements_with_the_serial_coordinates_and_exact_ghost_rings() {
        let (path, serial) = cylinder("share.msh");
        let topo = Topology::build(&serial);
        let n = serial.n_elements();
        let size = 4;
        let mut seen = vec![0u8; n];
        for rank in 0..size {
            let depth = 2;
            let l = read_run(&path, rank, size, depth);
            assert_eq!(l.n_global as usize, n);
            // Own elements: a contiguous run, the serial element's vertices (by coordinates)
            // and tag, the serial orientation.
            for (i, &g) in l.global_element.iter().enumerate() {
                let g = g as usize;
                if i < l.n_owned {
                    seen[g] += 1;
                }
                assert_eq!(l.mesh.element_coords(i), serial.element_coords(g));
                assert_eq!(l.mesh.element_tags.get(i), serial.element_tags.get(g));
            }
            // Ghosts: exactly the elements within `depth` vertex rings of the own ones.
            let mut ring: std::collections::BTreeSet<usize> = l.global_element[..l.n_owned]
                .iter()
                .map(|&g| g as usize)
                .collect();
            for _ in 0..depth {
                let verts: Vec<u32> = ring
                    .iter()
                    .flat_map(|&e| serial.element(e).to_vec())
                    .collect();
                for v in verts {
                    let v = v as usize;
                    for k in topo.vertex_offsets[v]..topo.vertex_offsets[v + 1] {
                        ring.insert(topo.vertex_elements[k as usize] as usize);
                    }
                }
            }
            let mut have: Vec<usize> = l.global_element.iter().map(|&g| g as usize).collect();
            have.sort_unstable();
            assert_eq!(have, ring.into_iter().collect::<Vec<_>>());
            // Only the nodes of these elements: fewer than the whole mesh's.
            assert!(l.mesh.n_vertices() < serial.n_vertices());
            assert_eq!(l.global_vertex.len(), l.mesh.n_vertices());
            assert_eq!(l.mesh.tag_names, serial.tag_names);
            // Tagged facets: those of the serial mesh whose vertices are all here.
            assert!(l.mesh.facet_tags.len() <= serial.facet_tags.len());
            assert!(!l.mesh.facet_tags.is_empty());
        }
        assert!(seen.iter().all(|&s| s == 1), "every element owned once");
    }

    #[test]
    fn an_ascii_file_is_one_error_line() {
        let mesh = generate(Kind::Cylinder, 100);
        let topo = Topology::build(&mesh);
        let linear = crate::sample::sample(&mesh, &mesh, &topo, 1);
        let path =
            std::env::temp_dir().join(format!("polyspline-ascii-{}.msh", std::process::id()));
        let mut f = std::io::BufWriter::new(File::create(&path).unwrap());
        write_msh(&linear, MshVersion::V41, false, &mut f).unwrap();
        drop(f);
        let e = MshFile::open(&path)
            .err()
            .expect("ASCII is refused")
            .to_string();
        assert!(e.contains("binary MSH 4.1") && !e.contains('\n'), "{e}");
    }
}
