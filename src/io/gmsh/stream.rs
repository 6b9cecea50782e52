//! A binary MSH 4.1 file read by offsets, never held whole: the index of its blocks, then
//! runs of elements, streamed passes over the elements of one type, and the coordinates of a
//! set of nodes.
//!
//! Input: a file's path. [`Head::open`] parses the sections before `$Nodes` with the in-memory
//! parser ([`super::header_tags`]: format, physical names, entities); [`Head::index`] (binary
//! MSH 4.1 only, either byte order, 4- or 8-byte `size_t`) then makes one pass over the section
//! headers, recording where each node and element block starts and skipping its records by
//! seeking. Outputs: [`Indexed::range`] (elements `lo..hi` of one type, at their offsets),
//! [`Indexed::for_each`] (every element of one type, in file order, `CHUNK` records at a time)
//! and [`Indexed::coordinates`] (the nodes of a set, in file order, a chunk's coordinates read
//! only when one of its tags is wanted), and [`Indexed::declared_periodic`] (the `$Periodic`
//! section's bytes, parsed by the in-memory parser's code). Memory: the index, one chunk, and
//! what the caller keeps.
//!
//! Invariants: block headers, element types, entity physical tags and binary decoding are the
//! in-memory parser's ([`super::nodes::NodeBlockHeader`], [`super::elements::ElementBlockHeader`],
//! [`super::element_types`], [`super::binary::Bin`]), so an element has the tag [`super::read`]
//! gives it; a block whose records run past the end of the file is an error while indexing,
//! so the later passes read only bytes that exist. Errors name the byte offset.

use super::binary::Bin;
use super::element_types::element_type;
use super::elements::ElementBlockHeader;
use super::nodes::{NodeBlockHeader, section_counts};
use super::{Format, HeaderTags, header_tags};
use crate::mesh::raw::{Location, ParseError};
use std::collections::HashSet;
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::Path;

/// Records read per chunk of a streamed pass.
const CHUNK: usize = 1 << 14;

fn io_err(e: std::io::Error) -> ParseError {
    ParseError::new(Location::File, format!("read failed: {e}"))
}

/// One block of `$Nodes`.
#[derive(Clone, Debug)]
struct NodeBlock {
    n: u64,
    /// Offset of the node tags; the coordinates follow at `tags_at + size_t n`.
    tags_at: u64,
    /// Doubles per node (3, plus the parametric coordinates of parametric blocks).
    stride: usize,
}

/// One block of `$Elements`.
#[derive(Clone, Debug)]
pub(crate) struct ElementBlock {
    /// Dimension of its entity (that of its elements).
    pub(crate) dim: i32,
    pub(crate) gmsh_type: i32,
    /// Physical tag of its entity (0: none), as [`super::read`] tags its elements.
    pub(crate) physical: i32,
    pub(crate) n: u64,
    /// Nodes per element.
    pub(crate) npe: usize,
    /// Offset of its first record (tag, then `npe` node tags, all `size_t`).
    data_at: u64,
}

/// A buffered file with its length, read at offsets.
struct Source {
    r: BufReader<File>,
    len: u64,
}

impl Source {
    fn pos(&mut self) -> Result<u64, ParseError> {
        self.r.stream_position().map_err(io_err)
    }
    fn seek(&mut self, at: u64) -> Result<(), ParseError> {
        self.r.seek(SeekFrom::Start(at)).map(|_| ()).map_err(io_err)
    }
    fn line(&mut self) -> Result<Option<Vec<u8>>, ParseError> {
        let mut buf = Vec::new();
        let n = self.r.read_until(b'\n', &mut buf).map_err(io_err)?;
        Ok((n > 0).then_some(buf))
    }
    /// The next non-empty line, trimmed.
    fn token_line(&mut self) -> Result<Option<String>, ParseError> {
        while let Some(l) = self.line()? {
            let l = String::from_utf8_lossy(&l).trim().to_string();
            if !l.is_empty() {
                return Ok(Some(l));
            }
        }
        Ok(None)
    }
    fn expect_end(&mut self, name: &str) -> Result<(), ParseError> {
        let at = self.pos()?;
        match self.token_line()? {
            Some(l) if l == format!("$End{name}") => Ok(()),
            other => Err(ParseError::at_byte(
                at as usize,
                format!(
                    "expected $End{name}, found {}",
                    other.unwrap_or_else(|| "the end of the file".into())
                ),
            )),
        }
    }
    /// `n` bytes at the current position into `buf`, and their offset.
    fn bytes(&mut self, buf: &mut Vec<u8>, n: usize, what: &str) -> Result<u64, ParseError> {
        let at = self.pos()?;
        buf.resize(n, 0);
        self.r.read_exact(buf).map_err(|_| {
            ParseError::at_byte(
                at as usize,
                format!("expected {what} ({n} bytes), found the end of the file"),
            )
        })?;
        Ok(at)
    }
    /// Skip the `count` records of `record` bytes of block `what`, checked against the file's
    /// length.
    fn skip(
        &mut self,
        count: u64,
        record: usize,
        what: &dyn Fn() -> String,
    ) -> Result<(), ParseError> {
        let at = self.pos()?;
        let bytes = count.checked_mul(record as u64);
        match bytes.and_then(|b| at.checked_add(b)) {
            Some(end) if end <= self.len => self.seek(end),
            _ => Err(ParseError::at_byte(
                at as usize,
                format!("{} runs past the end of the file", what()),
            )),
        }
    }
}

