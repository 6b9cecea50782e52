//! From the accumulated sections to the [`RawMesh`]: node ids mapped to positions, set
//! tags assigned, surfaces turned into boundary facets.
//!
//! Input: the [`Reader`] after the last line. Output: the mesh with one block per `*ELEMENT`
//! section, tags and tag names. Invariants: a node id defined twice, or an element naming an
//! undefined node, is an error at its line; tags are 1, 2, ... in order of first appearance of
//! the non-internal sets, then the surfaces.

use super::element_types::element_face;
use super::{ElementBlock, ElementSet, IdMap, Reader, Surface, SurfaceTarget};
use crate::mesh::raw::{Location, ParseError, RawBlock, RawMesh};
use std::collections::BTreeMap;

impl Reader {
    /// Map ids, assign tags and build the mesh. Errors come in this order: an unread
    /// `*INCLUDE` when there are no elements, duplicate node ids, duplicate element ids,
    /// surface faces, undefined nodes of elements.
    pub(super) fn finish(self) -> Result<RawMesh, ParseError> {
        let Reader {
            node_ids,
            points,
            point_lines,
            blocks,
            sets,
            surfaces,
            includes,
            ..
        } = self;
        if blocks.iter().all(|b| b.ids.is_empty())
            && let Some((line, file)) = includes.first()
        {
            return Err(ParseError::at_line(
                *line,
                format!(
                    "the file defines no elements and includes \"{file}\", which is not read; merge the included file into this one"
                ),
            ));
        }
        let node_map = IdMap::build(&node_ids).map_err(|i| {
            ParseError::at_line(
                point_lines[i],
                format!("node id {} is defined twice", node_ids[i]),
            )
        })?;
        let (elem_ids, elem_map) = element_map(&blocks)?;
        let SetTags {
            mut tag_names,
            elem_tags,
            next_tag,
        } = set_tags(&sets, &elem_map, elem_ids.len());
        let mut mesh = RawMesh {
            points,
            point_locations: point_lines.into_iter().map(Location::Line).collect(),
            ..Default::default()
        };
        let facet_blocks = Facets {
            blocks: &blocks,
            sets: &sets,
            elem_map: &elem_map,
            node_map: &node_map,
            n_elems: elem_ids.len(),
        }
        .build(&surfaces, next_tag, &mut tag_names)?;
        let mut first = 0;
        for b in blocks {
            let n = b.ids.len();
            let npc = b.npc.unwrap_or(0);
            let mut rb = RawBlock::new(b.kind.clone(), npc);
            rb.nodes.reserve(b.nodes.len());
            for (c, cell) in b.nodes.chunks(npc.max(1)).enumerate() {
                for &id in cell {
                    rb.nodes
                        .push(translate(&node_map, id, b.lines[c], b.ids[c])?);
                }
            }
            if !elem_tags.is_empty() {
                rb.tags = elem_tags[first..first + n].to_vec();
            }
            rb.locations = b.lines.into_iter().map(Location::Line).collect();
            first += n;
            mesh.push_block(rb);
        }
        for fb in facet_blocks {
            mesh.push_block(fb);
        }
        mesh.tag_names = tag_names;
        Ok(mesh)
    }
}

/// Node id `id` of element `elem` (written at line `ln`) → 0-based node position.
fn translate(node_map: &IdMap, id: i64, ln: usize, elem: i64) -> Result<i64, ParseError> {
    node_map.get(id).map(|v| v as i64).ok_or_else(|| {
        ParseError::at_line(
            ln,
            format!("element {elem} refers to node {id}, which no *NODE line defines"),
        )
    })
}

/// Element ids in block order and their map to global element positions; an id defined
/// twice is an error at its second line.
fn element_map(blocks: &[ElementBlock]) -> Result<(Vec<i64>, IdMap), ParseError> {
    let elem_ids: Vec<i64> = blocks.iter().flat_map(|b| b.ids.iter().copied()).collect();
    let elem_map = IdMap::build(&elem_ids).map_err(|i| {
        let mut k = i;
        let mut line = 0;
        for b in blocks {
            if k < b.ids.len() {
                line = b.lines[k];
                break;
            }
            k -= b.ids.len();
        }
        ParseError::at_line(line, format!("element id {} is defined twice", elem_ids[i]))
    })?;
    Ok((elem_ids, elem_map))
}

