//! The CGNS node tree of a CGNS file, in either container: HDF5 (read through `hdf5-pure`)
//! or ADF (read by [`super::adf`]).
//!
//! Input: the file's bytes. Output: [`Node`]s, each with a name, a `label` (the SIDS type,
//! `Zone_t`, ...), a data type (`MT`, `I4`, `I8`, `R4`, `R8`, `C1`, `LK`) and a value. In HDF5 a
//! node is a group with the attributes `name`, `label` and `type` and its value in the dataset
//! `" data"` (contiguous or chunked, deflated or not); in ADF a node header (the same fields)
//! and its data chunks. Both present the same tree. Every error names the node's path
//! (`/Base/Zone1/GridCoordinates`).
//!
//! Invariants:
//! * memory is bounded by the file's size: before a value is read its declared element count
//!   is checked against the bytes the file could hold for it (the file's size, or
//!   [`MAX_DEFLATE_RATIO`] times it for a filtered dataset), so a forged shape cannot allocate
//!   more than a constant times the input;
//! * a link node (`LK`: a node stored in another file) is refused, never followed.

use super::adf::{self, Adf};
use crate::mesh::raw::{Location, ParseError};
use hdf5_pure::{File, Group};

/// The deflate format's largest expansion (a 258-byte match in about two bits).
pub const MAX_DEFLATE_RATIO: usize = 1032;

/// How a CGNS file starts: HDF5 (the signature at offset 0, or after a user block at 512,
/// 1024, ...) or ADF.
pub fn container(data: &[u8]) -> Option<&'static str> {
    const HDF5: &[u8] = b"\x89HDF\r\n\x1a\n";
    if data.starts_with(HDF5) {
        return Some("hdf5");
    }
    let mut at = 512;
    while at + HDF5.len() <= data.len() && at <= 1 << 20 {
        if &data[at..at + HDF5.len()] == HDF5 {
            return Some("hdf5");
        }
        at *= 2;
    }
    // ADF files start with a 4-byte tag and "ADF Database Version".
    let head = &data[..data.len().min(64)];
    if head.windows(12).any(|w| w == b"ADF Database") {
        return Some("adf");
    }
    None
}

/// An error at a node: the node's path, then the problem.
pub fn error(path: &str, message: impl std::fmt::Display) -> ParseError {
    ParseError::new(Location::Tree, format!("{path}: {message}"))
}

/// An open CGNS file.
pub struct Tree {
    file: Container,
    len: usize,
}

/// The file's container.
enum Container {
    Hdf5(File),
    Adf(Adf),
}

/// Where a node lives in its container.
enum Handle {
    Hdf5(Group),
    Adf(adf::Header),
}

/// One node of the tree.
pub struct Node<'a> {
    tree: &'a Tree,
    handle: Handle,
    /// Path from the root, `/Base/Zone1` (the root itself is `/`).
    pub path: String,
    /// The node's name (the last component of its path).
    pub name: String,
}

impl Tree {
    /// Open the container (HDF5 or ADF) of a CGNS file.
    pub fn open(data: &[u8]) -> Result<Tree, ParseError> {
        let file = match container(data) {
            Some("hdf5") => Container::Hdf5(
                File::from_bytes(data.to_vec())
                    .map_err(|e| ParseError::new(Location::Byte(0), format!("HDF5: {e}")))?,
            ),
            Some(_) => Container::Adf(
                Adf::open(data.to_vec()).map_err(|e| ParseError::new(Location::Byte(0), e))?,
            ),
            None => {
                return Err(ParseError::new(
                    Location::Byte(0),
                    "not a CGNS file (neither an HDF5 nor an ADF header)",
                ));
            }
        };
        Ok(Tree {
            file,
            len: data.len(),
        })
    }

    /// The root node (`/`).
    pub fn root(&self) -> Result<Node<'_>, ParseError> {
        let handle = match &self.file {
            Container::Hdf5(f) => Handle::Hdf5(f.root()),
            Container::Adf(a) => Handle::Adf(a.root().map_err(|e| error("/", e))?),
        };
        Ok(Node {
            tree: self,
            handle,
            path: String::new(),
            name: String::new(),
        })
    }
}

