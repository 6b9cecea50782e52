//! The fit's normal matrix K = Σ_e E_eᵀ G_e E_e: the sample points and weights that make the
//! element blocks G_e (one per weight mask), the assembled CSR form ([`NormalMatrix`], built by
//! [`super::assembly`]) and the matrix-free product ([`MatrixFree`]).

use super::*;
use crate::math::bernstein::net_len;
use crate::math::reference::{HEX_SIDES, QUAD_SIDES};
use crate::mesh::topology::NONE;

/// The symmetric matrix K in CSR form (`u32` column indices, `usize` row offsets, columns
/// sorted within each row), applied to 3-component vectors.
///
/// The values are stored either as a plain CSR value array or, as the assembly makes them
/// on meshes whose rows repeat (K depends on the topology and the weights, not on the
/// geometry), as one template id per row into a table of distinct row value sequences: at
/// 1M hexes that is a few MB instead of the 0.95 GB value array. [`Self::data`] expands the
/// templates on first use (once); the blocked CG takes them as they are.
#[derive(Clone)]
pub struct NormalMatrix {
    indptr: Vec<usize>,
    indices: Vec<u32>,
    values: Values,
    /// The control points' lattice lines, for the line blocks of
    /// [`crate::solve::CgPreconditioner::BlockJacobiLines`] ([`Self::set_lines`]).
    lines: Option<crate::solve::lines::Lines>,
}

/// A matrix stored by row template: row offsets, columns, template per row, templates.
pub(crate) type TemplatedParts = (
    Vec<usize>,
    Vec<u32>,
    Vec<u32>,
    crate::solve::blocked::RowTemplates,
);

#[derive(Clone)]
enum Values {
    Full(Vec<f64>),
    Templated {
        row_template: Vec<u32>,
        table: crate::solve::blocked::RowTemplates,
        /// The expanded values, made by the first [`NormalMatrix::data`].
        full: std::sync::OnceLock<Vec<f64>>,
    },
    /// Values not summed yet ([`super::assembly::assemble_deferred`]): the element matrices
    /// they are summed from, the symmetric scaling D to apply, and the value array once the
    /// host has asked for it.
    Deferred {
        sums: std::sync::Arc<super::assembly::RowSums>,
        scale: Option<Vec<f64>>,
        full: std::sync::OnceLock<Vec<f64>>,
    },
}

impl NormalMatrix {
    /// The n×n matrix of the CSR arrays `indptr` (n + 1 row offsets), `indices` (columns,
    /// strictly increasing within each row) and `data`.
    ///
    /// # Panics
    /// If the arrays do not describe a valid n×n CSR structure: they are built by this crate,
    /// so a failure is a bug, not bad input.
    pub fn new(n: usize, indptr: Vec<usize>, indices: Vec<u32>, data: Vec<f64>) -> Self {
        let (indptr, indices, data) =
            sprs::CsMatI::new((n, n), indptr, indices, data).into_raw_storage();
        NormalMatrix {
            indptr,
            indices,
            lines: None,
            values: Values::Full(data),
        }
    }

    /// The matrix whose row r has the columns `indices[indptr[r]..indptr[r + 1]]` (strictly
    /// increasing) and the values of template `row_template[r]` of `table`.
    pub(crate) fn from_templates(
        indptr: Vec<usize>,
        indices: Vec<u32>,
        row_template: Vec<u32>,
        table: crate::solve::blocked::RowTemplates,
    ) -> Self {
        debug_assert!((0..row_template.len()).all(|r| {
            table.get(row_template[r]).len() == indptr[r + 1] - indptr[r]
                && indices[indptr[r]..indptr[r + 1]]
                    .windows(2)
                    .all(|w| w[0] < w[1])
        }));
        NormalMatrix {
            indptr,
            indices,
            lines: None,
            values: Values::Templated {
                row_template,
                table,
                full: std::sync::OnceLock::new(),
            },
        }
    }

    /// The matrix of the row offsets `indptr` and sorted columns `indices` whose values are
    /// the row sums of `sums`.
    pub(crate) fn deferred(
        indptr: Vec<usize>,
        indices: Vec<u32>,
        sums: std::sync::Arc<super::assembly::RowSums>,
    ) -> Self {
        NormalMatrix {
            indptr,
            indices,
            lines: None,
            values: Values::Deferred {
                sums,
                scale: None,
                full: std::sync::OnceLock::new(),
            },
        }
    }

    /// For a matrix whose values are not summed yet, the element matrices they are summed
    /// from and the symmetric scaling D (value_rc · d_r d_c) to apply after the sums.
    pub fn unsummed(&self) -> Option<(&super::assembly::RowSums, Option<&[f64]>)> {
        match &self.values {
            Values::Deferred { sums, scale, .. } => Some((sums, scale.as_deref())),
            _ => None,
        }
    }

    /// The number of distinct row value sequences stored, `None` for a plain value array.
    pub fn n_templates(&self) -> Option<usize> {
        match &self.values {
            Values::Full(_) | Values::Deferred { .. } => None,
            Values::Templated { table, .. } => Some(table.len()),
        }
    }

