//! Data lines of the sections the reader keeps: `*NODE`, `*ELEMENT`, `*ELSET` and
//! `*SURFACE`.
//!
//! Input: one data line and its number. Output: nodes, element records (continued over lines
//! ending with a comma), set members and surface faces accumulated in the [`Reader`]; ids stay
//! as written until [`Reader::finish`] maps them. Invariant: a malformed field is an error naming
//! the line and the field.

use super::lines::{Lines, parse_float, parse_int, show};
use super::{ElementSet, Reader, SurfaceTarget};
use crate::mesh::raw::ParseError;

impl Reader {
    pub(super) fn set_named(&mut self, name: &str, internal: bool) -> usize {
        let key = name.to_ascii_lowercase();
        if let Some(&i) = self.set_index.get(&key) {
            return i;
        }
        self.sets.push(ElementSet {
            name: name.to_string(),
            internal,
            members: Vec::new(),
        });
        self.set_index.insert(key, self.sets.len() - 1);
        self.sets.len() - 1
    }

    pub(super) fn node_line(&mut self, ln: usize, line: &[u8]) -> Result<(), ParseError> {
        let mut fields = line.split(|&b| b == b',').map(|f| f.trim_ascii());
        let id_field = fields.next().unwrap_or_default();
        let id = parse_int(id_field).ok_or_else(|| {
            ParseError::at_line(
                ln,
                format!("expected node id, found \"{}\"", show(id_field)),
            )
        })?;
        let mut p = [0.0; 3];
        for (k, c) in p.iter_mut().enumerate() {
            match fields.next() {
                None => break,
                Some([]) => {}
                Some(f) => {
                    *c = parse_float(f).ok_or_else(|| {
                        ParseError::at_line(
                            ln,
                            format!(
                                "expected {} coordinate of node {id}, found \"{}\"",
                                ["x", "y", "z"][k],
                                show(f)
                            ),
                        )
                    })?;
                }
            }
        }
        self.node_ids.push(id);
        self.points.push(p);
        self.point_lines.push(ln);
        Ok(())
    }

    pub(super) fn element_record(
        &mut self,
        b: usize,
        ln: usize,
        line: &[u8],
        lines: &mut Lines,
    ) -> Result<(), ParseError> {
        let block = &mut self.blocks[b];
        let start = block.nodes.len();
        let mut id: Option<i64> = None;
        let mut line = line;
        let mut cur_line = ln;
        loop {
            let trimmed = line.trim_ascii();
            let continues = trimmed.ends_with(b",");
            for f in trimmed.split(|&c| c == b',').map(|f| f.trim_ascii()) {
                if f.is_empty() {
                    continue;
                }
                let v = parse_int(f).ok_or_else(|| {
                    let what = if id.is_none() {
                        "element id".to_string()
                    } else {
                        format!("node id of element {}", id.unwrap_or(0))
                    };
                    ParseError::at_line(cur_line, format!("expected {what}, found \"{}\"", show(f)))
                })?;
                if id.is_none() {
                    id = Some(v);
                    continue;
                }
                if block.npc == Some(block.nodes.len() - start) {
                    return Err(ParseError::at_line(
                        cur_line,
                        format!(
                            "element {} of type {} has more than {} node ids",
                            id.unwrap_or(0),
                            block.type_name,
                            block.nodes.len() - start
                        ),
                    ));
                }
                block.nodes.push(v);
            }
            let have = block.nodes.len() - start;
            let complete = match block.npc {
                Some(n) => have == n,
                None => !continues,
            };
            if complete && id.is_some() {
                break;
            }
            // The record goes on in the next line, which must be a data line.
            match lines.peek_content() {
                Some((_, next)) if !next.trim_ascii().starts_with(b"*") => {
                    while let Some((n, l)) = lines.next_line() {
                        let t = l.trim_ascii();
                        if t.is_empty() || t.starts_with(b"**") {
                            continue;
                        }
                        cur_line = n;
                        line = l;
                        break;
                    }
                }
                _ => {
                    return Err(ParseError::at_line(
                        cur_line,
                        match (id, block.npc) {
                            (Some(id), Some(n)) => format!(
                                "element {id} of type {} needs {n} node ids, found {have} before the end of the section",
                                block.type_name
                            ),
                            (Some(id), None) => format!(
                                "element {id}: the line ends with a comma but no data line follows"
                            ),
                            (None, _) => "expected an element id".to_string(),
                        },
                    ));
                }
            }
        }
        let have = block.nodes.len() - start;
        match block.npc {
            None if have == 0 => {
                return Err(ParseError::at_line(
                    cur_line,
                    format!("element {} has no node ids", id.unwrap_or(0)),
                ));
            }
            None => block.npc = Some(have),
            Some(_) => {}
        }
        if block.npc != Some(have) {
            return Err(ParseError::at_line(
                cur_line,
                format!(
                    "element {} of type {} has {have} node ids, the first element of this section has {}",
                    id.unwrap_or(0),
                    block.type_name,
                    block.npc.unwrap_or(0)
                ),
            ));
        }
        let id = id.unwrap_or(0);
        block.ids.push(id);
        block.lines.push(ln);
        if let Some(s) = block.elset {
            self.sets[s].members.push(id);
        }
        Ok(())
    }