/// Tags of the element sets.
struct SetTags {
    tag_names: BTreeMap<i32, String>,
    /// Per global element (empty when the file has no sets): the tag of the first
    /// non-internal set that contains it, 0 if none.
    elem_tags: Vec<i32>,
    /// The first tag not used by a set (surfaces follow).
    next_tag: i32,
}

/// Tags 1, 2, ... for the non-internal element sets, in order of first appearance.
fn set_tags(sets: &[ElementSet], elem_map: &IdMap, n_elems: usize) -> SetTags {
    let mut tag_names = BTreeMap::new();
    let mut elem_tags = vec![0i32; if sets.is_empty() { 0 } else { n_elems }];
    let mut next_tag = 1i32;
    for set in sets {
        if set.internal {
            continue;
        }
        tag_names.insert(next_tag, set.name.clone());
        for &id in &set.members {
            if let Some(e) = elem_map.get(id)
                && elem_tags[e] == 0
            {
                elem_tags[e] = next_tag;
            }
        }
        next_tag += 1;
    }
    SetTags {
        tag_names,
        elem_tags,
        next_tag,
    }
}

/// What the surfaces' faces are looked up in.
struct Facets<'r> {
    blocks: &'r [ElementBlock],
    sets: &'r [ElementSet],
    elem_map: &'r IdMap,
    node_map: &'r IdMap,
    n_elems: usize,
}

impl Facets<'_> {
    /// The surfaces' faces as facet blocks grouped by facet kind, each surface tagged
    /// `first_tag`, `first_tag + 1`, ... and named in `tag_names`.
    fn build(
        &self,
        surfaces: &[Surface],
        first_tag: i32,
        tag_names: &mut BTreeMap<i32, String>,
    ) -> Result<Vec<RawBlock>, ParseError> {
        // Per-element (block, cell) lookup.
        let mut owner: Vec<(u32, u32)> = Vec::with_capacity(self.n_elems);
        for (bi, b) in self.blocks.iter().enumerate() {
            owner.extend((0..b.ids.len()).map(|c| (bi as u32, c as u32)));
        }
        let mut facet_blocks: Vec<RawBlock> = Vec::new();
        for (tag, surface) in (first_tag..).zip(surfaces) {
            tag_names.insert(tag, surface.name.clone());
            for (ln, target, face) in &surface.faces {
                let members: &[i64] = match target {
                    SurfaceTarget::Set(s) => &self.sets[*s].members,
                    SurfaceTarget::Element(id) => std::slice::from_ref(id),
                };
                for &id in members {
                    let Some(e) = self.elem_map.get(id) else {
                        if matches!(target, SurfaceTarget::Element(_)) {
                            return Err(ParseError::at_line(
                                *ln,
                                format!(
                                    "surface {} refers to element {id}, which is not defined",
                                    surface.name
                                ),
                            ));
                        }
                        continue;
                    };
                    let (bi, c) = owner[e];
                    let b = &self.blocks[bi as usize];
                    let npc = b.npc.unwrap_or(0);
                    let Some((fkind, local)) = element_face(&b.kind, *face) else {
                        return Err(ParseError::at_line(
                            *ln,
                            format!(
                                "surface {}: element {id} of type {} has no face S{face}",
                                surface.name, b.type_name
                            ),
                        ));
                    };
                    let cell = &b.nodes[c as usize * npc..(c as usize + 1) * npc];
                    let fb = match facet_blocks.iter_mut().position(|fb| fb.kind() == &fkind) {
                        Some(i) => &mut facet_blocks[i],
                        None => {
                            facet_blocks.push(RawBlock::new(fkind.clone(), local.len()));
                            facet_blocks.last_mut().expect("just pushed")
                        }
                    };
                    for &l in local {
                        fb.nodes
                            .push(translate(self.node_map, cell[l], b.lines[c as usize], id)?);
                    }
                    fb.tags.push(tag);
                    fb.locations.push(Location::Line(*ln));
                }
            }
        }
        Ok(facet_blocks)
    }
}
