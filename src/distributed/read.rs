//! One rank's share of a binary MSH 4.1 file, read by offsets, with ghost layers.
//!
//! Input: the path of a binary (little-endian, 8-byte `size_t`) MSH 4.1 file, the rank, the
//! number of ranks and the ghost depth g. Output: a [`LocalMesh`]: the rank's contiguous run
//! of the file's elements (hexes in 3D, quads in 2D, in file order: ranks r gets elements
//! ⌊rN/P⌋ … ⌊(r+1)N/P⌋ − 1), then the ghost elements within g vertex rings of them, the
//! tagged boundary facets whose vertices are all present, and only the nodes these use, with
//! the global id of every element (its index among the file's elements) and vertex (its node
//! tag).
//!
//! How it reads: one pass over the section headers records where each node and element block
//! starts (its records are skipped by seeking); the rank's own elements are read at their
//! offsets; each ghost ring is one streamed pass over the element blocks in chunks, keeping
//! the elements that touch a node of the previous rings; the tagged facets are one streamed
//! pass; the coordinates one streamed pass over the node blocks keeping the needed tags. No
//! rank ever holds more than its elements, ghosts and their nodes, plus one chunk.
//!
//! Invariant: the local mesh is what the serial reader ([`crate::io::read_mesh`]) makes of
//! the file restricted to these elements: the same element tags (the entity's first physical
//! tag), the same facet tags and group names, the same orientation fix per element.