    pub(super) fn elset_line(
        &mut self,
        set: usize,
        generate: bool,
        ln: usize,
        line: &[u8],
    ) -> Result<(), ParseError> {
        let fields: Vec<&[u8]> = line
            .split(|&b| b == b',')
            .map(|f| f.trim_ascii())
            .filter(|f| !f.is_empty())
            .collect();
        if generate {
            let nums: Vec<i64> = fields
                .iter()
                .map(|f| {
                    parse_int(f).ok_or_else(|| {
                        ParseError::at_line(
                            ln,
                            format!(
                                "expected an element id of a GENERATE range, found \"{}\"",
                                show(f)
                            ),
                        )
                    })
                })
                .collect::<Result<_, _>>()?;
            let (first, last, step) = match nums[..] {
                [a, b] => (a, b, 1),
                [a, b, s] => (a, b, s),
                _ => {
                    return Err(ParseError::at_line(
                        ln,
                        format!(
                            "expected \"first, last[, increment]\", found {} values",
                            nums.len()
                        ),
                    ));
                }
            };
            if step <= 0 || last < first {
                return Err(ParseError::at_line(
                    ln,
                    format!("invalid GENERATE range {first}, {last}, {step}"),
                ));
            }
            // Members of a range that names no element are dropped later, so bound the range
            // by what the file can hold.
            let count = (last - first) / step + 1;
            if count > 8 * (self.blocks.iter().map(|b| b.ids.len()).sum::<usize>() as i64) + 1024 {
                return Err(ParseError::at_line(
                    ln,
                    format!(
                        "GENERATE range {first}..{last} is far larger than the number of elements"
                    ),
                ));
            }
            let members = &mut self.sets[set].members;
            let mut v = first;
            while v <= last {
                members.push(v);
                v += step;
            }
            return Ok(());
        }
        for f in fields {
            if let Some(v) = parse_int(f) {
                self.sets[set].members.push(v);
                continue;
            }
            let name = String::from_utf8_lossy(f).to_ascii_lowercase();
            match self.set_index.get(&name) {
                Some(&other) if other != set => {
                    let m = self.sets[other].members.clone();
                    self.sets[set].members.extend(m);
                }
                _ => {
                    return Err(ParseError::at_line(
                        ln,
                        format!(
                            "expected an element id or the name of an element set, found \"{}\"",
                            show(f)
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    pub(super) fn surface_line(
        &mut self,
        surface: usize,
        instances: &[String],
        ln: usize,
        line: &[u8],
    ) -> Result<(), ParseError> {
        let mut fields = line.split(|&b| b == b',').map(|f| f.trim_ascii());
        let target = fields.next().unwrap_or_default();
        let label = fields.next().unwrap_or_default();
        let face = match label {
            [b'S' | b's', rest @ ..] => match parse_int(rest) {
                Some(n) if n > 0 => n as usize,
                // SPOS / SNEG (shell sides) and the like.
                _ => return Ok(()),
            },
            // No label (free faces of a set) or edge labels: not read.
            _ => return Ok(()),
        };
        let target = if let Some(id) = parse_int(target) {
            SurfaceTarget::Element(id)
        } else {
            let mut name = String::from_utf8_lossy(target)
                .trim_matches('"')
                .to_ascii_lowercase();
            if let Some((inst, rest)) = name.split_once('.')
                && instances.iter().any(|i| i == inst)
            {
                name = rest.to_string();
            }
            match self.set_index.get(&name) {
                Some(&s) => SurfaceTarget::Set(s),
                None => {
                    return Err(ParseError::at_line(
                        ln,
                        format!(
                            "surface {} refers to element set \"{}\", which is not defined before it",
                            self.surfaces[surface].name,
                            show(target)
                        ),
                    ));
                }
            }
        };
        self.surfaces[surface].faces.push((ln, target, face));
        Ok(())
    }
}