/// The sections of a file before `$Nodes`, parsed, with the file positioned after the
/// `$Nodes` line.
pub(crate) struct Head {
    pub(crate) header: HeaderTags,
    src: Source,
}

impl Head {
    /// Read and parse the sections before `$Nodes` (a file without `$Nodes` is an error).
    pub(crate) fn open(path: &Path) -> Result<Head, ParseError> {
        let f = File::open(path).map_err(io_err)?;
        let len = f.metadata().map_err(io_err)?.len();
        let mut src = Source {
            r: BufReader::with_capacity(1 << 16, f),
            len,
        };
        let mut head = Vec::new();
        loop {
            let Some(line) = src.line()? else {
                return Err(ParseError::new(Location::File, "no $Nodes section"));
            };
            if line.trim_ascii() == b"$Nodes" {
                break;
            }
            head.extend_from_slice(&line);
        }
        let header = header_tags(&head)?;
        Ok(Head { header, src })
    }

    /// Index the blocks of `$Nodes`, `$Elements` and skip every other section (see the
    /// module docs). The file must be binary MSH 4.1.
    pub(crate) fn index(self) -> Result<Indexed, ParseError> {
        let format = match self.header.format {
            Some(f) if self.header.is_binary_41() => f,
            _ => {
                return Err(ParseError::new(
                    Location::File,
                    format!(
                        "{} is not read by offsets (binary MSH 4.1 is)",
                        self.header.describe_format()
                    ),
                ));
            }
        };
        let mut ix = Indexed {
            src: self.src,
            format,
            header: self.header,
            nodes: Vec::new(),
            elements: Vec::new(),
            periodic_at: None,
        };
        // `Head::open` stopped after the `$Nodes` line.
        let mut next = Some("$Nodes".to_string());
        while let Some(l) = next {
            match l.as_str() {
                "$Nodes" => ix.index_nodes()?,
                "$Elements" => ix.index_elements()?,
                s if s.starts_with('$') => {
                    let body = ix.src.pos()?;
                    let end = format!("$End{}", &s[1..]);
                    loop {
                        let at = ix.src.pos()?;
                        match ix.src.line()? {
                            Some(l) if String::from_utf8_lossy(&l).trim() == end => {
                                if s == "$Periodic" {
                                    ix.periodic_at = Some((body, at));
                                }
                                break;
                            }
                            Some(_) => {}
                            None => {
                                return Err(ParseError::new(
                                    Location::File,
                                    format!("{s} has no {end} before the end of the file"),
                                ));
                            }
                        }
                    }
                }
                other => {
                    let at = ix.src.pos()?;
                    return Err(ParseError::new(
                        Location::File,
                        format!("unexpected line '{other}' between sections (before byte {at})"),
                    ));
                }
            }
            next = ix.src.token_line()?;
        }
        Ok(ix)
    }
}

/// An indexed binary MSH 4.1 file (see the module docs).
pub(crate) struct Indexed {
    src: Source,
    format: Format,
    pub(crate) header: HeaderTags,
    nodes: Vec<NodeBlock>,
    /// The element blocks, in file order.
    pub(crate) elements: Vec<ElementBlock>,
    /// Where the body of the file's `$Periodic` section starts and ends (its `$EndPeriodic`
    /// line), when it has one ([`Indexed::declared_periodic`] reads it).
    periodic_at: Option<(u64, u64)>,
}