use crate::io::raw::{CellKind, Location, ParseError, RawBlock, RawMesh};
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

    /// The rank owning global element `g` under [`LocalMesh::starts`].
    pub fn owner(starts: &[u64], g: u64) -> usize {
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

/// The header pass: format, names, entities' physical tags, and the blocks' offsets.
fn index(path: &Path) -> Result<Index, ParseError> {
    let mut r = open(path)?;
    let mut ix = Index::default();
    let mut physical: HashMap<(i32, i32), i32> = HashMap::new();
    let mut format = false;
    while let Some(l) = r.token_line()? {
        match l.as_str() {
            "$MeshFormat" => {
                let head = r.line()?.unwrap_or_default();
                let f: Vec<&str> = head.split_whitespace().collect();
                if f.len() != 3 || f[0] != "4.1" || f[1] != "1" || f[2] != "8" {
                    return Err(err(format!(
                        "the rank-local reader reads binary MSH 4.1 with 8-byte size_t; this file's format line is '{head}' (convert it with gmsh -format msh41 -bin, or run on one process)"
                    )));
                }
                if r.i32()? != 1 {
                    return Err(err("big-endian MSH files are not supported"));
                }
                r.expect_end("MeshFormat")?;
                format = true;
            }
            "$PhysicalNames" => {
                let n: usize = r
                    .line()?
                    .and_then(|l| l.parse().ok())
                    .ok_or_else(|| err("bad $PhysicalNames count"))?;
                for _ in 0..n {
                    let l = r.line()?.unwrap_or_default();
                    let mut it = l.splitn(3, char::is_whitespace);
                    let _dim = it.next();
                    let tag: i32 = it
                        .next()
                        .and_then(|t| t.parse().ok())
                        .ok_or_else(|| err(format!("bad physical name line '{l}'")))?;
                    let rest = it.next().unwrap_or("").trim();
                    let name = rest
                        .strip_prefix('"')
                        .and_then(|r| r.strip_suffix('"'))
                        .unwrap_or(rest);
                    let entry = ix.tag_names.entry(tag).or_default();
                    if entry.is_empty() {
                        *entry = name.to_string();
                    } else if entry.split(" / ").all(|e| e != name) {
                        entry.push_str(" / ");
                        entry.push_str(name);
                    }
                }
                r.expect_end("PhysicalNames")?;
            }
            "$Entities" => {
                let mut counts = [0u64; 4];
                for c in &mut counts {
                    *c = r.size()?;
                }
                for (dim, &count) in counts.iter().enumerate() {
                    for _ in 0..count {
                        let tag = r.i32()?;
                        r.skip(if dim == 0 { 24 } else { 48 })?;
                        let nphys = r.size()?;
                        let mut first = 0;
                        for k in 0..nphys {
                            let p = r.i32()?;
                            if k == 0 {
                                first = p;
                            }
                        }
                        if dim > 0 {
                            let nb = r.size()?;
                            r.skip(4 * nb)?;
                        }
                        physical.insert((dim as i32, tag), first);
                    }
                }
                r.expect_end("Entities")?;
            }
            "$PartitionedEntities" => {
                return Err(err(
                    "a partitioned MSH file: give the partition files IN_1.msh … IN_N.msh as IN.msh (one per rank)",
                ));
            }
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
                        physical: physical.get(&(dim, tag)).copied().unwrap_or(0),
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
    }
    if !format {
        return Err(err("no $MeshFormat section"));
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

/// Read this rank's share with `depth` vertex rings of ghosts (see the module docs).
pub fn read_share(
    path: &Path,
    rank: usize,
    size: usize,
    depth: usize,
    options: &MeshOptions,
) -> Result<LocalMesh, crate::io::ReadError> {
    read_share_inner(path, rank, size, depth, options).map_err(|source| {
        crate::io::ReadError::Parse {
            path: path.to_owned(),
            source,
        }
    })
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

fn read_share_inner(
    path: &Path,
    rank: usize,
    size: usize,
    depth: usize,
    options: &MeshOptions,
) -> Result<LocalMesh, ParseError> {
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
    let starts = LocalMesh::starts(n_global, size);
    let (lo, hi) = (starts[rank], starts[rank + 1]);
    let mut r = open(path)?;

    // Own elements, then the ghost rings.
    let mut global_element: Vec<u64> = Vec::new();
    let mut tags: Vec<i32> = Vec::new();
    let mut nodes: Vec<u64> = Vec::new();
    read_range(&mut r, &ix, kind, lo, hi, |g, p, v| {
        global_element.push(g);
        tags.push(p);
        nodes.extend_from_slice(v);
    })?;
    let n_owned = global_element.len();
    let mut have: HashSet<u64> = nodes.iter().copied().collect();
    let mut ghost: HashSet<u64> = HashSet::new();
    for _ in 0..depth {
        let before = global_element.len();
        stream(&mut r, &ix, kind, |g, p, v| {
            if (lo..hi).contains(&g) || ghost.contains(&g) {
                return;
            }
            if v.iter().any(|t| have.contains(t)) {
                ghost.insert(g);
                global_element.push(g);
                tags.push(p);
                nodes.extend_from_slice(v);
            }
        })?;
        if global_element.len() == before {
            break;
        }
        have.extend(nodes[npe * before..].iter().copied());
    }
    drop(ghost);

    // Tagged facets among the present nodes.
    let mut facets: Vec<u64> = Vec::new();
    let mut facet_tags: Vec<i32> = Vec::new();
    stream(&mut r, &ix, facet_kind, |_, p, v| {
        if p != 0 && v.iter().all(|t| have.contains(t)) {
            facets.extend_from_slice(v);
            facet_tags.push(p);
        }
    })?;

    let (global_vertex, points) = read_coordinates(&mut r, &ix, &have)?;
    drop(have);
    let local: HashMap<u64, i64> = global_vertex
        .iter()
        .enumerate()
        .map(|(i, &t)| (t, i as i64))
        .collect();
    let mut block = RawBlock::new(
        if dim == 3 {
            CellKind::Hexahedron
        } else {
            CellKind::Quad
        },
        npe,
    );
    block.nodes = nodes.iter().map(|t| local[t]).collect();
    block.tags = tags;
    drop(nodes);
    let mut fblock = RawBlock::new(
        if dim == 3 {
            CellKind::Quad
        } else {
            CellKind::Line
        },
        npe / 2,
    );
    fblock.nodes = facets.iter().map(|t| local[t]).collect();
    fblock.tags = facet_tags;
    let raw = RawMesh {
        points,
        point_locations: Vec::new(),
        declared_dim: Some(3),
        blocks: vec![block, fblock],
        tag_names: ix.tag_names,
    };
    let mesh = LinearMesh::from_raw(raw, options)?;
    debug_assert_eq!(mesh.unused_vertices, 0);
    Ok(LocalMesh {
        mesh,
        n_owned,
        global_element,
        global_vertex,
        n_global,
    })
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

    #[test]
    fn shares_partition_the_elements_with_the_serial_coordinates_and_exact_ghost_rings() {
        let (path, serial) = cylinder("share.msh");
        let topo = Topology::build(&serial);
        let n = serial.n_elements();
        let size = 4;
        let mut seen = vec![0u8; n];
        for rank in 0..size {
            let depth = 2;
            let l = read_share(&path, rank, size, depth, &MeshOptions::default()).unwrap();
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
        let e = read_share(&path, 0, 2, 1, &MeshOptions::default())
            .err()
            .expect("ASCII is refused")
            .to_string();
        assert!(e.contains("binary MSH 4.1") && !e.contains('\n'), "{e}");
    }
}
