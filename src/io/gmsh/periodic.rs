//! `$Periodic` (MSH 2.x and 4.0 ASCII, MSH 4.1 ASCII and binary): the periodic entity pairs.
//!
//! Input: the section body, after `$Nodes`. Per link: the dimension, the image entity, its
//! master entity, the affine map master → image (MSH 4.1: a count, 0 or 16, then the values;
//! MSH 2/4.0: an optional `Affine` line of 16 values) and the node pairs. MSH 2 files keep the
//! section in ASCII even when the rest is binary (Gmsh writes it so).
//!
//! Output: one [`Link`] per link in `Reader::periodic`; once every section is read,
//! [`Reader::declared_periodic`] turns the entity tags into the physical tags the cells carry
//! (MSH 4: the entities' physical tags; MSH 1/2: the physical tag of the first element of each
//! elementary entity). Node pairs are checked (both tags defined by `$Nodes`) and not kept:
//! the pairing is found again from the positions when the pair is used.
//!
//! Invariant: a count no larger than what the rest of the input can hold is trusted; a node tag
//! `$Nodes` does not define, a truncated link or an affine map of other than 16 values is an
//! error at its line (byte offset in binary sections).

use super::binary::Bin;
use super::{Reader, Version, parse_f64, to_i32};
use crate::mesh::raw::{DeclaredPeriodic, Location, ParseError};

/// One link of `$Periodic`, in the file's entity tags.
#[derive(Clone, Debug)]
pub(super) struct Link {
    dim: i32,
    slave: i32,
    master: i32,
    affine: Option<[f64; 16]>,
    location: Location,
}

/// Values of an affine map.
const AFFINE: usize = 16;

/// A node pair naming node `tag`, which `$Nodes` does not define, at `at`.
pub(super) fn undefined_node(tag: u64, at: Location) -> ParseError {
    ParseError::new(
        at,
        format!("periodic node pair names node {tag}, which $Nodes does not define"),
    )
}

/// The body of a binary MSH 4.1 `$Periodic` section read by offsets (`stream`): `data`, the
/// bytes after its `$Periodic` line, at file offset `at`, in a file of `format` whose header
/// is `header`. Parsed by the in-memory reader's own code; returns the links in physical tags
/// ([`Reader::declared_periodic`]) and every node tag of the node pairs with its place, which
/// the caller checks against `$Nodes` (it does not hold them).
#[allow(clippy::type_complexity)]
pub(super) fn stream_section(
    header: &super::HeaderTags,
    format: super::Format,
    data: &[u8],
    at: u64,
) -> Result<(Vec<DeclaredPeriodic>, Vec<(u64, Location)>), ParseError> {
    let mut r = Reader::new(data);
    r.format = Some(format);
    r.entities = header.entities.clone();
    r.unchecked_nodes = Some(Vec::new());
    let mut b = Bin {
        data,
        pos: 0,
        base: at as usize,
        big_endian: format.big_endian,
        size_t: format.size_t,
    };
    r.periodic_binary(&mut b)?;
    let nodes = r.unchecked_nodes.take().unwrap_or_default();
    Ok((r.declared_periodic(), nodes))
}