impl<'a> Node<'a> {
    /// The path for messages (`/` for the root).
    pub fn at(&self) -> &str {
        if self.path.is_empty() {
            "/"
        } else {
            &self.path
        }
    }

    /// An error at this node.
    pub fn error(&self, message: impl std::fmt::Display) -> ParseError {
        error(self.at(), message)
    }

    /// The ADF file of an ADF node (`None` for HDF5).
    fn adf(&self) -> Option<(&'a Adf, &adf::Header)> {
        match (&self.tree.file, &self.handle) {
            (Container::Adf(a), Handle::Adf(h)) => Some((a, h)),
            _ => None,
        }
    }

    /// The HDF5 group of an HDF5 node.
    fn group(&self) -> Option<&Group> {
        match &self.handle {
            Handle::Hdf5(g) => Some(g),
            Handle::Adf(_) => None,
        }
    }

    fn attr(&self, group: &Group, key: &str) -> Result<String, ParseError> {
        let attrs = group
            .attrs()
            .map_err(|e| self.error(format!("unreadable attributes: {e}")))?;
        use hdf5_pure::AttrValue as A;
        Ok(match attrs.get(key) {
            Some(A::String(s)) | Some(A::AsciiString(s)) => s.clone(),
            Some(A::StringSized { value, .. }) | Some(A::AsciiStringSized { value, .. }) => {
                value.clone()
            }
            _ => String::new(),
        }
        .trim_end_matches(['\0', ' '])
        .to_string())
    }

    /// The SIDS label (`Zone_t`, ...), empty when missing.
    pub fn label(&self) -> Result<String, ParseError> {
        match &self.handle {
            Handle::Hdf5(g) => self.attr(g, "label"),
            Handle::Adf(h) => Ok(h.label.clone()),
        }
    }

    /// The data type (`MT`, `I4`, `I8`, `R4`, `R8`, `C1`, `LK`).
    pub fn data_type(&self) -> Result<String, ParseError> {
        match &self.handle {
            Handle::Hdf5(g) => self.attr(g, "type"),
            Handle::Adf(h) => Ok(h.data_type.clone()),
        }
    }

