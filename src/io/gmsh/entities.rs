//! `$Entities` and `$PartitionedEntities` (MSH 4): the physical tag of each entity.
//!
//! Input: the section body, ASCII or binary. Output: [`EntityTags`] (first physical tag of
//! each (dimension, entity tag), 0 when none, and the parent of each partitioned entity
//! without physical tags), read by [`EntityTags::physical_of`] when element blocks are tagged;
//! from `$PartitionedEntities` also the number of partitions and the ghost entities' tags (the
//! partitioned-input reader drops the cells of those entities: another part owns them).

use super::binary::Bin;
use super::{Reader, Version, to_i32};
use crate::mesh::raw::ParseError;
use std::collections::{HashMap, HashSet};

/// The physical tag of every entity of `$Entities` and `$PartitionedEntities`.
#[derive(Clone, Debug, Default)]
pub struct EntityTags {
    /// First physical tag (0 if none) of each (dimension, entity tag).
    physical: HashMap<(i32, i32), i32>,
    /// Parent (dimension, tag) of each partitioned entity that has no physical tag itself.
    parent: HashMap<(i32, i32), (i32, i32)>,
    /// The number of partitions of `$PartitionedEntities` (None without that section).
    partitions: Option<u64>,
    /// The tags of the ghost entities of `$PartitionedEntities`.
    ghosts: HashSet<i32>,
}

impl EntityTags {
    /// Physical tag of the elements of entity (dim, tag): its first physical tag, else its
    /// partition parent's, else 0.
    pub fn physical_of(&self, dim: i32, tag: i32) -> i32 {
        match self.physical.get(&(dim, tag)) {
            Some(&p) if p != 0 => p,
            _ => self
                .parent
                .get(&(dim, tag))
                .and_then(|parent| self.physical.get(parent))
                .copied()
                .unwrap_or(0),
        }
    }

    /// The number of partitions `$PartitionedEntities` declares; None without that section.
    pub(crate) fn partitions(&self) -> Option<u64> {
        self.partitions
    }

    /// Whether `tag` is one of the ghost entities `$PartitionedEntities` lists (Gmsh gives
    /// the ghost entities tags of their own, whatever their dimension).
    pub(crate) fn is_ghost(&self, tag: i32) -> bool {
        self.ghosts.contains(&tag)
    }
}