    /// The number of rows (= columns).
    pub fn n(&self) -> usize {
        self.indptr.len() - 1
    }

    /// The n + 1 row offsets into [`Self::indices`] and [`Self::data`].
    pub fn indptr(&self) -> &[usize] {
        &self.indptr
    }

    /// The column of each stored entry, row by row.
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// The value of each stored entry, row by row (expanding row templates on first use).
    pub fn data(&self) -> &[f64] {
        match &self.values {
            Values::Full(d) => d,
            Values::Templated {
                row_template,
                table,
                full,
            } => full.get_or_init(|| expand(&self.indptr, row_template, table)),
            Values::Deferred { sums, scale, full } => {
                full.get_or_init(|| sums.values(&self.indptr, &self.indices, scale.as_deref()))
            }
        }
    }

    /// Give the solve the control points' lattice lines (unknowns numbered as K's rows), for
    /// [`crate::solve::CgPreconditioner::BlockJacobiLines`].
    pub fn set_lines(&mut self, lines: crate::solve::lines::Lines) {
        self.lines = Some(lines);
    }

    /// The CSR arrays (row offsets, columns, values), without copying them (row templates
    /// are expanded).
    pub fn into_parts(self) -> (Vec<usize>, Vec<u32>, Vec<f64>) {
        let data = match self.values {
            Values::Full(d) => d,
            Values::Templated {
                row_template,
                table,
                full,
            } => full
                .into_inner()
                .unwrap_or_else(|| expand(&self.indptr, &row_template, &table)),
            Values::Deferred { sums, scale, full } => full
                .into_inner()
                .unwrap_or_else(|| sums.values(&self.indptr, &self.indices, scale.as_deref())),
        };
        (self.indptr, self.indices, data)
    }

    /// The rows stored by template as (row offsets, columns, template per row, templates), or
    /// the matrix back when it holds a plain value array.
    pub(crate) fn into_templates(self) -> Result<TemplatedParts, Box<Self>> {
        match self.values {
            Values::Templated {
                row_template,
                table,
                ..
            } => Ok((self.indptr, self.indices, row_template, table)),
            values => Err(Box::new(NormalMatrix { values, ..self })),
        }
    }

    /// The stored values, for in-place rescaling (the structure stays fixed; row templates
    /// are expanded).
    pub fn data_mut(&mut self) -> &mut [f64] {
        if matches!(self.values, Values::Deferred { .. }) {
            self.data();
            let Values::Deferred { full, .. } =
                std::mem::replace(&mut self.values, Values::Full(Vec::new()))
            else {
                unreachable!("matched just above")
            };
            self.values = Values::Full(full.into_inner().expect("summed just above"));
        }
        if matches!(self.values, Values::Templated { .. }) {
            let Values::Templated {
                row_template,
                table,
                full,
            } = std::mem::replace(&mut self.values, Values::Full(Vec::new()))
            else {
                unreachable!("matched just above")
            };
            let data = full
                .into_inner()
                .unwrap_or_else(|| expand(&self.indptr, &row_template, &table));
            self.values = Values::Full(data);
        }
        match &mut self.values {
            Values::Full(d) => d,
            Values::Templated { .. } | Values::Deferred { .. } => {
                unreachable!("expanded just above")
            }
        }
    }

    /// [`crate::solve::pcg`] on this matrix, consuming it: the blocked solvers keep A in their
    /// own form and release the CSR arrays as they build it
    /// ([`crate::solve::BlockedSystem::from_parts`]; row templates are taken as they are), so
    /// the solve's peak memory does not hold A twice. Same iterates as `pcg(&self, ..)`.
    pub fn pcg(
        mut self,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        params: &crate::solve::CgParams,
        progress: impl crate::solve::CgMonitor,
    ) -> Result<crate::solve::CgInfo, CgError> {
        // Line blocks on block Jacobi where asked for and known; the preconditioner's own
        // blocked kind otherwise.
        let lines = self
            .lines
            .take()
            .filter(|_| params.preconditioner.with_lines());
        let blocked = params
            .preconditioner
            .blocked()
            .map(|(size, kind)| match lines {
                Some(_) => (size, crate::solve::BlockedKind::Jacobi),
                None => (size, kind),
            });
        let with_lines = |sys: crate::solve::BlockedSystem| match &lines {
            Some(l) => sys.with_lines(l),
            None => Ok(sys),
        };
        match blocked {
            Some((size, kind)) => match self.values {
                Values::Templated {
                    row_template,
                    table,
                    full,
                } => {
                    // An expanded copy, if one was asked for, is not kept through the solve.
                    drop(full);
                    with_lines(crate::solve::BlockedSystem::from_templates(
                        self.indptr,
                        self.indices,
                        row_template,
                        table,
                        size,
                        kind,
                    )?)?
                    .solve(b, x, params, progress)
                }
                Values::Full(_) | Values::Deferred { .. } => {
                    let (indptr, indices, data) = self.into_parts();
                    with_lines(crate::solve::BlockedSystem::from_parts(
                        indptr, indices, data, size, kind,
                    )?)?
                    .solve(b, x, params, progress)
                }
            },
            None => crate::solve::pcg(&self, b, x, params, progress),
        }
    }
}