    /// The child nodes, sorted by name (neither container keeps an order the CGNS library
    /// relies on).
    pub fn children(&self) -> Result<Vec<Node<'a>>, ParseError> {
        if self.data_type()? == "LK" {
            return Err(self.error(
                "a link to a node in another file; links are not followed (expand them with `cgnsconvert -l IN OUT`)",
            ));
        }
        let handles: Vec<(String, Handle)> = match (&self.tree.file, &self.handle) {
            (Container::Adf(a), Handle::Adf(h)) => a
                .children(h)
                .map_err(|e| self.error(e))?
                .into_iter()
                .map(|c| (c.name.clone(), Handle::Adf(c)))
                .collect(),
            (_, Handle::Hdf5(g)) => g
                .iter_groups()
                .map_err(|e| self.error(format!("unreadable children: {e}")))?
                .map(|(name, group)| (name, Handle::Hdf5(group)))
                .collect(),
            _ => unreachable!("a node's handle matches its container"),
        };
        let mut out: Vec<Node<'a>> = handles
            .into_iter()
            .map(|(name, handle)| Node {
                tree: self.tree,
                handle,
                path: format!("{}/{name}", self.path),
                name,
            })
            .collect();
        out.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(out)
    }

    /// The children labelled `label`.
    pub fn labelled(&self, label: &str) -> Result<Vec<Node<'a>>, ParseError> {
        let mut out = Vec::new();
        for c in self.children()? {
            if c.label()? == label {
                out.push(c);
            }
        }
        Ok(out)
    }

    /// The child named `name`, if any.
    pub fn child(&self, name: &str) -> Result<Option<Node<'a>>, ParseError> {
        Ok(self.children()?.into_iter().find(|c| c.name == name))
    }

    /// The child named `name`, which must exist.
    pub fn require(&self, name: &str) -> Result<Node<'a>, ParseError> {
        self.child(name)?
            .ok_or_else(|| self.error(format!("no child node {name}")))
    }

    /// The `" data"` dataset and its shape, after the memory check (module docs).
    fn dataset(&self) -> Result<Option<(hdf5_pure::Dataset, Vec<usize>)>, ParseError> {
        let Some(group) = self.group() else {
            return Ok(None);
        };
        if !group
            .datasets()
            .map_err(|e| self.error(format!("unreadable node: {e}")))?
            .iter()
            .any(|d| d == " data")
        {
            return Ok(None);
        }
        let d = group
            .dataset(" data")
            .map_err(|e| self.error(format!("unreadable data: {e}")))?;
        let shape: Vec<usize> = d
            .shape()
            .map_err(|e| self.error(format!("unreadable data shape: {e}")))?
            .into_iter()
            .map(|n| usize::try_from(n).unwrap_or(usize::MAX))
            .collect();
        let count = shape
            .iter()
            .try_fold(1usize, |a, &n| a.checked_mul(n))
            .unwrap_or(usize::MAX);
        let size = d.element_size().unwrap_or(1).max(1) as usize;
        let limit = if d.filters().is_empty() {
            self.tree.len
        } else {
            self.tree.len.saturating_mul(MAX_DEFLATE_RATIO)
        };
        if count.saturating_mul(size) > limit {
            return Err(self.error(format!(
                "data of shape {shape:?} is larger than the file ({} bytes) can hold",
                self.tree.len
            )));
        }
        Ok(Some((d, shape)))
    }

    /// The node's value as integers (`I4`/`I8`, or a real array of whole numbers is refused),
    /// with its shape.
    pub fn ints(&self) -> Result<(Vec<i64>, Vec<usize>), ParseError> {
        let ty = self.data_type()?;
        if ty != "I4" && ty != "I8" {
            return Err(self.error(format!("expected integer data (I4 or I8), found {ty:?}")));
        }
        if let Some((a, h)) = self.adf() {
            let bytes = a.value(h).map_err(|e| self.error(e))?;
            if bytes.is_empty() {
                return Err(self.error("no data"));
            }
            // HDF5's shape is CGNS's dimensions reversed (C order); ADF keeps CGNS's.
            let shape = h.dims.iter().rev().map(|&n| n as usize).collect();
            return Ok((a.ints(&ty, &bytes), shape));
        }
        let (d, shape) = self.dataset()?.ok_or_else(|| self.error("no data"))?;
        let v = d
            .read_i64()
            .map_err(|e| self.error(format!("unreadable integer data: {e}")))?;
        Ok((v, shape))
    }

    /// The node's value as reals (`R4`/`R8`).
    pub fn reals(&self) -> Result<Vec<f64>, ParseError> {
        let ty = self.data_type()?;
        if ty != "R4" && ty != "R8" {
            return Err(self.error(format!("expected real data (R4 or R8), found {ty:?}")));
        }
        if let Some((a, h)) = self.adf() {
            let bytes = a.value(h).map_err(|e| self.error(e))?;
            if bytes.is_empty() {
                return Err(self.error("no data"));
            }
            return Ok(a.reals(&ty, &bytes));
        }
        let (d, _) = self.dataset()?.ok_or_else(|| self.error("no data"))?;
        d.read_f64()
            .map_err(|e| self.error(format!("unreadable real data: {e}")))
    }

    /// The node's value as a string (`C1`), trailing blanks and NULs removed.
    pub fn string(&self) -> Result<String, ParseError> {
        let ty = self.data_type()?;
        if ty != "C1" {
            return Err(self.error(format!("expected character data (C1), found {ty:?}")));
        }
        let bytes = if let Some((a, h)) = self.adf() {
            a.value(h).map_err(|e| self.error(e))?
        } else {
            let Some((d, _)) = self.dataset()? else {
                return Ok(String::new());
            };
            d.read_raw()
                .map_err(|e| self.error(format!("unreadable character data: {e}")))?
        };
        Ok(String::from_utf8_lossy(&bytes)
            .trim_end_matches(['\0', ' '])
            .to_string())
    }
}
