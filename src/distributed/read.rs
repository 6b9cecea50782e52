//! Reading a binary MSH 4.1 file by offsets: runs of elements, ghost rings, and a rank's
//! ghosted sub-mesh.
//!
//! Input: the path of a binary (little-endian, 8-byte `size_t`) MSH 4.1 file of linear hexes
//! (3D) or quads (2D) ([`MshFile::open`]). Outputs: a contiguous run of the file's elements
//! ([`MshFile::run`]); the elements within g vertex rings of a set of elements
//! ([`MshFile::ghosts`]); the coordinates of a set of nodes; and a [`LocalMesh`]: given own
//! elements, ghosts and the ghosts' owners, the tagged boundary facets whose vertices are all
//! present and only the nodes these use, with the global id of every element (its index among
//! the file's elements) and vertex (its node tag). [`super::share`] decides which elements a
//! rank owns.
//!
//! How it reads: one pass over the section headers records where each node and element block
//! starts (its records are skipped by seeking); a run is read at its offsets; each ghost ring
//! is one streamed pass over the element blocks in chunks, keeping the elements that touch a
//! node of the previous rings; the tagged facets are one streamed pass; the coordinates one
//! streamed pass over the node blocks keeping the needed tags. No rank ever holds more than
//! its elements, ghosts and their nodes, plus one chunk.
//!
//! Invariant: the local mesh is what the serial reader ([`crate::io::read_mesh`]) makes of
//! the file restricted to these elements: the same element tags (the entity's first physical
//! tag), the same facet tags and group names, the same orientation fix per element.

use crate::mesh::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};
use crate::mesh::{LinearMesh, MeshOptions};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::Path;

/// Records read per chunk of a streamed pass.
const CHUNK: usize = 1 << 14;

/// One block of `$Nodes`.
#[derive(Clone, Debug)]
struct NodeBlock {
    n: u64,
    /// Offset of the node tags; the coordinates follow at `tags_at + 8 n`.
    tags_at: u64,
    /// Doubles per node (3, plus the parametric coordinates of parametric blocks).
    stride: usize,
}

/// One block of `$Elements`.
#[derive(Clone, Debug)]
struct ElementBlock {
    /// Gmsh element type.
    kind: i32,
    /// Physical tag of its entity (0: none).
    physical: i32,
    n: u64,
    /// Nodes per element.
    npe: usize,
    /// Offset of its first record (tag, then `npe` node tags, all `size_t`).
    data_at: u64,
}

/// Where everything is in the file.
#[derive(Debug, Default)]
struct Index {
    tag_names: BTreeMap<i32, String>,
    nodes: Vec<NodeBlock>,
    elements: Vec<ElementBlock>,
}

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

fn io_err(e: std::io::Error) -> ParseError {
    err(format!("read failed: {e}"))
}

/// Nodes per element of the Gmsh types a linear quad/hex file may hold.
fn nodes_per_element(kind: i32) -> Result<usize, ParseError> {
    Ok(match kind {
        15 => 1,
        1 => 2,
        2 => 3,
        3 => 4,
        4 => 4,
        5 => 8,
        6 => 6,
        7 => 5,
        8 => 3,
        9 => 6,
        10 => 9,
        11 => 10,
        12 => 27,
        16 => 8,
        17 => 20,
        _ => {
            return Err(err(format!(
                "element type {kind} is not supported by the rank-local reader"
            )));
        }
    })
}

struct Reader {
    r: BufReader<File>,
}