/// The CSR value array of rows stored by template (rows past `row_template`'s end are zero).
pub(super) fn expand(
    indptr: &[usize],
    row_template: &[u32],
    table: &crate::solve::blocked::RowTemplates,
) -> Vec<f64> {
    let mut data = vec![0.0; indptr[indptr.len() - 1]];
    crate::solve::block_jacobi::split_at_offsets(&mut data, indptr)
        .into_par_iter()
        .zip(row_template.par_iter())
        .with_min_len(256)
        .for_each(|(row, &t)| row.copy_from_slice(table.get(t)));
    data
}

impl LinOp for NormalMatrix {
    fn nrows(&self) -> usize {
        self.n()
    }
    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        if let Values::Deferred { sums, scale, full } = &self.values
            && full.get().is_none()
        {
            // Each row summed where it is used, not kept: the product of the value array.
            let (indptr, indices, n) = (&self.indptr, &self.indices, self.n());
            let scale = scale.as_deref();
            y.par_iter_mut()
                .enumerate()
                .with_min_len(256)
                .for_each_init(
                    || (vec![0u32; n], Vec::new()),
                    |(pos, row), (r, y)| {
                        let cols = &indices[indptr[r]..indptr[r + 1]];
                        row.resize(cols.len(), 0.0);
                        sums.row(r, cols, pos, row);
                        if let Some(d) = scale {
                            scale_row(cols, d, r, row);
                        }
                        *y = crate::solve::row_dot(cols, row, x);
                    },
                );
            return;
        }
        let (indptr, indices, data) = (self.indptr(), self.indices(), self.data());
        y.par_iter_mut()
            .enumerate()
            .with_min_len(256)
            .for_each(|(r, y)| {
                let (lo, hi) = (indptr[r], indptr[r + 1]);
                *y = crate::solve::row_dot(&indices[lo..hi], &data[lo..hi], x);
            });
    }
    fn diagonal(&self) -> Vec<f64> {
        if let Some((sums, scale)) = self.unsummed() {
            let mut diag = sums.diagonal();
            if let Some(d) = scale {
                for (r, v) in diag.iter_mut().enumerate() {
                    *v *= d[r] * d[r];
                }
            }
            return diag;
        }
        let (indptr, indices, data) = (self.indptr(), self.indices(), self.data());
        (0..self.n())
            .map(|r| {
                (indptr[r]..indptr[r + 1])
                    .find(|&k| indices[k] as usize == r)
                    .map_or(0.0, |k| data[k])
            })
            .collect()
    }
    fn csr(&self) -> Option<(&[usize], &[u32], &[f64])> {
        Some((self.indptr(), self.indices(), self.data()))
    }
}

/// Sample points of one element: lattice point, Bernstein values b_i and derivatives b'_ij.
struct Samples {
    dim: usize,
    /// Per sample: the 3^d lattice coordinates in {0,1,2}.
    points: Vec<[usize; 3]>,
    values: Vec<[f64; 27]>,
    derivs: Vec<[[f64; 27]; 3]>,
}

impl Samples {
    fn new(dim: usize) -> Self {
        let n = net_len(dim);
        let nz = if dim == 2 { 1 } else { 3 };
        let db = |t: f64| [-2.0 * (1.0 - t), 2.0 * (1.0 - 2.0 * t), 2.0 * t];
        let mut s = Samples {
            dim,
            points: Vec::new(),
            values: Vec::new(),
            derivs: Vec::new(),
        };
        for i in 0..n {
            let l = [i % 3, (i / 3) % 3, i / 9];
            let t = l.map(|c| c as f64 / 2.0);
            let b = [
                bernstein2(t[0]),
                bernstein2(t[1]),
                if dim == 2 {
                    [1.0, 0.0, 0.0]
                } else {
                    bernstein2(t[2])
                },
            ];
            let d = [db(t[0]), db(t[1]), db(t[2])];
            let mut v = [0.0; 27];
            let mut dv = [[0.0; 27]; 3];
            for c in 0..nz {
                for bb in 0..3 {
                    for a in 0..3 {
                        let o = a + 3 * bb + 9 * c;
                        v[o] = b[0][a] * b[1][bb] * b[2][c];
                        dv[0][o] = d[0][a] * b[1][bb] * b[2][c];
                        dv[1][o] = b[0][a] * d[1][bb] * b[2][c];
                        if dim == 3 {
                            dv[2][o] = b[0][a] * b[1][bb] * d[2][c];
                        }
                    }
                }
            }
            s.points.push(l);
            s.values.push(v);
            s.derivs.push(dv);
        }
        s
    }

    fn is_corner(&self, i: usize) -> bool {
        self.points[i][..self.dim].iter().all(|&c| c != 1)
    }
}