impl Reader<'_> {
    /// `$Entities` or `$PartitionedEntities`: remember the first physical tag of each entity.
    pub(super) fn entities(&mut self, partitioned: bool) -> Result<(), ParseError> {
        let f = self.format();
        if f.version != Version::V40 && f.version != Version::V41 {
            let name = if partitioned {
                "PartitionedEntities"
            } else {
                "Entities"
            };
            return self.skip_section(name, self.c.line());
        }
        if f.binary {
            self.c.skip_line();
            let mut b = self.bin();
            self.entities_binary(&mut b, partitioned)?;
            self.c.seek_forward(b.pos);
        } else {
            self.entities_ascii(partitioned, f.version)?;
        }
        self.expect_end(if partitioned {
            "PartitionedEntities"
        } else {
            "Entities"
        })
    }

    pub(super) fn record_entity(
        &mut self,
        dim: i32,
        tag: i32,
        first_phys: i32,
        parent: Option<(i32, i32)>,
    ) {
        self.entities.physical.insert((dim, tag), first_phys);
        // A partition entity inherits its parent's physical group only from a parent of the
        // same dimension (partition interfaces have the volume or surface as parent).
        if let Some(p) = parent
            && first_phys == 0
            && p.0 == dim
        {
            self.entities.parent.insert((dim, tag), p);
        }
    }

    pub(super) fn entities_ascii(
        &mut self,
        partitioned: bool,
        version: Version,
    ) -> Result<(), ParseError> {
        let c = &mut self.c;
        if partitioned {
            let parts = c.parse_or::<u64>(|| "number of partitions".into())?;
            let ghosts = c.parse_or::<u64>(|| "number of ghost entities".into())?;
            for _ in 0..ghosts {
                let tag = c.parse_or::<i64>(|| "ghost entity tag".into())?;
                let tag = to_i32(tag, c, "ghost entity tag")?;
                c.parse_or::<i64>(|| "ghost entity partition".into())?;
                self.entities.ghosts.insert(tag);
            }
            self.entities.partitions = Some(parts);
        }
        let mut counts = [0u64; 4];
        for (d, n) in counts.iter_mut().enumerate() {
            *n = self.c.parse_or::<u64>(|| {
                format!(
                    "number of {} entities",
                    ["point", "curve", "surface", "volume"][d]
                )
            })?;
        }
        for (dim, &count) in counts.iter().enumerate() {
            let dim = dim as i32;
            for k in 0..count {
                let c = &mut self.c;
                let what =
                    |s: &'static str| move || format!("{s} of entity {} of dimension {dim}", k + 1);
                let tag = c.parse_or::<i64>(what("tag"))?;
                let tag = to_i32(tag, c, "entity tag")?;
                let mut parent = None;
                if partitioned {
                    let pdim = c.parse_or::<i64>(what("parent dimension"))?;
                    let ptag = c.parse_or::<i64>(what("parent tag"))?;
                    parent = Some((
                        to_i32(pdim, c, "dimension")?,
                        to_i32(ptag, c, "entity tag")?,
                    ));
                    let np = c.parse_or::<u64>(what("number of partitions"))?;
                    for _ in 0..np {
                        c.parse_or::<i64>(what("partition"))?;
                    }
                }
                let nbox = if version == Version::V41 && dim == 0 {
                    3
                } else {
                    6
                };
                for _ in 0..nbox {
                    c.f64_or(what("bounding box coordinate"))?;
                }
                let nphys = c.parse_or::<u64>(what("number of physical tags"))?;
                let mut first = 0;
                for j in 0..nphys {
                    let p = c.parse_or::<i64>(what("physical tag"))?;
                    if j == 0 {
                        first = to_i32(p, c, "physical tag")?;
                    }
                }
                if dim > 0 {
                    let nb = c.parse_or::<u64>(what("number of bounding entities"))?;
                    for _ in 0..nb {
                        c.parse_or::<i64>(what("bounding entity tag"))?;
                    }
                }
                self.record_entity(dim, tag, first, parent);
            }
        }
        Ok(())
    }

    pub(super) fn entities_binary(
        &mut self,
        b: &mut Bin,
        partitioned: bool,
    ) -> Result<(), ParseError> {
        let sz = b.size_t;
        if partitioned {
            let parts = b.size(&|| "number of partitions".into())?;
            let ghosts = b.size(&|| "number of ghost entities".into())?;
            b.room(ghosts, 8, "ghost entities")?;
            for _ in 0..ghosts {
                let tag = b.i32(&|| "ghost entity tag".into())?;
                b.i32(&|| "ghost entity partition".into())?;
                self.entities.ghosts.insert(tag);
            }
            self.entities.partitions = Some(parts);
        }
        let mut counts = [0u64; 4];
        for n in counts.iter_mut() {
            *n = b.size(&|| "number of entities".into())?;
        }
        for (dim, &count) in counts.iter().enumerate() {
            let dim = dim as i32;
            // Every entity takes at least an int, a box and a count.
            b.room(count, 4 + 24 + sz, "entities")?;
            for k in 0..count {
                let what = || format!("entity {} of dimension {dim}", k + 1);
                let tag = b.i32(&what)?;
                let mut parent = None;
                if partitioned {
                    let pdim = b.i32(&what)?;
                    let ptag = b.i32(&what)?;
                    parent = Some((pdim, ptag));
                    let np = b.size(&what)?;
                    b.skip(np, 4, "partition tags")?;
                }
                b.take(if dim == 0 { 24 } else { 48 }, &what)?;
                let nphys = b.size(&what)?;
                b.room(nphys, 4, "physical tags")?;
                let mut first = 0;
                if nphys > 0 {
                    first = b.i32(&what)?;
                    b.skip(nphys - 1, 4, "physical tags")?;
                }
                if dim > 0 {
                    let nb = b.size(&what)?;
                    b.skip(nb, 4, "bounding entity tags")?;
                }
                self.record_entity(dim, tag, first, parent);
            }
        }
        Ok(())
    }
}