impl Reader {
    fn line(&mut self) -> Result<Option<String>, ParseError> {
        let mut buf = Vec::new();
        let n = self.r.read_until(b'\n', &mut buf).map_err(io_err)?;
        if n == 0 {
            return Ok(None);
        }
        Ok(Some(String::from_utf8_lossy(&buf).trim().to_string()))
    }
    /// The next non-empty line.
    fn token_line(&mut self) -> Result<Option<String>, ParseError> {
        while let Some(l) = self.line()? {
            if !l.is_empty() {
                return Ok(Some(l));
            }
        }
        Ok(None)
    }
    fn expect_end(&mut self, name: &str) -> Result<(), ParseError> {
        match self.token_line()? {
            Some(l) if l == format!("$End{name}") => Ok(()),
            other => Err(err(format!(
                "expected $End{name}, found {}",
                other.unwrap_or_else(|| "the end of the file".into())
            ))),
        }
    }
    fn bytes<const N: usize>(&mut self) -> Result<[u8; N], ParseError> {
        let mut b = [0u8; N];
        self.r
            .read_exact(&mut b)
            .map_err(|_| err("the file ends inside a binary section"))?;
        Ok(b)
    }
    fn i32(&mut self) -> Result<i32, ParseError> {
        Ok(i32::from_le_bytes(self.bytes::<4>()?))
    }
    fn size(&mut self) -> Result<u64, ParseError> {
        Ok(u64::from_le_bytes(self.bytes::<8>()?))
    }
    fn pos(&mut self) -> Result<u64, ParseError> {
        self.r.stream_position().map_err(io_err)
    }
    fn skip(&mut self, bytes: u64) -> Result<(), ParseError> {
        let bytes = i64::try_from(bytes).map_err(|_| err("a block size overflows"))?;
        self.r.seek_relative(bytes).map_err(io_err)
    }
    fn seek(&mut self, at: u64) -> Result<(), ParseError> {
        self.r.seek(SeekFrom::Start(at)).map(|_| ()).map_err(io_err)
    }
    /// `n` little-endian u64 at the current position.
    fn sizes(&mut self, out: &mut Vec<u64>, n: usize) -> Result<(), ParseError> {
        let mut b = vec![0u8; 8 * n];
        self.r
            .read_exact(&mut b)
            .map_err(|_| err("the file ends inside a binary section"))?;
        out.clear();
        out.extend(
            b.chunks_exact(8)
                .map(|c| u64::from_le_bytes(c.try_into().unwrap())),
        );
        Ok(())
    }
}

fn open(path: &Path) -> Result<Reader, ParseError> {
    let f = File::open(path).map_err(io_err)?;
    Ok(Reader {
        r: BufReader::with_capacity(1 << 16, f),
    })
}

/// The sections before `$Nodes`, as bytes, with the format checked: what the rank-local
/// reader can read, and no partitioned file.
fn head(r: &mut Reader) -> Result<Vec<u8>, ParseError> {
    let mut head = Vec::new();
    let mut buf = Vec::new();
    loop {
        buf.clear();
        if r.r.read_until(b'\n', &mut buf).map_err(io_err)? == 0 {
            return Err(err("no $Nodes section"));
        }
        let line = String::from_utf8_lossy(&buf);
        match line.trim() {
            "$Nodes" => break,
            "$PartitionedEntities" => {
                return Err(err(
                    "a partitioned MSH file: give the partition files IN_1.msh … IN_N.msh as IN.msh (one per rank)",
                ));
            }
            "$MeshFormat" if head.is_empty() => {
                head.extend_from_slice(&buf);
                buf.clear();
                r.r.read_until(b'\n', &mut buf).map_err(io_err)?;
                let line = String::from_utf8_lossy(&buf);
                let f: Vec<&str> = line.split_whitespace().collect();
                if f.len() != 3 || f[0] != "4.1" || f[1] != "1" || f[2] != "8" {
                    return Err(err(format!(
                        "the rank-local reader reads binary MSH 4.1 with 8-byte size_t; this file's format line is '{}' (convert it with gmsh -format msh41 -bin, or run on one process)",
                        line.trim()
                    )));
                }
                head.extend_from_slice(&buf);
                let one = r.bytes::<4>()?;
                if i32::from_le_bytes(one) != 1 {
                    return Err(err("big-endian MSH files are not supported"));
                }
                head.extend_from_slice(&one);
                continue;
            }
            _ => {}
        }
        head.extend_from_slice(&buf);
    }
    Ok(head)
}