/// Whether every corner of the edge, face or cell whose midpoint is lattice point `l` is a
/// boundary corner in `mask`: the boundary sides' midpoints (and the few interior edges, faces
/// or cells spanned by boundary vertices alone), which take [`FitWeights::boundary_midpoint`].
/// Called per sample in the right-hand side's assembly, so without allocation.
fn boundary_midpoint(mask: u64, l: [usize; 3]) -> bool {
    (0..8usize).all(|b| {
        // Corner b's coordinate j is 0 or 2 where l[j] = 1; the other coordinates are l's.
        let c: [usize; 3] =
            std::array::from_fn(|j| if l[j] == 1 { 2 * ((b >> j) & 1) } else { l[j] });
        mask & (1 << corner_of(c)) != 0
    })
}

/// Corner number (VTK order) of a lattice point with coordinates in {0, 2}.
fn corner_of(l: [usize; 3]) -> usize {
    const TABLE: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];
    TABLE[l[0] / 2 + 2 * (l[1] / 2) + 4 * (l[2] / 2)]
}

/// The per-element blocks G_e = G^d_e + G^r_e of the normal equations on the Bernstein points.
/// They depend on an element only through which of its corners are boundary vertices and
/// which samples lie on sharp features (the position weights), so one block per pattern is
/// kept.
pub struct ElementBlocks {
    /// Per element: bit c (c < 8) for a boundary corner c (of `weighted_boundary`), bit
    /// 8 + i for a sample i that takes the feature weight, `DEEP_BIT` for an element a ring
    /// away from that boundary, `EXTRAORDINARY_BIT` for one near an extraordinary vertex, the
    /// size level in the 8 bits from `LEVEL_SHIFT`, bit `THIN_RIM_SHIFT` + c for a corner c
    /// on a thin rim.
    pub masks: Vec<u64>,
    /// (G^d, G^r), row-major 3^d × 3^d, per mask.
    pub cache: HashMap<u64, (Vec<f64>, Vec<f64>)>,
}

/// Position weight of sample `i` (lattice point `l`) of an element with weight mask `mask`.
pub(super) fn sample_weight(
    w: &FitWeights,
    mask: u64,
    i: usize,
    l: [usize; 3],
    corner: bool,
) -> f64 {
    size_scale(mask) * sample_weight_unscaled(w, mask, i, l, corner)
}

/// Weight-mask bit of an element none of whose vertices belongs to an element touching the
/// boundary ([`FitWeights::deep_midpoint`]; above the feature bits 8..35).
pub(super) const DEEP_BIT: u64 = 1 << 40;

/// Weight-mask bit of an element without a boundary corner within two element rings of an
/// extraordinary vertex or edge ([`FitWeights::extraordinary_midpoint`]).
pub(super) const EXTRAORDINARY_BIT: u64 = 1 << 41;

/// Bit offset of an element's size level in its weight mask.
pub(super) const LEVEL_SHIFT: u32 = 48;

/// Bit offset of the corners at thin-rim vertices in a weight mask (bit `THIN_RIM_SHIFT + c`
/// for corner c, [`features::thin_rim_weight`]), above the size level.
pub(super) const THIN_RIM_SHIFT: u32 = 56;

/// The weight factor 4^k of size level k (bits 48.. of the mask; see [`size_levels`]).
fn size_scale(mask: u64) -> f64 {
    let k = ((mask >> LEVEL_SHIFT) & LEVEL_BITS) as i32;
    (4.0f64).powi(k)
}

/// The size level stored in a weight mask.
pub fn mask_level(mask: u64) -> u16 {
    ((mask >> LEVEL_SHIFT) & LEVEL_BITS) as u16
}

/// The bits of a size level in a weight mask, above [`LEVEL_SHIFT`] ([`MAX_LEVEL`] < 256).
pub(super) const LEVEL_BITS: u64 = 0xFF;

fn sample_weight_unscaled(w: &FitWeights, mask: u64, i: usize, l: [usize; 3], corner: bool) -> f64 {
    if mask & (1 << (8 + i)) != 0 {
        w.feature
    } else if !corner {
        if boundary_midpoint(mask, l) {
            w.boundary_midpoint
        } else {
            let base = if mask & DEEP_BIT != 0 {
                w.deep_midpoint.unwrap_or(w.midpoint)
            } else {
                w.midpoint
            };
            if mask & EXTRAORDINARY_BIT != 0 {
                base.max(w.extraordinary_midpoint)
            } else {
                base
            }
        }
    } else if mask & (1 << (THIN_RIM_SHIFT as usize + corner_of(l))) != 0 {
        features::thin_rim_weight(w)
    } else if mask & (1 << corner_of(l)) != 0 {
        w.boundary_corner
    } else {
        w.corner
    }
}

/// Size levels below this many halvings of the largest element's size get no extra weight, so
/// meshes whose element sizes vary by less than 2^`LEVEL_DEAD_ZONE` keep plain weights.
pub(super) const LEVEL_DEAD_ZONE: f64 = 2.0;

/// The shortest edge of element `e` (h_e of [`size_levels`]).
pub(super) fn shortest_edge(mesh: &LinearMesh, e: usize) -> f64 {
    let edges: &[[usize; 2]] = if mesh.dim == 2 {
        &[[0, 1], [1, 2], [2, 3], [3, 0]]
    } else {
        &crate::math::reference::HEX_EDGES
    };
    let x = mesh.element_coords(e).map(DVec3::from);
    edges
        .iter()
        .map(|&[a, b]| (x[a] - x[b]).length())
        .fold(f64::INFINITY, f64::min)
}

