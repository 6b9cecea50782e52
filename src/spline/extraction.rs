//! Bézier extraction operators (`architecture.md` §1).
//!
//! Every element e, spline or Q2, is a tensor-product quadratic polynomial on `[0,1]`^d whose
//! 3^d Bernstein control points (local index 9z + 3y + x) are `B_e = E_e · C`. The operator is
//! stored factored, which keeps a 1M-hex space near 110 bytes per element instead of the
//! ~1.5 kB of 125 explicit (column, weight) pairs per element:
//!
//! `E_e = (M_z ⊗ M_y ⊗ M_x) · W_e`
//!
//! * `M_k` is the 3×3 change of basis of direction k ([`Op1d::bernstein_matrix`]): a spline
//!   knot case, or Lagrange→Bernstein for Q2 elements (`ops[e]`); with non-uniform knot
//!   intervals the spline cases take the element's weights (`knot_weights[e]`,
//!   [`Op1d::bernstein_matrix_graded`]).
//! * `W_e` has one row per local node (`local_nodes`, 3^d per element, x fastest). A value
//!   below `n_control` is a control point taken with weight 1 (spline stencil entries, own Q2
//!   nodes); a value `n_control + r` is constraint row r, a list of (control point, weight)
//!   pairs (`constraint_offsets`, `constraint_entries`), shared by all elements using it.
//!
//! [`Extraction::rows`] expands one element into explicit CSR-like rows, and
//! [`Extraction::to_csr`] the whole operator (for small meshes, tests and assembly).

use super::knots::Op1d;
use crate::math::bernstein::net_len;

/// The factored extraction operator of a [`crate::spline::SplineSpace`].
#[derive(Clone, Debug, Default)]
pub struct Extraction {
    /// 2 or 3.
    pub dim: usize,
    /// Number of global control points (columns of every `E_e`).
    pub n_control: usize,
    /// 1D basis of each element direction (the z entry of a quad is unused).
    pub ops: Vec<[Op1d; 3]>,
    /// Knot weights `[α, β]` of each element direction
    /// ([`Op1d::bernstein_matrix_graded`]); empty for uniform knots (`α = β = ½`).
    pub knot_weights: Vec<[[f64; 2]; 3]>,
    /// 3^d local nodes per element: control point id, or `n_control` + constraint row.
    pub local_nodes: Vec<u32>,
    /// Constraint rows: entries `constraint_offsets[r]..constraint_offsets[r + 1]`.
    pub constraint_offsets: Vec<u32>,
    /// (control point, weight) pairs of the constraint rows, sorted by column within a row.
    pub constraint_entries: Vec<(u32, f64)>,
    /// Periodic seams ([`super::seam`]): per element an index into `node_shifts`, or `NONE`
    /// for an element whose local nodes take the control points as they are; empty when no
    /// element has a shift.
    pub shift_of: Vec<u32>,
    /// Per shifted element, the offset added to each local node (3^d used): where its stencil
    /// reaches control points across a periodic seam, the known translation that carries them
    /// to this element's side. Constant in the control points: the rows `E_e` are unchanged.
    pub node_shifts: Vec<[[f64; 3]; 27]>,
    /// Rotation-periodic seams ([`super::seam`]): per element an index into `frames`, or
    /// `NONE` for an element that sees every control point unrotated; empty when none does.
    pub frame_of: Vec<u32>,
    /// Per rotated element, the control points it sees rotated and the rotation R of each:
    /// the element takes R P + t for such a point P (t is in `node_shifts`), so its net is
    /// no longer the same linear map of every coordinate and E_e alone does not describe it.
    pub frames: Vec<Vec<SeamFrame>>,
}

/// A control point an element sees rotated across a periodic seam, and the rotation R (rows).
pub type SeamFrame = (u32, [[f64; 3]; 3]);

/// The explicit rows of one element's `E_e`: row i (Bernstein index, x fastest) has the
/// entries `offsets[i]..offsets[i + 1]` of `cols` / `weights`, sorted by column.
#[derive(Clone, Debug, Default)]
pub struct ElementRows {
    pub offsets: Vec<usize>,
    pub cols: Vec<u32>,
    pub weights: Vec<f64>,
}

impl ElementRows {
    pub fn n_rows(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Columns and weights of row `i`.
    pub fn row(&self, i: usize) -> (&[u32], &[f64]) {
        let r = self.offsets[i]..self.offsets[i + 1];
        (&self.cols[r.clone()], &self.weights[r])
    }
}

/// The whole extraction as one CSR matrix: row `3^d·e + i` is Bernstein point i of element e.
#[derive(Clone, Debug, Default)]
pub struct ExtractionCsr {
    pub n_rows: usize,
    pub n_cols: usize,
    pub row_offsets: Vec<usize>,
    pub cols: Vec<u32>,
    pub weights: Vec<f64>,
}

/// The (control point, weight) entries of one local node.
#[derive(Clone, Debug)]
pub enum NodeEntries<'a> {
    One(Option<(u32, f64)>),
    Many(std::slice::Iter<'a, (u32, f64)>),
}

impl Iterator for NodeEntries<'_> {
    type Item = (u32, f64);
    fn next(&mut self) -> Option<(u32, f64)> {
        match self {
            NodeEntries::One(x) => x.take(),
            NodeEntries::Many(it) => it.next().copied(),
        }
    }
}