impl Reader<'_> {
    /// `$Periodic`: read the links into `self.periodic`.
    pub(super) fn periodic_section(&mut self, line: usize) -> Result<(), ParseError> {
        if self.nodes.is_none() {
            return Err(ParseError::at_line(
                line,
                "$Periodic section before the $Nodes section",
            ));
        }
        let f = self.format();
        if f.binary && f.version == Version::V41 {
            self.c.skip_line();
            let mut b = self.bin();
            self.periodic_binary(&mut b)?;
            self.c.seek_forward(b.pos);
        } else {
            self.periodic_ascii(f.version)?;
        }
        self.expect_end("Periodic")
    }

    fn periodic_ascii(&mut self, version: Version) -> Result<(), ParseError> {
        let n = self
            .c
            .parse_or::<u64>(|| "number of periodic links".into())?;
        for i in 0..n {
            let what = |s: &str| format!("{s} of periodic link {} of {n}", i + 1);
            let c = &mut self.c;
            let location = c.location();
            let dim = c.parse_or::<i64>(|| what("dimension"))?;
            let dim = to_i32(dim, c, "periodic entity dimension")?;
            let slave = c.parse_or::<i64>(|| what("entity tag"))?;
            let slave = to_i32(slave, c, "periodic entity tag")?;
            let master = c.parse_or::<i64>(|| what("master entity tag"))?;
            let master = to_i32(master, c, "periodic master entity tag")?;
            let mut affine = None;
            let count;
            if version == Version::V41 {
                let values = c.parse_or::<u64>(|| what("number of affine values"))?;
                if values != 0 {
                    if values != AFFINE as u64 {
                        return Err(c.error(format!(
                            "periodic link {} has an affine map of {values} values, expected 16 or 0",
                            i + 1
                        )));
                    }
                    affine = Some(self.affine_ascii(&what)?);
                }
                count = self.c.parse_or::<u64>(|| what("number of node pairs"))?;
            } else {
                let tok = c.token_or(|| what("`Affine` or the number of node pairs"))?;
                if let Some(rest) = tok.strip_prefix("Affine") {
                    // The 16 values follow on the same line.
                    let line = c.next_line().unwrap_or("");
                    let values: Vec<&str> = rest
                        .split_whitespace()
                        .chain(line.split_whitespace())
                        .collect();
                    let parsed: Vec<Option<f64>> = values.iter().map(|v| parse_f64(v)).collect();
                    if let Some(j) = parsed.iter().position(Option::is_none) {
                        return Err(
                            c.expected(&what(&format!("affine value {} of 16", j + 1)), values[j])
                        );
                    }
                    if values.len() != AFFINE {
                        return Err(c.error(format!(
                            "the Affine line of periodic link {} has {} values, expected 16",
                            i + 1,
                            values.len()
                        )));
                    }
                    let mut a = [0.0; AFFINE];
                    for (v, p) in a.iter_mut().zip(parsed) {
                        *v = p.unwrap_or(0.0);
                    }
                    affine = Some(a);
                    count = self.c.parse_or::<u64>(|| what("number of node pairs"))?;
                } else {
                    count = tok
                        .parse::<u64>()
                        .map_err(|_| c.expected(&what("number of node pairs"), tok))?;
                }
            }
            // Every pair takes at least 4 bytes ("1 2\n").
            let remaining = self.c.data().len() - self.c.pos();
            if count > (remaining / 4) as u64 {
                return Err(self.c.error(format!(
                    "periodic link {} declares {count} node pairs, more than the {remaining} bytes left can hold",
                    i + 1
                )));
            }
            for k in 0..count {
                for side in ["node", "master node"] {
                    let t = self.c.parse_or::<u64>(|| {
                        what(&format!("{side} of node pair {} of {count}", k + 1))
                    })?;
                    self.periodic_node(t, || self.c.location())?;
                }
            }
            self.periodic.push(Link {
                dim,
                slave,
                master,
                affine,
                location,
            });
        }
        Ok(())
    }

    fn affine_ascii(&mut self, what: &dyn Fn(&str) -> String) -> Result<[f64; 16], ParseError> {
        let mut a = [0.0; AFFINE];
        for (j, v) in a.iter_mut().enumerate() {
            *v = self
                .c
                .f64_or(|| what(&format!("affine value {} of 16", j + 1)))?;
        }
        Ok(a)
    }

    fn periodic_binary(&mut self, b: &mut Bin) -> Result<(), ParseError> {
        let n = b.size(&|| "number of periodic links".into())?;
        for i in 0..n {
            let what = || format!("periodic link {} of {n}", i + 1);
            let at = b.at();
            let dim = b.i32(&what)?;
            let slave = b.i32(&what)?;
            let master = b.i32(&what)?;
            let values = b.size(&what)?;
            let affine = match values {
                0 => None,
                16 => {
                    let data = b.take(8 * AFFINE, &what)?;
                    let mut a = [0.0; AFFINE];
                    for (v, x) in a.iter_mut().zip(data.chunks_exact(8)) {
                        *v = b.dec_f64(x);
                    }
                    Some(a)
                }
                _ => {
                    return Err(ParseError::at_byte(
                        at,
                        format!(
                            "periodic link {} has an affine map of {values} values, expected 16 or 0",
                            i + 1
                        ),
                    ));
                }
            };
            let count = b.size(&what)?;
            let start = b.at();
            let sz = b.size_t;
            let len = b.room(count, 2 * sz, "periodic node pairs")?;
            let data = b.take(len, &|| "periodic node pairs".into())?;
            for (k, t) in data.chunks_exact(sz).enumerate() {
                let (tag, at) = (b.dec_size(t), Location::Byte(start + k * sz));
                match &mut self.unchecked_nodes {
                    Some(later) => later.push((tag, at)),
                    None => self.periodic_node(tag, || at)?,
                }
            }
            self.periodic.push(Link {
                dim,
                slave,
                master,
                affine,
                location: Location::Byte(at),
            });
        }
        Ok(())
    }

    /// A node tag of a periodic node pair must be one `$Nodes` defined.
    fn periodic_node(&self, tag: u64, at: impl Fn() -> Location) -> Result<(), ParseError> {
        let defined = self.nodes.as_ref().is_some_and(|m| m.get(tag).is_some());
        if defined {
            return Ok(());
        }
        Err(undefined_node(tag, at()))
    }

    /// The links read, in the physical tags the cells carry (0 where the entity has none).
    pub(super) fn declared_periodic(&self) -> Vec<DeclaredPeriodic> {
        let v4 = matches!(self.format().version, Version::V40 | Version::V41);
        let physical = |dim: i32, tag: i32| {
            if v4 {
                self.entities.physical_of(dim, tag)
            } else {
                self.v2_entities.get(&(dim, tag)).copied().unwrap_or(0)
            }
        };
        self.periodic
            .iter()
            .filter_map(|l| {
                Some(DeclaredPeriodic {
                    dim: usize::try_from(l.dim).ok()?,
                    sides: Some([physical(l.dim, l.master), physical(l.dim, l.slave)]),
                    source: format!("$Periodic link of entities {} -> {}", l.master, l.slave),
                    affine: l.affine,
                    precision: 0.0,
                    location: l.location,
                })
            })
            .collect()
    }
}