/// Per element, the size level k = max(0, ⌊log₂(h_max / h_e)⌋ − `LEVEL_DEAD_ZONE`), h_e the
/// element's shortest edge: its samples are weighted by 4^k ≈ (h_max / h_e)², so the fit
/// balances errors relative to the size of the element they distort. With plain weights the
/// least-squares error of a large far-field cell leaks into the thin boundary-layer cells next
/// to it (on a C-grid with wall cells 10⁻⁵ and far-field cells 10² long, errors of 10⁻² in cells
/// 10⁻⁵ thin).
pub fn size_levels(mesh: &LinearMesh) -> Vec<u16> {
    let h: Vec<f64> = (0..mesh.n_elements())
        .into_par_iter()
        .map(|e| shortest_edge(mesh, e))
        .collect();
    let hmax = h.iter().copied().fold(0.0, f64::max);
    h.par_iter()
        .map(|&he| {
            if he > 0.0 && hmax > 0.0 {
                ((hmax / he).log2().floor() - LEVEL_DEAD_ZONE).clamp(0.0, MAX_LEVEL as f64) as u16
            } else {
                0
            }
        })
        .collect()
}

/// Largest size level (4^k stays far inside f64's range).
pub(super) const MAX_LEVEL: u16 = 200;

/// Per control point, 2^−k with k the largest size level of the elements using it, or `None`
/// when every level is 0. The fit solves D K D y = D b with D = diag(2^−k) and δ = D y: the
/// same iterates under (block) Jacobi preconditioning, but the residual that stops CG then
/// weighs every control point relative to its own elements' size, so far-field rows do not
/// stop it before the boundary-layer rows have converged (powers of 2 keep K's values exact).
pub(super) fn control_point_scales(space: &dyn FitSpace, levels: &[u16]) -> Option<Vec<f64>> {
    if levels.iter().all(|&l| l == 0) {
        return None;
    }
    let mut k = vec![0u16; space.control_points().len()];
    let (mut offsets, mut cols, mut weights) = (Vec::new(), Vec::new(), Vec::new());
    for (e, &l) in levels.iter().enumerate() {
        if l == 0 {
            continue;
        }
        space.element_rows(e, &mut offsets, &mut cols, &mut weights);
        for &c in &cols {
            let slot = &mut k[c as usize];
            *slot = (*slot).max(l);
        }
    }
    Some(k.iter().map(|&k| (0.5f64).powi(k as i32)).collect())
}

impl NormalMatrix {
    /// K ← D K D for the diagonal D = diag(`d`).
    pub fn scale_symmetric(&mut self, d: &[f64]) {
        if let Values::Deferred { scale, full, .. } = &mut self.values
            && scale.is_none()
            && full.get().is_none()
        {
            // Applied after the sums, wherever they run.
            *scale = Some(d.to_vec());
            return;
        }
        let (indptr, indices) = (&self.indptr, &self.indices);
        if let Values::Templated {
            row_template,
            table,
            full,
        } = &mut self.values
        {
            // Rows and columns with D = 1 keep their template; the other rows get templates
            // of their scaled values, a chunk of rows at a time.
            let moved: Vec<usize> = (0..row_template.len())
                .into_par_iter()
                .with_min_len(256)
                .filter(|&r| {
                    d[r] != 1.0
                        || indices[indptr[r]..indptr[r + 1]]
                            .iter()
                            .any(|&c| d[c as usize] != 1.0)
                })
                .collect();
            if 2 * moved.len() <= row_template.len() {
                *full = std::sync::OnceLock::new();
                for rows in moved.chunks(1 << 14) {
                    let mut start = vec![0usize];
                    for &r in rows {
                        start.push(start[start.len() - 1] + indptr[r + 1] - indptr[r]);
                    }
                    let mut values = vec![0.0; start[rows.len()]];
                    crate::solve::block_jacobi::split_at_offsets(&mut values, &start)
                        .into_par_iter()
                        .zip(rows.par_iter())
                        .for_each(|(v, &r)| {
                            v.copy_from_slice(table.get(row_template[r]));
                            scale_row(&indices[indptr[r]..indptr[r + 1]], d, r, v);
                        });
                    let t = table.add_rows(
                        rows.len(),
                        |i| &values[start[i]..start[i + 1]],
                        crate::solve::blocked::hash_row,
                    );
                    for (&r, t) in rows.iter().zip(t) {
                        row_template[r] = t;
                    }
                }
                return;
            }
        }
        // Scaled rows seldom repeat: the plain value array.
        self.data_mut();
        let Values::Full(data) = &mut self.values else {
            unreachable!("expanded by data_mut")
        };
        let (indptr, indices) = (&self.indptr, &self.indices);
        crate::solve::block_jacobi::split_at_offsets(data, indptr)
            .into_par_iter()
            .enumerate()
            .for_each(|(r, row)| scale_row(&indices[indptr[r]..indptr[r + 1]], d, r, row));
    }
}

