//! `$Elements` (MSH 2/4, ASCII and binary) and `$ELM` (MSH 1): cells, their nodes and tags.
//!
//! Input: the section body and the [`NodeMap`] of the `$Nodes` section before it. Output: one
//! [`RawBlock`](crate::mesh::raw::RawBlock) per element type in `Reader::blocks`, node tags mapped
//! to 0-based positions, each cell tagged with its physical group (MSH 1/2: the first integer
//! tag; MSH 4: the entity's physical tag). In the tag-keeping mode (MSH 4), cells keep the
//! file's node tags, and `Reader::keep` gets each cell's element tag and entity tag.
//! Invariant: an element naming a node tag `$Nodes` did not define is an error at that line
//! (byte offset in binary sections). [`ElementBlockHeader`] reads binary MSH 4.1 block headers
//! for this parser and for the streamed one ([`super::stream`]).

use super::binary::Bin;
use super::nodes::{NodeMap, section_counts};
use super::{Reader, Version, capped, to_i32};
use crate::mesh::raw::{Location, ParseError};

/// The header of a binary MSH 4.1 `$Elements` entity block (as many bytes as
/// [`super::nodes::NodeBlockHeader::len`]): entity dimension and tag, Gmsh element type,
/// element count. `count` records follow, each the element tag and its nodes' tags (`size_t`).
pub(super) struct ElementBlockHeader {
    pub(super) dim: i32,
    pub(super) entity: i32,
    pub(super) gmsh_type: i32,
    pub(super) count: u64,
}

impl ElementBlockHeader {
    /// Read the header of element block `blk` (0-based).
    pub(super) fn read(b: &mut Bin, blk: u64) -> Result<Self, ParseError> {
        let what = || format!("header of element block {}", blk + 1);
        Ok(ElementBlockHeader {
            dim: b.i32(&what)?,
            entity: b.i32(&what)?,
            gmsh_type: b.i32(&what)?,
            count: b.size(&what)?,
        })
    }
}

