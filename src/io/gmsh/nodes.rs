//! `$Nodes` (MSH 2/4, ASCII and binary) and `$NOD` (MSH 1): node coordinates and tags.
//!
//! Input: the section body. Output: the points pushed to the mesh, in file order, with their
//! locations, and `Reader::nodes`, the [`NodeMap`] from node tag to 0-based position (in the
//! tag-keeping mode, the node tags in `Reader::keep` and the identity map: elements keep the
//! file's node tags). Invariants: a tag defined twice is an error at its second definition
//! (not checked when keeping tags); MSH 4 parametric coordinates are skipped; reservations are
//! capped by what the remaining input can hold. [`NodeBlockHeader`] and [`section_counts`]
//! read the binary MSH 4.1 headers for this parser and for the streamed one
//! ([`super::stream`]).

use super::binary::Bin;
use super::{Reader, Version, capped};
use crate::mesh::raw::{Location, ParseError};
use std::collections::HashMap;

/// Node tag -> 0-based position, or the tag itself (`Identity`, when keeping the file's tags).
pub(super) enum NodeMap {
    Dense(Vec<u32>),
    Sparse(HashMap<u64, u32>),
    Identity,
}

/// The counts that open a binary MSH 4.1 `$Nodes` or `$Elements` section (`item`: "node" or
/// "element"): the number of entity blocks and of items; the smallest and largest tags that
/// follow are read and dropped.
pub(super) fn section_counts(b: &mut Bin, item: &str) -> Result<(u64, u64), ParseError> {
    let blocks = b.size(&|| format!("number of {item} entity blocks"))?;
    let total = b.size(&|| format!("number of {item}s"))?;
    b.size(&|| format!("minimum {item} tag"))?;
    b.size(&|| format!("maximum {item} tag"))?;
    Ok((blocks, total))
}

/// The header of a binary MSH 4.1 `$Nodes` entity block (`NodeBlockHeader::len` bytes):
/// entity dimension and tag, parametric flag, node count. The block's `count` node tags
/// (`size_t`) follow, then `count` records of [`NodeBlockHeader::stride`] doubles.
pub(super) struct NodeBlockHeader {
    pub(super) dim: i32,
    pub(super) parametric: bool,
    pub(super) count: u64,
}

impl NodeBlockHeader {
    /// Bytes of the header for a `size_t` of `size_t` bytes.
    pub(super) fn len(size_t: usize) -> usize {
        12 + size_t
    }

    /// Read the header of node block `blk` (0-based); a dimension outside 0..=3 is an error.
    pub(super) fn read(b: &mut Bin, blk: u64) -> Result<Self, ParseError> {
        let what = || format!("header of node block {}", blk + 1);
        let header_at = b.at();
        let dim = b.i32(&what)?;
        b.i32(&what)?;
        let parametric = b.i32(&what)? != 0;
        let count = b.size(&what)?;
        if !(0..=3).contains(&dim) {
            return Err(ParseError::at_byte(
                header_at,
                format!(
                    "entity dimension {dim} of node block {} is not 0, 1, 2 or 3",
                    blk + 1
                ),
            ));
        }
        Ok(NodeBlockHeader {
            dim,
            parametric,
            count,
        })
    }

    /// Doubles per node record: x, y, z, then the parametric coordinates of a parametric block.
    pub(super) fn stride(&self) -> usize {
        3 + if self.parametric {
            self.dim as usize
        } else {
            0
        }
    }
}

impl NodeMap {
    /// Build the map; a tag defined twice is an error at its second definition.
    pub(super) fn build(tags: &[u64], locations: &[Location]) -> Result<NodeMap, ParseError> {
        if tags.len() >= u32::MAX as usize {
            return Err(ParseError::new(
                Location::File,
                format!("too many nodes ({})", tags.len()),
            ));
        }
        let duplicate = |i: usize, first: u32| {
            let loc = locations.get(i).copied().unwrap_or_default();
            let first_loc = locations.get(first as usize).copied().unwrap_or_default();
            ParseError::new(
                loc,
                format!(
                    "node tag {} is defined twice (first at {first_loc})",
                    tags[i]
                ),
            )
        };
        let max = tags.iter().copied().max().unwrap_or(0);
        // A dense table costs 4 bytes per possible tag; use it while that stays within a small
        // multiple of the node count.
        if max <= 10 * tags.len() as u64 + 1024 {
            let mut table = vec![u32::MAX; max as usize + 1];
            for (i, &t) in tags.iter().enumerate() {
                let slot = &mut table[t as usize];
                if *slot != u32::MAX {
                    return Err(duplicate(i, *slot));
                }
                *slot = i as u32;
            }
            Ok(NodeMap::Dense(table))
        } else {
            let mut map = HashMap::with_capacity(tags.len());
            for (i, &t) in tags.iter().enumerate() {
                if let Some(&first) = map.get(&t) {
                    return Err(duplicate(i, first));
                }
                map.insert(t, i as u32);
            }
            Ok(NodeMap::Sparse(map))
        }
    }