/// The header pass: format, names, entities' physical tags (parsed by the serial reader's
/// [`crate::io::gmsh::header_tags`]), and the blocks' offsets.
fn index(path: &Path) -> Result<Index, ParseError> {
    let mut r = open(path)?;
    let head = head(&mut r)?;
    if !head.starts_with(b"$MeshFormat") {
        return Err(err("no $MeshFormat section"));
    }
    let tags = crate::io::gmsh::header_tags(&head)?;
    drop(head);
    let mut ix = Index {
        tag_names: tags.tag_names,
        ..Index::default()
    };
    // `head` stopped at the `$Nodes` line.
    let mut next = Some("$Nodes".to_string());
    while let Some(l) = next {
        match l.as_str() {
            "$Nodes" => {
                let blocks = r.size()?;
                let _n = r.size()?;
                r.skip(16)?;
                for _ in 0..blocks {
                    let dim = r.i32()?;
                    let _tag = r.i32()?;
                    let parametric = r.i32()?;
                    let n = r.size()?;
                    let stride = 3 + if parametric != 0 {
                        dim.max(0) as usize
                    } else {
                        0
                    };
                    let tags_at = r.pos()?;
                    ix.nodes.push(NodeBlock { n, tags_at, stride });
                    r.skip(8 * n + 8 * n * stride as u64)?;
                }
                r.expect_end("Nodes")?;
            }
            "$Elements" => {
                let blocks = r.size()?;
                r.skip(24)?;
                for _ in 0..blocks {
                    let dim = r.i32()?;
                    let tag = r.i32()?;
                    let kind = r.i32()?;
                    let n = r.size()?;
                    let npe = nodes_per_element(kind)?;
                    let data_at = r.pos()?;
                    ix.elements.push(ElementBlock {
                        kind,
                        physical: tags.entities.physical_of(dim, tag),
                        n,
                        npe,
                        data_at,
                    });
                    r.skip(8 * n * (1 + npe as u64))?;
                }
                r.expect_end("Elements")?;
            }
            s if s.starts_with('$') => {
                // Another section: skip to its end line.
                let end = format!("$End{}", &s[1..]);
                loop {
                    match r.line()? {
                        Some(l) if l == end => break,
                        Some(_) => {}
                        None => return Err(err(format!("{s} has no {end}"))),
                    }
                }
            }
            other => return Err(err(format!("unexpected line '{other}' between sections"))),
        }
        next = r.token_line()?;
    }
    Ok(ix)
}

/// Calls `f(global index, physical tag, nodes)` for every element of Gmsh type `kind`, in
/// file order, reading `CHUNK` records at a time.
fn stream(
    r: &mut Reader,
    ix: &Index,
    kind: i32,
    mut f: impl FnMut(u64, i32, &[u64]),
) -> Result<(), ParseError> {
    let mut g = 0u64;
    let mut buf = Vec::new();
    for b in ix.elements.iter().filter(|b| b.kind == kind) {
        r.seek(b.data_at)?;
        let rec = 1 + b.npe;
        let mut left = b.n;
        while left > 0 {
            let k = left.min(CHUNK as u64) as usize;
            r.sizes(&mut buf, k * rec)?;
            for c in buf.chunks_exact(rec) {
                f(g, b.physical, &c[1..]);
                g += 1;
            }
            left -= k as u64;
        }
    }
    Ok(())
}

/// Elements `lo..hi` (global indices among those of type `kind`), read at their offsets.
fn read_range(
    r: &mut Reader,
    ix: &Index,
    kind: i32,
    lo: u64,
    hi: u64,
    mut f: impl FnMut(u64, i32, &[u64]),
) -> Result<(), ParseError> {
    let mut first = 0u64;
    let mut buf = Vec::new();
    for b in ix.elements.iter().filter(|b| b.kind == kind) {
        let (s, e) = (lo.max(first), hi.min(first + b.n));
        if s < e {
            let rec = 1 + b.npe;
            r.seek(b.data_at + 8 * (s - first) * rec as u64)?;
            let mut g = s;
            while g < e {
                let k = (e - g).min(CHUNK as u64) as usize;
                r.sizes(&mut buf, k * rec)?;
                for c in buf.chunks_exact(rec) {
                    f(g, b.physical, &c[1..]);
                    g += 1;
                }
            }
        }
        first += b.n;
    }
    Ok(())
}