impl Extraction {
    /// Local nodes (and Bernstein points) per element: 9 or 27.
    pub fn n_local(&self) -> usize {
        net_len(self.dim)
    }

    pub fn n_elements(&self) -> usize {
        self.ops.len()
    }

    pub fn n_constraints(&self) -> usize {
        self.constraint_offsets.len().saturating_sub(1)
    }

    /// The local nodes of element `e`.
    pub fn element_nodes(&self, e: usize) -> &[u32] {
        let n = self.n_local();
        &self.local_nodes[e * n..(e + 1) * n]
    }

    /// (control point, weight) entries of a local node value.
    pub fn node_entries(&self, node: u32) -> NodeEntries<'_> {
        let node = node as usize;
        if node < self.n_control {
            NodeEntries::One(Some((node as u32, 1.0)))
        } else {
            let r = node - self.n_control;
            let (a, b) = (
                self.constraint_offsets[r] as usize,
                self.constraint_offsets[r + 1] as usize,
            );
            NodeEntries::Many(self.constraint_entries[a..b].iter())
        }
    }

    /// The local node offsets of element `e` across a periodic seam, if it has any.
    pub fn node_shift(&self, e: usize) -> Option<&[[f64; 3]; 27]> {
        match self.shift_of.get(e) {
            Some(&i) if i != u32::MAX => Some(&self.node_shifts[i as usize]),
            _ => None,
        }
    }

    /// The control points element `e` sees rotated across a periodic seam, with their
    /// rotations, if it has any.
    pub fn frames(&self, e: usize) -> Option<&[SeamFrame]> {
        match self.frame_of.get(e) {
            Some(&i) if i != u32::MAX => Some(&self.frames[i as usize]),
            _ => None,
        }
    }

    /// Whether some element sees control points rotated (rotation-periodic seams glued).
    pub fn has_frames(&self) -> bool {
        !self.frames.is_empty()
    }

    /// The three 1D Bernstein matrices of element `e` (x, y, z; identity for z in 2D).
    pub fn matrices(&self, e: usize) -> [[[f64; 3]; 3]; 3] {
        let ops = self.ops[e];
        let w = self.knot_weights.get(e);
        std::array::from_fn(|k| {
            if k < self.dim {
                match w {
                    Some(w) => ops[k].bernstein_matrix_graded(w[k]),
                    None => ops[k].bernstein_matrix(),
                }
            } else {
                Op1d::BothEnds.bernstein_matrix()
            }
        })
    }

    /// True when element `e`'s rows are those of uniform knots.
    pub fn is_uniform(&self, e: usize) -> bool {
        self.knot_weights.get(e).is_none_or(|w| {
            (0..self.dim).all(|k| w[k] == [0.5, 0.5] || !self.ops[e][k].is_spline())
        })
    }

    /// Expand `E_e` into explicit rows (duplicates summed, exact zeros dropped).
    pub fn rows(&self, e: usize, out: &mut ElementRows) {
        out.offsets.clear();
        out.cols.clear();
        out.weights.clear();
        out.offsets.push(0);
        let n = self.n_local();
        let m = self.matrices(e);
        let nodes = self.element_nodes(e);
        let mut acc: Vec<(u32, f64)> = Vec::with_capacity(64);
        for b in 0..n {
            let (bx, by, bz) = (b % 3, (b / 3) % 3, b / 9);
            acc.clear();
            for (l, &node) in nodes.iter().enumerate() {
                let w = m[0][bx][l % 3] * m[1][by][(l / 3) % 3] * m[2][bz][l / 9];
                if w != 0.0 {
                    acc.extend(self.node_entries(node).map(|(g, x)| (g, w * x)));
                }
            }
            acc.sort_unstable_by_key(|p| p.0);
            let mut i = 0;
            while i < acc.len() {
                let g = acc[i].0;
                let mut w = 0.0;
                while i < acc.len() && acc[i].0 == g {
                    w += acc[i].1;
                    i += 1;
                }
                if w != 0.0 {
                    out.cols.push(g);
                    out.weights.push(w);
                }
            }
            out.offsets.push(out.cols.len());
        }
    }

    /// The whole operator as one CSR matrix (3^d rows per element).
    pub fn to_csr(&self) -> ExtractionCsr {
        let n = self.n_local();
        let mut csr = ExtractionCsr {
            n_rows: self.n_elements() * n,
            n_cols: self.n_control,
            row_offsets: vec![0],
            ..Default::default()
        };
        let mut rows = ElementRows::default();
        for e in 0..self.n_elements() {
            self.rows(e, &mut rows);
            let base = csr.cols.len();
            csr.cols.extend_from_slice(&rows.cols);
            csr.weights.extend_from_slice(&rows.weights);
            csr.row_offsets
                .extend(rows.offsets[1..].iter().map(|&o| base + o));
        }
        csr
    }
}