/// Row r's values `v` (columns `cols`) times d_r d_c.
pub(super) fn scale_row(cols: &[u32], d: &[f64], r: usize, v: &mut [f64]) {
    for (v, &c) in v.iter_mut().zip(cols) {
        *v *= d[r] * d[c as usize];
    }
}

impl ElementBlocks {
    pub fn new(space: &dyn FitSpace, mesh: &LinearMesh, topo: &Topology, w: &FitWeights) -> Self {
        Self::with_features(space, mesh, topo, w, None)
    }

    /// [`ElementBlocks::new`], with the feature samples of `features` weighted by
    /// [`FitWeights::feature`].
    pub fn with_features(
        space: &dyn FitSpace,
        mesh: &LinearMesh,
        topo: &Topology,
        w: &FitWeights,
        features: Option<&crate::mesh::features::Features>,
    ) -> Self {
        let dim = space.dim();
        let nb = net_len(dim);
        let samples = Samples::new(dim);
        let g_of = |mask: u64| -> (Vec<f64>, Vec<f64>) {
            let mut gd = vec![0.0; nb * nb];
            let mut gr = vec![0.0; nb * nb];
            for i in 0..nb {
                let corner = samples.is_corner(i);
                let wd = sample_weight(w, mask, i, samples.points[i], corner);
                let wr = size_scale(mask)
                    * if corner {
                        w.frame_corner
                    } else {
                        w.frame_midpoint
                    };
                let b = &samples.values[i];
                for r in 0..nb {
                    for c in 0..nb {
                        gd[r * nb + c] += wd * b[r] * b[c];
                        for j in 0..dim {
                            let d = &samples.derivs[i][j];
                            gr[r * nb + c] += wr * d[r] * d[c];
                        }
                    }
                }
            }
            (gd, gr)
        };
        let masks = weight_masks(space.n_elements(), mesh, topo, w, features);
        let mut cache = HashMap::new();
        for &m in &masks {
            cache.entry(m).or_insert_with(|| g_of(m));
        }
        ElementBlocks { masks, cache }
    }
}

/// Per element, its weight mask ([`ElementBlocks::masks`]).
fn weight_masks(
    n: usize,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    features: Option<&crate::mesh::features::Features>,
) -> Vec<u64> {
    let levels = size_levels(mesh);
    let on_boundary = weighted_boundary(topo, features, w);
    // Vertices of the elements that touch the boundary: an element with none of them is
    // "deep" (a ring away from the wall).
    let mut near = vec![false; on_boundary.len()];
    for e in 0..n {
        let vs = mesh.element(e);
        if vs.iter().any(|&v| on_boundary[v as usize]) {
            vs.iter().for_each(|&v| near[v as usize] = true);
        }
    }
    let extraordinary = extraordinary_elements(n, mesh, topo, w);
    (0..n)
        .map(|e| {
            let mut m = 0u64;
            for (c, &v) in mesh.element(e).iter().enumerate() {
                if on_boundary[v as usize] {
                    m |= 1 << c;
                }
            }
            if mesh.element(e).iter().all(|&v| !near[v as usize]) {
                m |= DEEP_BIT;
            }
            // Not at the boundary's corners, whose midpoints pull the fitted boundary.
            if extraordinary[e] && m & 0xFF == 0 {
                m |= EXTRAORDINARY_BIT;
            }
            if let Some(f) = features {
                m |= features::sample_mask(f, mesh, e) << 8;
                m |= features::thin_rim_corners(f, mesh, e) << THIN_RIM_SHIFT;
            }
            m | (levels[e] as u64) << LEVEL_SHIFT
        })
        .collect()
}

/// Per element, whether [`FitWeights::extraordinary_midpoint`] raises the weight of its
/// interior midpoints under `w`: an element within two element rings of an extraordinary
/// vertex or edge ([`extraordinary_vertices`]) without a boundary corner, whose own midpoint
/// weight is lower.
/// The fit under `w` is the fit without that weight where no element is.
pub fn extraordinary_reweighted(
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    features: Option<&crate::mesh::features::Features>,
) -> Vec<bool> {
    weight_masks(mesh.n_elements(), mesh, topo, w, features)
        .into_iter()
        .map(|m| {
            let base = if m & DEEP_BIT != 0 {
                w.deep_midpoint.unwrap_or(w.midpoint)
            } else {
                w.midpoint
            };
            m & EXTRAORDINARY_BIT != 0 && base < w.extraordinary_midpoint
        })
        .collect()
}