    /// The position of node `tag` (the tag itself for `Identity`); None when undefined.
    #[inline]
    pub(super) fn get(&self, tag: u64) -> Option<i64> {
        match self {
            NodeMap::Dense(v) => usize::try_from(tag)
                .ok()
                .and_then(|t| v.get(t))
                .copied()
                .filter(|&i| i != u32::MAX)
                .map(i64::from),
            NodeMap::Sparse(m) => m.get(&tag).copied().map(i64::from),
            NodeMap::Identity => i64::try_from(tag).ok(),
        }
    }
}

impl Reader<'_> {
    pub(super) fn nodes_section(&mut self, name: &str) -> Result<(), ParseError> {
        if self.nodes.is_some() {
            return Err(self.c.error(format!("second ${name} section")));
        }
        let f = self.format();
        let mut tags: Vec<u64> = Vec::new();
        match (f.version, f.binary) {
            (Version::V1 | Version::V2, false) => self.nodes_v2_ascii(&mut tags)?,
            (Version::V2, true) => self.nodes_v2_binary(&mut tags)?,
            (Version::V40 | Version::V41, false) => self.nodes_v4_ascii(&mut tags, f.version)?,
            (_, true) => self.nodes_v41_binary(&mut tags)?,
        }
        self.nodes = Some(match &mut self.keep {
            Some(keep) => {
                keep.node_tags = tags;
                NodeMap::Identity
            }
            None => NodeMap::build(&tags, &self.mesh.point_locations)?,
        });
        self.expect_end(name)
    }

    pub(super) fn push_point(&mut self, p: [f64; 3], loc: Location) {
        self.mesh.points.push(p);
        self.mesh.point_locations.push(loc);
    }

    pub(super) fn reserve_points(&mut self, n: usize) {
        self.mesh.points.reserve(n);
        self.mesh.point_locations.reserve(n);
    }

    pub(super) fn nodes_v2_ascii(&mut self, tags: &mut Vec<u64>) -> Result<(), ParseError> {
        let n = self.c.parse_or::<u64>(|| "number of nodes".into())?;
        let remaining = self.c.data().len() - self.c.pos();
        let cap = capped(n, remaining, 8);
        tags.reserve(cap);
        self.reserve_points(cap);
        for i in 0..n {
            let c = &mut self.c;
            let tag = c.parse_or::<u64>(|| format!("tag of node {} of {n}", i + 1))?;
            let loc = c.location();
            let mut p = [0.0; 3];
            for (k, x) in p.iter_mut().enumerate() {
                *x = c.f64_or(|| format!("{} coordinate of node {tag}", ["x", "y", "z"][k]))?;
            }
            tags.push(tag);
            self.push_point(p, loc);
        }
        Ok(())
    }

    pub(super) fn nodes_v2_binary(&mut self, tags: &mut Vec<u64>) -> Result<(), ParseError> {
        let n = self.c.parse_or::<u64>(|| "number of nodes".into())?;
        self.c.skip_line();
        let mut b = self.bin();
        let start = b.pos;
        let len = b.room(n, 28, "nodes")?;
        let data = b.take(len, &|| "node records".into())?;
        tags.reserve(n as usize);
        self.reserve_points(n as usize);
        for (i, r) in data.chunks_exact(28).enumerate() {
            let at = start + 28 * i;
            let tag = b.dec_i32(r);
            if tag < 0 {
                return Err(ParseError::at_byte(at, format!("negative node tag {tag}")));
            }
            tags.push(tag as u64);
            let p = [b.dec_f64(&r[4..]), b.dec_f64(&r[12..]), b.dec_f64(&r[20..])];
            self.push_point(p, Location::Byte(at));
        }
        self.c.seek_forward(b.pos);
        Ok(())
    }

    pub(super) fn nodes_v4_ascii(
        &mut self,
        tags: &mut Vec<u64>,
        version: Version,
    ) -> Result<(), ParseError> {
        let c = &mut self.c;
        let blocks = c.parse_or::<u64>(|| "number of node entity blocks".into())?;
        let total = c.parse_or::<u64>(|| "number of nodes".into())?;
        if version == Version::V41 {
            c.parse_or::<u64>(|| "minimum node tag".into())?;
            c.parse_or::<u64>(|| "maximum node tag".into())?;
        }
        let remaining = c.data().len() - c.pos();
        let cap = capped(total, remaining, 8);
        tags.reserve(cap);
        self.reserve_points(cap);
        for blk in 0..blocks {
            let c = &mut self.c;
            let what = |s: &'static str| move || format!("{s} of node block {}", blk + 1);
            let (dim, parametric, count);
            if version == Version::V41 {
                dim = c.parse_or::<i64>(what("entity dimension"))?;
                c.parse_or::<i64>(what("entity tag"))?;
            } else {
                c.parse_or::<i64>(what("entity tag"))?;
                dim = c.parse_or::<i64>(what("entity dimension"))?;
            }
            parametric = c.parse_or::<i64>(what("parametric flag"))?;
            count = c.parse_or::<u64>(what("number of nodes"))?;
            if !(0..=3).contains(&dim) {
                return Err(c.error(format!("entity dimension {dim} is not 0, 1, 2 or 3")));
            }
            let nparam = if parametric != 0 { dim as usize } else { 0 };
            let first = tags.len();
            if version == Version::V41 {
                for i in 0..count {
                    let t = c.parse_or::<u64>(|| {
                        format!("node tag {} of {count} in node block {}", i + 1, blk + 1)
                    })?;
                    tags.push(t);
                }
            }
            for i in 0..count {
                let c = &mut self.c;
                let tag = if version == Version::V41 {
                    tags[first + i as usize]
                } else {
                    let t = c.parse_or::<u64>(|| {
                        format!("node tag {} of {count} in node block {}", i + 1, blk + 1)
                    })?;
                    tags.push(t);
                    t
                };
                let mut p = [0.0; 3];
                let mut loc = Location::File;
                for (k, x) in p.iter_mut().enumerate() {
                    *x = c.f64_or(|| format!("{} coordinate of node {tag}", ["x", "y", "z"][k]))?;
                    if k == 0 {
                        loc = c.location();
                    }
                }
                for _ in 0..nparam {
                    c.f64_or(|| format!("parametric coordinate of node {tag}"))?;
                }
                self.push_point(p, loc);
            }
        }
        if tags.len() as u64 != total {
            return Err(self.c.error(format!(
                "$Nodes declares {total} nodes but its blocks hold {}",
                tags.len()
            )));
        }
        Ok(())
    }

    pub(super) fn nodes_v41_binary(&mut self, tags: &mut Vec<u64>) -> Result<(), ParseError> {
        self.c.skip_line();
        let mut b = self.bin();
        let sz = b.size_t;
        let (blocks, total) = section_counts(&mut b, "node")?;
        let cap = capped(total, b.remaining(), sz + 24);
        tags.reserve(cap);
        self.reserve_points(cap);
        for blk in 0..blocks {
            let header = NodeBlockHeader::read(&mut b, blk)?;
            let (count, nval) = (header.count, header.stride());
            // Tags of the whole block first, then its coordinates.
            let tag_len = b.room(count, sz, "node tags")?;
            let tag_data = b.take(tag_len, &|| "node tags".into())?;
            tags.extend(tag_data.chunks_exact(sz).map(|t| b.dec_size(t)));
            let rec = 8 * nval;
            let coord_at = b.pos;
            let len = b.room(count, rec, "node coordinate records")?;
            let data = b.take(len, &|| "node coordinates".into())?;
            for (i, r) in data.chunks_exact(rec).enumerate() {
                let p = [b.dec_f64(r), b.dec_f64(&r[8..]), b.dec_f64(&r[16..])];
                self.push_point(p, Location::Byte(coord_at + i * rec));
            }
        }
        if tags.len() as u64 != total {
            return Err(ParseError::at_byte(
                b.pos,
                format!(
                    "$Nodes declares {total} nodes but its blocks hold {}",
                    tags.len()
                ),
            ));
        }
        self.c.seek_forward(b.pos);
        Ok(())
    }
}