/// The coordinates of the nodes in `have`, in file order, read block by block in chunks (a
/// chunk's coordinates are read only when one of its tags is needed). Fails when a needed node
/// is not defined.
fn read_coordinates(
    r: &mut Reader,
    ix: &Index,
    have: &HashSet<u64>,
) -> Result<(Vec<u64>, Vec<[f64; 3]>), ParseError> {
    let mut global_vertex: Vec<u64> = Vec::with_capacity(have.len());
    let mut points: Vec<[f64; 3]> = Vec::with_capacity(have.len());
    let mut tag_buf = Vec::new();
    let mut xyz_buf = Vec::new();
    for b in &ix.nodes {
        let mut done = 0u64;
        while done < b.n {
            let k = (b.n - done).min(CHUNK as u64) as usize;
            r.seek(b.tags_at + 8 * done)?;
            r.sizes(&mut tag_buf, k)?;
            if tag_buf.iter().any(|t| have.contains(t)) {
                r.seek(b.tags_at + 8 * b.n + 8 * done * b.stride as u64)?;
                r.sizes(&mut xyz_buf, k * b.stride)?;
                for (i, t) in tag_buf.iter().enumerate() {
                    if have.contains(t) {
                        let x = &xyz_buf[i * b.stride..i * b.stride + 3];
                        global_vertex.push(*t);
                        points.push([
                            f64::from_bits(x[0]),
                            f64::from_bits(x[1]),
                            f64::from_bits(x[2]),
                        ]);
                    }
                }
            }
            done += k as u64;
        }
    }
    if global_vertex.len() != have.len() {
        return Err(err(format!(
            "{} node(s) used by the elements are not defined in $Nodes",
            have.len() - global_vertex.len()
        )));
    }
    Ok((global_vertex, points))
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
    r: Reader,
    ix: Index,
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
    /// Index the file and check it holds only quads or only hexes among its cells.
    pub fn open(path: &Path) -> Result<MshFile, ParseError> {
        let ix = index(path)?;
        let count = |k: i32| -> u64 {
            ix.elements
                .iter()
                .filter(|b| b.kind == k)
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
        for b in &ix.elements {
            let bad = match dim {
                3 => matches!(b.kind, 4..=7 | 11..=14 | 16..=19),
                _ => matches!(b.kind, 2 | 9 | 10 | 16),
            } && b.kind != kind;
            if bad && b.n > 0 {
                return Err(err(format!(
                    "element type {} next to the {}: polyspline curves linear quad (2D) and hex (3D) meshes",
                    b.kind,
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
            r: open(path)?,
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
        read_range(&mut self.r, &self.ix, self.kind, lo, hi, |g, p, v| {
            out.push(g, p, v)
        })?;
        Ok(out)
    }

    /// The cells within `depth` vertex rings of `own` and not in it: one streamed pass over
    /// the cell blocks per ring, keeping the cells that touch a node of the previous rings.
    pub fn ghosts(&mut self, own: &Elements, depth: usize) -> Result<Elements, ParseError> {
        let mut have: HashSet<u64> = own.nodes.iter().copied().collect();
        let mut seen: HashSet<u64> = own.global.iter().copied().collect();
        let mut out = Elements::default();
        for _ in 0..depth {
            let before = out.global.len();
            stream(&mut self.r, &self.ix, self.kind, |g, p, v| {
                if !seen.contains(&g) && v.iter().any(|t| have.contains(t)) {
                    seen.insert(g);
                    out.push(g, p, v);
                }
            })?;
            if out.global.len() == before {
                break;
            }
            have.extend(out.nodes[self.npe * before..].iter().copied());
        }
        Ok(out)
    }

    /// The coordinates of the nodes in `have`, in file order; fails when a needed node is not
    /// defined.
    pub fn coordinates(
        &mut self,
        have: &HashSet<u64>,
    ) -> Result<(Vec<u64>, Vec<[f64; 3]>), ParseError> {
        read_coordinates(&mut self.r, &self.ix, have)
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
        stream(&mut self.r, &self.ix, self.facet_kind, |_, p, v| {
            if p != 0 && v.iter().all(|t| have.contains(t)) {
                facets.extend_from_slice(v);
                facet_tags.push(p);
            }
        })?;

        let (global_vertex, points) = read_coordinates(&mut self.r, &self.ix, &have)?;
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
            // The ranks' readers do not read `$Periodic`.
            periodic: Vec::new(),
            tag_names: self.ix.tag_names.clone(),
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
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::gmsh_write::{MshVersion, write_msh};
    use crate::mesh::Topology;
    use crate::mesh::generate::{Kind, generate};

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
        let ghosts = f.ghosts(&own, depth).unwrap();
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