/// Per vertex, whether it is an extraordinary interior vertex: not on the boundary, and in 2D
/// of valence other than 4; in 3D with other than 8 elements around it or on an edge of
/// valence other than 4 (an extraordinary edge with an end point inside the mesh). Vertices
/// on a facet glued across a periodic seam ([`Topology::with_interior_facets`]: the elements
/// on its two sides hold different copies of them) are not counted: their elements on the
/// other side are not theirs.
///
/// On a rank's ghosted sub-mesh the answer at a vertex whose elements are all on the rank
/// (own or ghost) is the whole mesh's: every element around its edges is one of them, and
/// so is every facet deciding whether it is on the boundary.
pub fn extraordinary_vertices(mesh: &LinearMesh, topo: &Topology) -> Vec<bool> {
    let regular = 1usize << topo.dim;
    let mut ev: Vec<bool> = (0..topo.n_vertices)
        .map(|v| !topo.vertex_on_boundary[v] && topo.vertex_valence(v) != regular)
        .collect();
    if topo.dim == 3 {
        for (edge, &valence) in topo.edges.iter().zip(&topo.edge_valence) {
            if valence != 4 {
                for &v in edge {
                    ev[v as usize] |= !topo.vertex_on_boundary[v as usize];
                }
            }
        }
    }
    let side = |e: u32, s: u8| -> Vec<u32> {
        let vs = mesh.element(e as usize);
        let mut out: Vec<u32> = if topo.dim == 2 {
            QUAD_SIDES[s as usize].iter().map(|&i| vs[i]).collect()
        } else {
            HEX_SIDES[s as usize].iter().map(|&i| vs[i]).collect()
        };
        out.sort_unstable();
        out
    };
    for (els, sides) in topo.facet_elements.iter().zip(&topo.facet_sides) {
        if els[1] == NONE {
            continue;
        }
        let (a, b) = (side(els[0], sides[0]), side(els[1], sides[1]));
        if a != b {
            for v in a.into_iter().chain(b) {
                ev[v as usize] = false;
            }
        }
    }
    ev
}

/// The elements whose interior midpoints may take [`FitWeights::extraordinary_midpoint`]:
/// those sharing a vertex with an element at an extraordinary vertex
/// ([`extraordinary_vertices`]); none where that weight is not above the midpoint weights it
/// would replace (the position and frame presets), so those fits are unchanged.
///
/// Why two element rings: hsphere8's ratio-guard rejections sit in the elements at its
/// valence-3 diagonal and in their neighbours (51, 15 of them at the diagonal), sphere_r6's at
/// and around its irregular interior vertices; weighting only the elements at the vertices
/// kept 22 % and 15 % held back, the two rings 11 % and 8 % (`BENCHMARKS.md`, "Midpoint weight
/// at extraordinary vertices").
fn extraordinary_elements(
    n: usize,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
) -> Vec<bool> {
    let deep = w.deep_midpoint.unwrap_or(w.midpoint);
    if w.extraordinary_midpoint <= w.midpoint.min(deep) {
        return vec![false; n];
    }
    let ev = extraordinary_vertices(mesh, topo);
    let mut near = vec![false; topo.n_vertices];
    for e in 0..n {
        let vs = mesh.element(e);
        if vs.iter().any(|&v| ev[v as usize]) {
            vs.iter().for_each(|&v| near[v as usize] = true);
        }
    }
    (0..n)
        .map(|e| mesh.element(e).iter().any(|&v| near[v as usize]))
        .collect()
}

/// The vertices that take the boundary weights ([`FitWeights::boundary_corner`], the
/// boundary midpoints they span) and make their elements' neighbours non-deep: the boundary
/// vertices; in 3D where the deep midpoints weigh otherwise than the interior ones (graded
/// knots, [`FitWeights::for_knots`]), less those whose boundary facets all lie in planar
/// patches, unless they lie on a feature curve or corner.
///
/// Why: a planar patch is projected back onto its plane after the fit, and its midpoints have
/// no smooth targets to follow; counted as boundary, the caps of a one- or three-layer
/// extrusion made every element a boundary element (every midpoint at `boundary_midpoint`,
/// none deep), and the graded fit lost the deep-midpoint weight that keeps graded layers
/// valid in 2D (ellipse O-grid, wall cells 1e-6 growing by 1.05, one layer: every element held
/// back with either knots, 18 % with graded knots and these vertices). Not with uniform
/// knots, where the deep weight is the interior one: there nothing becomes deep, and the
/// planar vertices' interior weights only loosen the fit (box with a hole: feature vertices
/// 9e-9 off their straight edges instead of rounding; min scaled Jacobian 0.7018 against
/// 0.7071). The planar vertices next to a feature keep the interior weights too: with the
/// boundary corner weight beside interior midpoints, CG took 2× the iterations on meshes of
/// planar patches (acoustics_mesh3d 105 → 217, NACA4412_2.msh 69 → 88).
fn weighted_boundary(
    topo: &Topology,
    features: Option<&crate::mesh::features::Features>,
    w: &FitWeights,
) -> Vec<bool> {
    let mut on = topo.vertex_on_boundary.clone();
    let deep_differs = w.deep_midpoint.is_some_and(|d| d != w.midpoint);
    let Some(f) =
        features.filter(|f| deep_differs && topo.dim == 3 && f.planes.iter().any(Option::is_some))
    else {
        return on;
    };
    on.iter_mut().for_each(|b| *b = false);
    for (i, &facet) in topo.boundary_facets.iter().enumerate() {
        if f.planes[f.facet_patch[i] as usize].is_none() {
            for &v in topo.facet_vertices(facet as usize) {
                on[v as usize] = true;
            }
        }
    }
    // Feature curves and corners keep the boundary weights: they are not projected back
    // along their curve, and their neighbours' weights hold them at the input's vertices.
    for (v, &m) in f.vertex_mask.iter().enumerate() {
        on[v] |= m;
    }
    for &c in &f.corners {
        on[c as usize] = true;
    }
    on
}