impl Reader<'_> {
    /// Remember the physical tag of the first element of elementary entity `entity` of the
    /// dimension of block `bi` (MSH 1/2 `$Periodic` names elementary entities).
    fn record_v2_entity(&mut self, bi: usize, entity: i32, physical: i32) {
        let dim = self.blocks.list[bi].1.kind().dim().map_or(-1, |d| d as i32);
        self.v2_entities.entry((dim, entity)).or_insert(physical);
    }

    pub(super) fn elements_section(&mut self, name: &str, line: usize) -> Result<(), ParseError> {
        let Some(nodes) = self.nodes.take() else {
            return Err(ParseError::at_line(
                line,
                format!("${name} section before the $Nodes section"),
            ));
        };
        let f = self.format();
        let r = match (f.version, f.binary) {
            (Version::V1 | Version::V2, false) => self.elements_v2_ascii(&nodes, f.version),
            (Version::V2, true) => self.elements_v2_binary(&nodes),
            (Version::V40 | Version::V41, false) => self.elements_v4_ascii(&nodes, f.version),
            (_, true) => self.elements_v41_binary(&nodes),
        };
        self.nodes = Some(nodes);
        r?;
        self.expect_end(name)
    }

    pub(super) fn elements_v2_ascii(
        &mut self,
        nodes: &NodeMap,
        version: Version,
    ) -> Result<(), ParseError> {
        let n = self.c.parse_or::<u64>(|| "number of elements".into())?;
        for i in 0..n {
            let c = &mut self.c;
            let id = c.parse_or::<u64>(|| format!("number of element {} of {n}", i + 1))?;
            let loc = c.location();
            let ty = c.parse_or::<i64>(|| format!("type of element {id}"))?;
            let bi = self.blocks.index(ty, loc)?;
            let npe = self.blocks.list[bi].1.nodes_per_cell;
            let physical;
            if version == Version::V1 {
                let p = c.parse_or::<i64>(|| format!("physical region of element {id}"))?;
                physical = to_i32(p, c, "physical tag")?;
                c.parse_or::<i64>(|| format!("elementary region of element {id}"))?;
                let nn = c.parse_or::<u64>(|| format!("node count of element {id}"))?;
                if nn != npe as u64 {
                    return Err(c.error(format!(
                        "element {id} of Gmsh type {ty} has {npe} nodes, but the file says {nn}"
                    )));
                }
            } else {
                let ntags = c.parse_or::<u64>(|| format!("number of tags of element {id}"))?;
                let mut first = 0;
                let mut elementary = None;
                for j in 0..ntags {
                    let t = c.parse_or::<i64>(|| format!("tag {} of element {id}", j + 1))?;
                    if j == 0 {
                        first = to_i32(t, c, "physical tag")?;
                    } else if j == 1 {
                        elementary = i32::try_from(t).ok();
                    }
                }
                physical = first;
                if let Some(e) = elementary {
                    self.record_v2_entity(bi, e, physical);
                }
            }
            let c = &mut self.c;
            let block = &mut self.blocks.list[bi].1;
            for k in 0..npe {
                let t = c.parse_or::<u64>(|| format!("node {} of {npe} of element {id}", k + 1))?;
                let Some(v) = nodes.get(t) else {
                    return Err(c.error(format!(
                        "element {id} refers to node {t}, which $Nodes does not define"
                    )));
                };
                block.nodes.push(v);
            }
            block.tags.push(physical);
            block.locations.push(loc);
        }
        Ok(())
    }

    pub(super) fn elements_v2_binary(&mut self, nodes: &NodeMap) -> Result<(), ParseError> {
        let n = self.c.parse_or::<u64>(|| "number of elements".into())?;
        self.c.skip_line();
        let mut b = self.bin();
        let mut read = 0u64;
        while read < n {
            let header_at = b.pos;
            let what = || format!("element block header after {read} of {n} elements");
            let ty = b.i32(&what)?;
            let count = b.i32(&what)?;
            let ntags = b.i32(&what)?;
            if count < 0 || ntags < 0 {
                return Err(ParseError::at_byte(
                    header_at,
                    format!(
                        "element block header has a negative count ({count} elements, {ntags} tags)"
                    ),
                ));
            }
            if count as u64 > n - read {
                return Err(ParseError::at_byte(
                    header_at,
                    format!(
                        "element block of {count} elements exceeds the {} elements left of the {n} declared",
                        n - read
                    ),
                ));
            }
            let bi = self
                .blocks
                .index(i64::from(ty), Location::Byte(header_at))?;
            let block = &mut self.blocks.list[bi].1;
            let block_dim = block.kind().dim().map_or(-1, |d| d as i32);
            let npe = block.nodes_per_cell;
            let ntags = ntags as usize;
            let rec = 4 * (1 + ntags + npe);
            let start = b.pos;
            let len = b.room(count as u64, rec, "element records")?;
            let data = b.take(len, &|| "element records".into())?;
            block.nodes.reserve(count as usize * npe);
            for (e, r) in data.chunks_exact(rec).enumerate() {
                let at = start + e * rec;
                let physical = if ntags > 0 { b.dec_i32(&r[4..]) } else { 0 };
                if ntags > 1 {
                    self.v2_entities
                        .entry((block_dim, b.dec_i32(&r[8..])))
                        .or_insert(physical);
                }
                for node in r[4 * (1 + ntags)..].chunks_exact(4) {
                    let t = b.dec_i32(node);
                    let Some(v) = u64::try_from(t).ok().and_then(|t| nodes.get(t)) else {
                        return Err(ParseError::at_byte(
                            at,
                            format!(
                                "element {} refers to node {t}, which $Nodes does not define",
                                b.dec_i32(r)
                            ),
                        ));
                    };
                    block.nodes.push(v);
                }
                block.tags.push(physical);
                block.locations.push(Location::Byte(at));
            }
            read += count as u64;
        }
        self.c.seek_forward(b.pos);
        Ok(())
    }

    pub(super) fn elements_v4_ascii(
        &mut self,
        nodes: &NodeMap,
        version: Version,
    ) -> Result<(), ParseError> {
        let c = &mut self.c;
        let blocks = c.parse_or::<u64>(|| "number of element entity blocks".into())?;
        let total = c.parse_or::<u64>(|| "number of elements".into())?;
        if version == Version::V41 {
            c.parse_or::<u64>(|| "minimum element tag".into())?;
            c.parse_or::<u64>(|| "maximum element tag".into())?;
        }
        let mut read = 0u64;
        for blk in 0..blocks {
            let c = &mut self.c;
            let what = |s: &'static str| move || format!("{s} of element block {}", blk + 1);
            let (dim, etag);
            if version == Version::V41 {
                dim = c.parse_or::<i64>(what("entity dimension"))?;
                etag = c.parse_or::<i64>(what("entity tag"))?;
            } else {
                etag = c.parse_or::<i64>(what("entity tag"))?;
                dim = c.parse_or::<i64>(what("entity dimension"))?;
            }
            let ty = c.parse_or::<i64>(what("element type"))?;
            let type_loc = c.location();
            let count = c.parse_or::<u64>(what("number of elements"))?;
            let physical = match (i32::try_from(dim), i32::try_from(etag)) {
                (Ok(d), Ok(t)) => self.entities.physical_of(d, t),
                _ => 0,
            };
            let bi = self.blocks.index(ty, type_loc)?;
            let block = &mut self.blocks.list[bi].1;
            let npe = block.nodes_per_cell;
            let mut kept = self.keep.as_mut().map(|k| k.cells(bi));
            let entity = i32::try_from(etag).unwrap_or(0);
            let c = &mut self.c;
            let remaining = c.data().len() - c.pos();
            block
                .nodes
                .reserve(capped(count, remaining, 2 * (npe + 1)).saturating_mul(npe));
            for i in 0..count {
                let id = c.parse_or::<u64>(|| {
                    format!(
                        "tag of element {} of {count} in element block {}",
                        i + 1,
                        blk + 1
                    )
                })?;
                let loc = c.location();
                if let Some(k) = kept.as_mut() {
                    k.push(id, entity);
                }
                for k in 0..npe {
                    let t =
                        c.parse_or::<u64>(|| format!("node {} of {npe} of element {id}", k + 1))?;
                    let Some(v) = nodes.get(t) else {
                        return Err(c.error(format!(
                            "element {id} refers to node {t}, which $Nodes does not define"
                        )));
                    };
                    block.nodes.push(v);
                }
                block.tags.push(physical);
                block.locations.push(loc);
            }
            read += count;
        }
        if read != total {
            return Err(self.c.error(format!(
                "$Elements declares {total} elements but its blocks hold {read}"
            )));
        }
        Ok(())
    }

    pub(super) fn elements_v41_binary(&mut self, nodes: &NodeMap) -> Result<(), ParseError> {
        self.c.skip_line();
        let mut b = self.bin();
        let sz = b.size_t;
        let (blocks, total) = section_counts(&mut b, "element")?;
        let mut read = 0u64;
        for blk in 0..blocks {
            let header_at = b.pos;
            let h = ElementBlockHeader::read(&mut b, blk)?;
            let count = h.count;
            let physical = self.entities.physical_of(h.dim, h.entity);
            let bi = self
                .blocks
                .index(i64::from(h.gmsh_type), Location::Byte(header_at))?;
            let mut kept = self.keep.as_mut().map(|k| k.cells(bi));
            let block = &mut self.blocks.list[bi].1;
            let npe = block.nodes_per_cell;
            let rec = sz * (1 + npe);
            let start = b.pos;
            let len = b.room(count, rec, "element records")?;
            let data = b.take(len, &|| "element records".into())?;
            block.nodes.reserve(count as usize * npe);
            for (e, r) in data.chunks_exact(rec).enumerate() {
                let at = start + e * rec;
                if let Some(k) = kept.as_mut() {
                    k.push(b.dec_size(r), h.entity);
                }
                for node in r[sz..].chunks_exact(sz) {
                    let t = b.dec_size(node);
                    let Some(v) = nodes.get(t) else {
                        return Err(ParseError::at_byte(
                            at,
                            format!(
                                "element {} refers to node {t}, which $Nodes does not define",
                                b.dec_size(r)
                            ),
                        ));
                    };
                    block.nodes.push(v);
                }
                block.tags.push(physical);
                block.locations.push(Location::Byte(at));
            }
            read += count;
        }
        if read != total {
            return Err(ParseError::at_byte(
                b.pos,
                format!("$Elements declares {total} elements but its blocks hold {read}"),
            ));
        }
        self.c.seek_forward(b.pos);
        Ok(())
    }
}