impl Indexed {
    /// A decoder over `data`, read at file offset `at`.
    fn bin<'a>(&self, data: &'a [u8], at: u64) -> Bin<'a> {
        Bin {
            data,
            pos: 0,
            base: at as usize,
            big_endian: self.format.big_endian,
            size_t: self.format.size_t,
        }
    }

    /// The counts that open `$Nodes` or `$Elements` (`item`: "node" or "element").
    fn counts(&mut self, item: &str) -> Result<u64, ParseError> {
        let mut buf = Vec::new();
        let what = format!("the counts of the {item} section");
        let at = self.src.bytes(&mut buf, 4 * self.format.size_t, &what)?;
        Ok(section_counts(&mut self.bin(&buf, at), item)?.0)
    }

    /// The header bytes of block `blk` of `item` ("node" or "element"; the two headers have
    /// the same size), with a decoder over them.
    fn block_header<'b>(
        &mut self,
        buf: &'b mut Vec<u8>,
        item: &str,
        blk: u64,
    ) -> Result<Bin<'b>, ParseError> {
        let what = format!("the header of {item} block {}", blk + 1);
        let at = self
            .src
            .bytes(buf, NodeBlockHeader::len(self.format.size_t), &what)?;
        Ok(self.bin(buf, at))
    }

    fn index_nodes(&mut self) -> Result<(), ParseError> {
        let sz = self.format.size_t;
        let blocks = self.counts("node")?;
        let mut buf = Vec::new();
        for blk in 0..blocks {
            let h = NodeBlockHeader::read(&mut self.block_header(&mut buf, "node", blk)?, blk)?;
            let tags_at = self.src.pos()?;
            let stride = h.stride();
            self.src.skip(h.count, sz + 8 * stride, &|| {
                format!("node block {} ({} nodes)", blk + 1, h.count)
            })?;
            self.nodes.push(NodeBlock {
                n: h.count,
                tags_at,
                stride,
            });
        }
        self.src.expect_end("Nodes")
    }

    fn index_elements(&mut self) -> Result<(), ParseError> {
        let sz = self.format.size_t;
        let blocks = self.counts("element")?;
        let mut buf = Vec::new();
        for blk in 0..blocks {
            let mut b = self.block_header(&mut buf, "element", blk)?;
            let at = b.at();
            let h = ElementBlockHeader::read(&mut b, blk)?;
            let (_, npe) =
                element_type(i64::from(h.gmsh_type)).map_err(|m| ParseError::at_byte(at, m))?;
            let data_at = self.src.pos()?;
            self.src.skip(h.count, sz * (1 + npe), &|| {
                format!("element block {} ({} elements)", blk + 1, h.count)
            })?;
            self.elements.push(ElementBlock {
                dim: h.dim,
                gmsh_type: h.gmsh_type,
                physical: self.header.entities.physical_of(h.dim, h.entity),
                n: h.count,
                npe,
                data_at,
            });
        }
        self.src.expect_end("Elements")
    }

    /// `n` `size_t` values at `at`, decoded into `out`.
    fn sizes(
        &mut self,
        raw: &mut Vec<u8>,
        out: &mut Vec<u64>,
        at: u64,
        n: usize,
    ) -> Result<(), ParseError> {
        let sz = self.format.size_t;
        self.src.seek(at)?;
        self.src.bytes(raw, n * sz, "records")?;
        let b = self.bin(raw, at);
        out.clear();
        out.extend(raw.chunks_exact(sz).map(|c| b.dec_size(c)));
        Ok(())
    }

    /// Calls `f(index, physical tag, node tags)` for elements `lo..hi` of Gmsh type
    /// `gmsh_type` (indices counted among that type's elements, in file order), read at their
    /// offsets `CHUNK` records at a time.
    pub(crate) fn range(
        &mut self,
        gmsh_type: i32,
        lo: u64,
        hi: u64,
        mut f: impl FnMut(u64, i32, &[u64]),
    ) -> Result<(), ParseError> {
        let sz = self.format.size_t as u64;
        let mut first = 0u64;
        let (mut raw, mut buf) = (Vec::new(), Vec::new());
        let blocks: Vec<ElementBlock> = self
            .elements
            .iter()
            .filter(|b| b.gmsh_type == gmsh_type)
            .cloned()
            .collect();
        for b in blocks {
            let (s, e) = (lo.max(first), hi.min(first + b.n));
            let rec = 1 + b.npe;
            let mut g = s;
            while g < e {
                let k = (e - g).min(CHUNK as u64) as usize;
                let at = b.data_at + sz * (g - first) * rec as u64;
                self.sizes(&mut raw, &mut buf, at, k * rec)?;
                for c in buf.chunks_exact(rec) {
                    f(g, b.physical, &c[1..]);
                    g += 1;
                }
            }
            first += b.n;
        }
        Ok(())
    }

    /// Calls `f(index, physical tag, node tags)` for every element of Gmsh type `gmsh_type`,
    /// in file order (a streamed pass).
    pub(crate) fn for_each(
        &mut self,
        gmsh_type: i32,
        f: impl FnMut(u64, i32, &[u64]),
    ) -> Result<(), ParseError> {
        self.range(gmsh_type, 0, u64::MAX, f)
    }

    /// The periodic pairs `$Periodic` declares (none without the section), as the in-memory
    /// reader gives them ([`super::read`]'s `RawMesh::periodic`): the section's bytes read at
    /// their offset and parsed by its code, then the node tags of its node pairs checked
    /// against `$Nodes` in one streamed pass over the node tags (the first undefined one is
    /// the in-memory reader's error at its byte).
    pub(crate) fn declared_periodic(
        &mut self,
    ) -> Result<Vec<crate::mesh::raw::DeclaredPeriodic>, ParseError> {
        let Some((body, end)) = self.periodic_at else {
            return Ok(Vec::new());
        };
        let mut data = Vec::new();
        self.src.seek(body)?;
        self.src
            .bytes(&mut data, (end - body) as usize, "the $Periodic section")?;
        let (links, nodes) =
            super::periodic::stream_section(&self.header, self.format, &data, body)?;
        drop(data);
        let mut missing: HashSet<u64> = nodes.iter().map(|n| n.0).collect();
        let sz = self.format.size_t as u64;
        let (mut raw, mut tags) = (Vec::new(), Vec::new());
        for b in self.nodes.clone() {
            let mut done = 0u64;
            while done < b.n && !missing.is_empty() {
                let k = (b.n - done).min(CHUNK as u64) as usize;
                self.sizes(&mut raw, &mut tags, b.tags_at + sz * done, k)?;
                for t in &tags {
                    missing.remove(t);
                }
                done += k as u64;
            }
        }
        match nodes.into_iter().find(|n| missing.contains(&n.0)) {
            Some((tag, at)) => Err(super::periodic::undefined_node(tag, at)),
            None => Ok(links),
        }
    }

    /// The tags and coordinates of the nodes in `have`, in file order; fails when a wanted
    /// node is not defined.
    pub(crate) fn coordinates(
        &mut self,
        have: &HashSet<u64>,
    ) -> Result<(Vec<u64>, Vec<[f64; 3]>), ParseError> {
        let sz = self.format.size_t as u64;
        let mut tags: Vec<u64> = Vec::with_capacity(have.len());
        let mut points: Vec<[f64; 3]> = Vec::with_capacity(have.len());
        let (mut raw, mut tag_buf) = (Vec::new(), Vec::new());
        for b in self.nodes.clone() {
            let mut done = 0u64;
            while done < b.n {
                let k = (b.n - done).min(CHUNK as u64) as usize;
                self.sizes(&mut raw, &mut tag_buf, b.tags_at + sz * done, k)?;
                if !tag_buf.iter().any(|t| have.contains(t)) {
                    done += k as u64;
                    continue;
                }
                let rec = 8 * b.stride;
                let at = b.tags_at + sz * b.n + done * rec as u64;
                self.src.seek(at)?;
                self.src.bytes(&mut raw, k * rec, "node coordinates")?;
                let d = self.bin(&raw, at);
                for (t, x) in tag_buf.iter().zip(raw.chunks_exact(rec)) {
                    if have.contains(t) {
                        tags.push(*t);
                        points.push([d.dec_f64(x), d.dec_f64(&x[8..]), d.dec_f64(&x[16..])]);
                    }
                }
                done += k as u64;
            }
        }
        if tags.len() != have.len() {
            return Err(ParseError::new(
                Location::File,
                format!(
                    "{} node(s) used by the elements are not defined in $Nodes",
                    have.len() - tags.len()
                ),
            ));
        }
        Ok((tags, points))
    }
}