/// K applied without assembling it: y = Σ_e E_eᵀ G_e E_e x, element by element (the
/// alternative to [`NormalMatrix`]; see docs/benchmarks-history.md for the measured comparison).
pub struct MatrixFree<'a> {
    pub space: &'a dyn FitSpace,
    pub blocks: ElementBlocks,
    /// Explicit extraction rows per element (offsets, columns, weights).
    rows: Vec<(Vec<usize>, Vec<u32>, Vec<f64>)>,
}

impl<'a> MatrixFree<'a> {
    pub fn new(
        space: &'a dyn FitSpace,
        mesh: &LinearMesh,
        topo: &Topology,
        w: &FitWeights,
    ) -> Self {
        let rows = (0..space.n_elements())
            .into_par_iter()
            .map(|e| {
                let (mut o, mut c, mut w) = (Vec::new(), Vec::new(), Vec::new());
                space.element_rows(e, &mut o, &mut c, &mut w);
                (o, c, w)
            })
            .collect();
        MatrixFree {
            space,
            blocks: ElementBlocks::new(space, mesh, topo, w),
            rows,
        }
    }
}

impl LinOp for MatrixFree<'_> {
    fn nrows(&self) -> usize {
        self.space.control_points().len()
    }
    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        let n = self.nrows();
        let nb = net_len(self.space.dim());
        let sum = (0..self.rows.len())
            .into_par_iter()
            .fold(
                || vec![[0.0; 3]; n],
                |mut acc, e| {
                    let (o, c, w) = &self.rows[e];
                    let mut b = [DVec3::ZERO; 27];
                    for i in 0..nb {
                        for k in o[i]..o[i + 1] {
                            b[i] += DVec3::from(x[c[k] as usize]) * w[k];
                        }
                    }
                    let (gd, gr) = &self.blocks.cache[&self.blocks.masks[e]];
                    for i in 0..nb {
                        let mut z = DVec3::ZERO;
                        for j in 0..nb {
                            z += b[j] * (gd[i * nb + j] + gr[i * nb + j]);
                        }
                        for k in o[i]..o[i + 1] {
                            let t = &mut acc[c[k] as usize];
                            *t = (DVec3::from(*t) + z * w[k]).into();
                        }
                    }
                    acc
                },
            )
            .reduce(
                || vec![[0.0; 3]; n],
                |mut a, b| {
                    for (p, q) in a.iter_mut().zip(&b) {
                        for d in 0..3 {
                            p[d] += q[d];
                        }
                    }
                    a
                },
            );
        y.copy_from_slice(&sum);
    }
    fn diagonal(&self) -> Vec<f64> {
        let n = self.nrows();
        let nb = net_len(self.space.dim());
        let mut diag = vec![0.0; n];
        for (e, (o, c, w)) in self.rows.iter().enumerate() {
            let (gd, gr) = &self.blocks.cache[&self.blocks.masks[e]];
            // diag_c = Σ_e Σ_ij R_ic G_ij R_jc
            let mut cols: Vec<u32> = c.clone();
            cols.sort_unstable();
            cols.dedup();
            for &col in &cols {
                let r: Vec<f64> = (0..nb)
                    .map(|i| {
                        (o[i]..o[i + 1])
                            .filter(|&k| c[k] == col)
                            .map(|k| w[k])
                            .sum()
                    })
                    .collect();
                let mut s = 0.0;
                for i in 0..nb {
                    for j in 0..nb {
                        s += r[i] * (gd[i * nb + j] + gr[i * nb + j]) * r[j];
                    }
                }
                diag[col as usize] += s;
            }
        }
        diag
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hexahedron whose bottom face (VTK corners 0–3, z = 0) is on the boundary: its edge
    /// midpoints and face centre there are boundary midpoints; the midpoints of the vertical
    /// edges, the side faces' centres and the cell centre are not.
    #[test]
    fn boundary_midpoints_are_those_spanned_by_boundary_corners() {
        let mask = 0b1111;
        for l in [[1, 0, 0], [2, 1, 0], [1, 2, 0], [0, 1, 0], [1, 1, 0]] {
            assert!(boundary_midpoint(mask, l), "{l:?}");
        }
        for l in [[0, 0, 1], [1, 0, 1], [1, 1, 1], [1, 1, 2], [1, 0, 2]] {
            assert!(!boundary_midpoint(mask, l), "{l:?}");
        }
        // One boundary corner (VTK 1 at lattice (2, 0, 0)) spans no midpoint.
        assert!(!boundary_midpoint(0b10, [1, 0, 0]));
        assert!(!boundary_midpoint(0b10, [2, 1, 0]));
    }
}
