//! Least-squares fit of the spline control points to the input mesh (paper §2.3, eq. 3–9).
//!
//! Input: a spline space ([`FitSpace`]: control points C0 and the Bézier extraction E_e of every
//! element), the linear mesh and its topology, and [`FitParams`]. Output: fitted control points
//! C* and a [`FitInfo`].
//!
//! **Objective** Q = D + R over the 3^d sample points u_i ∈ {0, ½, 1}^d of every element:
//! * D = Σ_e Σ_i w^d_i ‖x_e(u_i) − P_e(u_i)‖², P_e the input element's multilinear map (its
//!   vertices at corners, points on straight edges/faces at midpoints);
//! * R = Σ_e Σ_i w^r_i Σ_j ‖∂_j x_e(u_i) − ∂_j x⁰_e(u_i)‖², x⁰ the initial IGA map (frames kept).
//!
//! The weights multiply the **squared** residuals (paper eq. 3), consistently in D and R; the
//! matrix form with rows scaled by √w gives the same normal equations. With x_e(u) = b(u)ᵀ E_e C
//! the normal equations are K C = F with K = Σ_e E_eᵀ G_e E_e,
//! G_e = Σ_i w^d_i b_i b_iᵀ + Σ_i w^r_i Σ_j b'_ij b'_ijᵀ, one SPD matrix for the three
//! coordinates. They are solved for the displacement δ = C − C0 (K δ = F − K C0), which keeps
//! the right-hand side small and the iteration well scaled, by preconditioned CG
//! ([`crate::solve::pcg`]: block Jacobi on aggregates by default, point Jacobi on request) on
//! the assembled matrix.
//!
//! **Targets.** [`FitTargets::Chords`] is the paper's P_e. [`FitTargets::Smooth`] moves the
//! midpoint targets (edge midpoints, face and cell centres) from the chords onto a local
//! second-order reconstruction of the smooth boundary ([`smooth`]), which makes the fitted
//! boundary third-order accurate instead of second where the spline space can follow the
//! input's boundary grid; where the grid lines kink, the caller makes the elements there Q2
//! ([`crate::spline::kinks`], [`SmoothParams::kink_angle_deg`]).

pub mod assembly;
pub mod features;
pub mod partial;
mod rhs;
pub mod smooth;

pub use smooth::{SmoothParams, SmoothTargets};

use crate::math::bernstein::bernstein2;
use crate::mesh::{LinearMesh, Topology, vec3};
use crate::solve::{CgError, CgInfo, CgParams, LinOp, pcg};
use rayon::prelude::*;
use std::collections::HashMap;

/// A space of quadratic Bézier elements driven by global control points.
pub trait FitSpace: Sync {
    fn dim(&self) -> usize;
    fn n_elements(&self) -> usize;
    fn control_points(&self) -> &[[f64; 3]];
    /// Explicit rows of E_e: Bernstein point i (index 9z + 3y + x) is Σ weights · C\[cols\]
    /// over `offsets[i]..offsets[i+1]`.
    fn element_rows(
        &self,
        e: usize,
        offsets: &mut Vec<usize>,
        cols: &mut Vec<u32>,
        weights: &mut Vec<f64>,
    );
    /// Bernstein net of element `e` for the control points `cps`.
    fn bezier_net_with(&self, e: usize, cps: &[[f64; 3]]) -> [[f64; 3]; 27];
    /// When E_e is a matrix shared by every element with the same key times the selection of
    /// 3^d distinct control points (in local-node order), return the key and write the
    /// control points into `ids`; the assembly then computes one local matrix per key.
    /// `None` (the default) always works.
    fn element_pattern(&self, _e: usize, _ids: &mut Vec<u32>) -> Option<u64> {
        None
    }
    /// Append E_eᵀ f to `out` as (control point, value) pairs (a control point may repeat),
    /// for f one 3-vector per Bernstein point. The default expands the explicit rows.
    fn add_transposed(&self, e: usize, f: &[[f64; 3]; 27], out: &mut Vec<(u32, [f64; 3])>) {
        let (mut offsets, mut cols, mut weights) = (Vec::new(), Vec::new(), Vec::new());
        self.element_rows(e, &mut offsets, &mut cols, &mut weights);
        for i in 0..offsets.len() - 1 {
            for k in offsets[i]..offsets[i + 1] {
                out.push((cols[k], f[i].map(|v| weights[k] * v)));
            }
        }
    }
}

/// Sample-point weights (they multiply squared residuals).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FitWeights {
    /// Position weight at element corners on interior vertices.
    pub corner: f64,
    /// Position weight at element corners on boundary vertices.
    pub boundary_corner: f64,
    /// Position weight at edge/face midpoints and element centres.
    pub midpoint: f64,
    /// Frame (first derivative) weight at corners.
    pub frame_corner: f64,
    /// Frame weight at midpoints and centres.
    pub frame_midpoint: f64,
    /// Position weight at element corners on sharp-feature vertices when the fit is given
    /// [`FitParams::features`]; it keeps the feature curves close to the input's feature
    /// polylines.
    pub feature: f64,
}

impl FitWeights {
    /// The paper's position-only example: w = 1 interior corners, 10 boundary corners,
    /// 0.5 midpoints, no frame term.
    pub fn position() -> Self {
        FitWeights {
            corner: 1.0,
            boundary_corner: 10.0,
            midpoint: 0.5,
            frame_corner: 0.0,
            frame_midpoint: 0.0,
            feature: 10.0,
        }
    }
    /// Weights of the smooth-boundary mode (`--fit smooth`, used with
    /// [`FitTargets::Smooth`]): the position preset's weights, no frame term (the frames of the
    /// initial map follow the chords and would pull the boundary back towards them).
    pub fn smooth() -> Self {
        FitWeights::position()
    }
    /// The paper's position + frame example: w^r = 1 everywhere, w^d = 0 at midpoints,
    /// corners as in [`FitWeights::position`].
    pub fn frame() -> Self {
        FitWeights {
            corner: 1.0,
            boundary_corner: 10.0,
            midpoint: 0.0,
            frame_corner: 1.0,
            frame_midpoint: 1.0,
            feature: 10.0,
        }
    }
}

/// The fit presets of the command line (`--fit`): which weights and targets the least-squares
/// fit uses, and whether the energy minimisation follows it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FitPreset {
    /// No fit: sample the initial spline map.
    None,
    /// The paper's position weights (least squares, then a certified line search).
    Position,
    /// The paper's position + frame weights.
    Frame,
    /// Midpoint targets from a local reconstruction of the smooth boundary instead of the
    /// straight chords (more accurate curved boundaries).
    Smooth,
    /// `smooth`, then the element degeneration energy minimised under the det J certificate
    /// (paper §2.4, docs/energy.md).
    Energy,
}

impl FitPreset {
    /// The preset's weights (the command line overrides single ones).
    pub fn weights(self) -> FitWeights {
        match self {
            FitPreset::Frame => FitWeights::frame(),
            FitPreset::Smooth | FitPreset::Energy => FitWeights::smooth(),
            FitPreset::None | FitPreset::Position => FitWeights::position(),
        }
    }
    /// Whether the midpoint targets come from the smooth-boundary reconstruction.
    pub fn smooth_targets(self) -> bool {
        matches!(self, FitPreset::Smooth | FitPreset::Energy)
    }
}

/// Where the position targets of midpoint samples come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FitTargets {
    /// The input's multilinear map (midpoints on straight edges/faces), as in the paper.
    #[default]
    Chords,
    /// Midpoints moved onto a local reconstruction of the smooth boundary ([`smooth`]).
    Smooth(SmoothParams),
}

/// Fit parameters.
#[derive(Clone, Debug)]
pub struct FitParams {
    pub weights: FitWeights,
    pub cg: CgParams,
    pub targets: FitTargets,
    /// Sharp features of the input: smooth targets are reconstructed per patch and feature
    /// samples get [`FitWeights::feature`] (see [`features`]). `None` treats the boundary as
    /// one smooth surface.
    pub features: Option<std::sync::Arc<crate::mesh::features::Features>>,
}

impl FitParams {
    /// The smooth-boundary mode: [`FitWeights::smooth`] with [`FitTargets::Smooth`].
    pub fn smooth() -> Self {
        FitParams {
            weights: FitWeights::smooth(),
            targets: FitTargets::Smooth(SmoothParams::default()),
            ..Default::default()
        }
    }
}

impl Default for FitParams {
    fn default() -> Self {
        FitParams {
            weights: FitWeights::position(),
            cg: CgParams::default(),
            targets: FitTargets::Chords,
            features: None,
        }
    }
}

/// What the fit did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FitInfo {
    pub cg: CgInfo,
    pub unknowns: usize,
    pub nonzeros: usize,
    pub assembly_seconds: f64,
    pub solve_seconds: f64,
}

/// The symmetric matrix K in CSR form, applied to 3-component vectors.
pub struct NormalMatrix {
    pub n: usize,
    pub indptr: Vec<usize>,
    pub indices: Vec<u32>,
    pub data: Vec<f64>,
}

impl LinOp for NormalMatrix {
    fn nrows(&self) -> usize {
        self.n
    }
    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        y.par_iter_mut()
            .enumerate()
            .with_min_len(256)
            .for_each(|(r, y)| {
                let (lo, hi) = (self.indptr[r], self.indptr[r + 1]);
                *y = crate::solve::row_dot(&self.indices[lo..hi], &self.data[lo..hi], x);
            });
    }
    fn diagonal(&self) -> Vec<f64> {
        (0..self.n)
            .map(|r| {
                (self.indptr[r]..self.indptr[r + 1])
                    .find(|&k| self.indices[k] as usize == r)
                    .map_or(0.0, |k| self.data[k])
            })
            .collect()
    }
    fn csr(&self) -> Option<(&[usize], &[u32], &[f64])> {
        Some((&self.indptr, &self.indices, &self.data))
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
        let n = if dim == 2 { 9 } else { 27 };
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
    /// Per element: bit c (c < 8) for a boundary corner c, bit 8 + i for a sample i that takes
    /// the feature weight.
    pub masks: Vec<u64>,
    /// (G^d, G^r), row-major 3^d × 3^d, per mask.
    pub cache: HashMap<u64, (Vec<f64>, Vec<f64>)>,
}

/// Position weight of sample `i` (lattice point `l`) of an element with weight mask `mask`.
fn sample_weight(w: &FitWeights, mask: u64, i: usize, l: [usize; 3], corner: bool) -> f64 {
    size_scale(mask) * sample_weight_unscaled(w, mask, i, l, corner)
}

/// Bit offset of an element's size level in its weight mask.
const LEVEL_SHIFT: u32 = 48;

/// The weight factor 4^k of size level k (bits 48.. of the mask; see [`size_levels`]).
fn size_scale(mask: u64) -> f64 {
    let k = (mask >> LEVEL_SHIFT) as i32;
    (4.0f64).powi(k)
}

/// The size level stored in a weight mask.
pub fn mask_level(mask: u64) -> u16 {
    (mask >> LEVEL_SHIFT) as u16
}

fn sample_weight_unscaled(w: &FitWeights, mask: u64, i: usize, l: [usize; 3], corner: bool) -> f64 {
    if mask & (1 << (8 + i)) != 0 {
        w.feature
    } else if !corner {
        w.midpoint
    } else if mask & (1 << corner_of(l)) != 0 {
        w.boundary_corner
    } else {
        w.corner
    }
}

/// Size levels below this many halvings of the largest element's size get no extra weight, so
/// meshes whose element sizes vary by less than 2^`LEVEL_DEAD_ZONE` keep plain weights.
const LEVEL_DEAD_ZONE: f64 = 2.0;

/// Per element, the size level k = max(0, ⌊log₂(h_max / h_e)⌋ − `LEVEL_DEAD_ZONE`), h_e the
/// element's shortest edge: its samples are weighted by 4^k ≈ (h_max / h_e)², so the fit
/// balances errors relative to the size of the element they distort. With plain weights the
/// least-squares error of a large far-field cell leaks into the thin boundary-layer cells next
/// to it (on a C-grid with wall cells 10⁻⁵ and far-field cells 10² long, errors of 10⁻² in cells
/// 10⁻⁵ thin).
pub fn size_levels(mesh: &LinearMesh) -> Vec<u16> {
    let edges: &[[usize; 2]] = if mesh.dim == 2 {
        &[[0, 1], [1, 2], [2, 3], [3, 0]]
    } else {
        &crate::mesh::topology::HEX_EDGES
    };
    let h: Vec<f64> = (0..mesh.n_elements())
        .into_par_iter()
        .map(|e| {
            let x = mesh.element_coords(e);
            edges
                .iter()
                .map(|&[a, b]| vec3::norm(vec3::sub(x[a], x[b])))
                .fold(f64::INFINITY, f64::min)
        })
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
const MAX_LEVEL: u16 = 200;

/// Per control point, 2^−k with k the largest size level of the elements using it, or `None`
/// when every level is 0. The fit solves D K D y = D b with D = diag(2^−k) and δ = D y: the
/// same iterates under (block) Jacobi preconditioning, but the residual that stops CG then
/// weighs every control point relative to its own elements' size, so far-field rows do not
/// stop it before the boundary-layer rows have converged (powers of 2 keep K's values exact).
fn control_point_scales(space: &dyn FitSpace, levels: &[u16]) -> Option<Vec<f64>> {
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
        let (indptr, indices) = (&self.indptr, &self.indices);
        crate::solve::block_jacobi::split_at_offsets(&mut self.data, indptr)
            .into_par_iter()
            .enumerate()
            .for_each(|(r, row)| {
                let cols = &indices[indptr[r]..indptr[r + 1]];
                for (v, &c) in row.iter_mut().zip(cols) {
                    *v *= d[r] * d[c as usize];
                }
            });
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
        let nb = if dim == 2 { 9 } else { 27 };
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
        let levels = size_levels(mesh);
        let masks: Vec<u64> = (0..space.n_elements())
            .map(|e| {
                let mut m = 0u64;
                for (c, &v) in mesh.element(e).iter().enumerate() {
                    if topo.vertex_on_boundary[v as usize] {
                        m |= 1 << c;
                    }
                }
                if let Some(f) = features {
                    m |= features::sample_mask(f, mesh, e) << 8;
                }
                m | (levels[e] as u64) << LEVEL_SHIFT
            })
            .collect();
        let mut cache = HashMap::new();
        for &m in &masks {
            cache.entry(m).or_insert_with(|| g_of(m));
        }
        ElementBlocks { masks, cache }
    }
}

/// K applied without assembling it: y = Σ_e E_eᵀ G_e E_e x, element by element (the
/// alternative to [`NormalMatrix`]; see BENCHMARKS.md for the measured comparison).
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
        let nb = if self.space.dim() == 2 { 9 } else { 27 };
        let sum = (0..self.rows.len())
            .into_par_iter()
            .fold(
                || vec![[0.0; 3]; n],
                |mut acc, e| {
                    let (o, c, w) = &self.rows[e];
                    let mut b = [[0.0; 3]; 27];
                    for i in 0..nb {
                        for k in o[i]..o[i + 1] {
                            let xc = x[c[k] as usize];
                            for d in 0..3 {
                                b[i][d] += w[k] * xc[d];
                            }
                        }
                    }
                    let (gd, gr) = &self.blocks.cache[&self.blocks.masks[e]];
                    for i in 0..nb {
                        let mut z = [0.0; 3];
                        for j in 0..nb {
                            let g = gd[i * nb + j] + gr[i * nb + j];
                            for d in 0..3 {
                                z[d] += g * b[j][d];
                            }
                        }
                        for k in o[i]..o[i + 1] {
                            let t = &mut acc[c[k] as usize];
                            for d in 0..3 {
                                t[d] += w[k] * z[d];
                            }
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
        let nb = if self.space.dim() == 2 { 9 } else { 27 };
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

/// Assemble K and the right-hand side of the displacement system (F − K C0).
pub fn assemble(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    assemble_with_targets(space, mesh, topo, w, None)
}

/// [`assemble`] with the midpoint targets moved by `smooth` (None: the chords).
pub fn assemble_with_targets(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    smooth: Option<&SmoothTargets>,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    assemble_with_features(space, mesh, topo, w, smooth, None)
}

/// The normal equations of the fit described by `params`: its targets (chords, or the smooth
/// reconstruction per feature patch), weights and features.
pub fn normal_equations(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    normal_equations_with(
        space,
        mesh,
        topo,
        params,
        smooth_targets(mesh, topo, params).as_ref(),
    )
}

/// The smooth-boundary models of the fit described by `params` (`None` with chord targets).
pub fn smooth_targets(
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
) -> Option<SmoothTargets> {
    match params.targets {
        FitTargets::Chords => None,
        FitTargets::Smooth(p) => Some(SmoothTargets::build_with_features(
            mesh,
            topo,
            &p,
            params.features.as_deref(),
        )),
    }
}

/// [`normal_equations`] with the smooth targets built already ([`smooth_targets`]).
pub fn normal_equations_with(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    smooth: Option<&SmoothTargets>,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    assemble_with_features(
        space,
        mesh,
        topo,
        &params.weights,
        smooth,
        params.features.as_deref(),
    )
}

/// The fit's targets as a conforming quadratic map: per element the multilinear lattice moved
/// by the smooth-target corrections (chords without them), interpolated at {0, ½, 1}^d and
/// written in Bernstein form. Every target depends only on its entity (its vertices and their
/// models), so neighbours agree on shared points. It is the straight elevation plus the
/// boundary's curvature carried into the layers next to it: the middle state of the certified
/// blend (`crate::validity::blend`).
pub struct TargetMap<'a> {
    pub mesh: &'a LinearMesh,
    pub topo: &'a Topology,
    pub smooth: Option<&'a SmoothTargets>,
}

impl crate::sample::BezierElements for TargetMap<'_> {
    fn dim(&self) -> usize {
        self.mesh.dim
    }
    fn n_elements(&self) -> usize {
        self.mesh.n_elements()
    }
    fn bezier_net(&self, e: usize) -> [[f64; 3]; 27] {
        let dim = self.mesh.dim;
        let mut v = rhs::multilinear_lattice(dim, &self.mesh.element_coords(e));
        if let Some(t) = self.smooth {
            let shift = t.corrections_at(self.mesh, self.topo, e, &v);
            for (p, s) in v.iter_mut().zip(shift) {
                *p = vec3::add(*p, s);
            }
        }
        // Values at {0, ½, 1} to Bernstein points, line by line: b₁ = 2 v(½) − (v₀ + v₁)/2.
        rhs::map_lines(dim, &mut v, |[a, m, c]| {
            [
                a,
                std::array::from_fn(|k| 2.0 * m[k] - 0.5 * (a[k] + c[k])),
                c,
            ]
        });
        v
    }
}

/// [`assemble_with_targets`] with the samples on the sharp `features` weighted by
/// [`FitWeights::feature`].
pub fn assemble_with_features(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    w: &FitWeights,
    smooth: Option<&SmoothTargets>,
    features: Option<&crate::mesh::features::Features>,
) -> (NormalMatrix, Vec<[f64; 3]>) {
    let blocks = ElementBlocks::with_features(space, mesh, topo, w, features);
    let rhs = rhs::displacement_rhs(space, mesh, topo, w, &blocks.masks, smooth);
    let k = assembly::assemble_matrix(space, &blocks);
    (k, rhs)
}

/// Solve the least-squares fit; returns the fitted control points C*.
pub fn fit(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    mut progress: impl FnMut(usize, f64),
) -> Result<(Vec<[f64; 3]>, FitInfo), CgError> {
    fit_with(space, mesh, topo, params, |k, rhs, delta, cg| {
        pcg(k, rhs, delta, cg, &mut progress)
    })
}

/// [`fit`] with the normal equations solved by `solve(matrix, rhs, delta, cg)` (the
/// unknowns are displacements from the initial control points, starting at 0), e.g. the GPU
/// solver `crate::gpu::cg::pcg`.
pub fn fit_with(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    solve: impl FnOnce(
        &NormalMatrix,
        &[[f64; 3]],
        &mut [[f64; 3]],
        &crate::solve::CgParams,
    ) -> Result<crate::solve::CgInfo, CgError>,
) -> Result<(Vec<[f64; 3]>, FitInfo), CgError> {
    fit_with_targets(
        space,
        mesh,
        topo,
        params,
        smooth_targets(mesh, topo, params).as_ref(),
        solve,
    )
}

/// [`fit_with`] given the smooth targets ([`smooth_targets`]).
pub fn fit_with_targets(
    space: &dyn FitSpace,
    mesh: &LinearMesh,
    topo: &Topology,
    params: &FitParams,
    smooth: Option<&SmoothTargets>,
    solve: impl FnOnce(
        &NormalMatrix,
        &[[f64; 3]],
        &mut [[f64; 3]],
        &crate::solve::CgParams,
    ) -> Result<crate::solve::CgInfo, CgError>,
) -> Result<(Vec<[f64; 3]>, FitInfo), CgError> {
    let t = std::time::Instant::now();
    let (mut k, mut rhs) = normal_equations_with(space, mesh, topo, params, smooth);
    let scale = control_point_scales(space, &size_levels(mesh));
    if let Some(d) = &scale {
        k.scale_symmetric(d);
        for (r, &d) in rhs.iter_mut().zip(d) {
            *r = r.map(|x| d * x);
        }
    }
    let assembly_seconds = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let mut delta = vec![[0.0; 3]; k.n];
    let cg = solve(&k, &rhs, &mut delta, &params.cg)?;
    if let Some(d) = &scale {
        for (x, &d) in delta.iter_mut().zip(d) {
            *x = x.map(|x| d * x);
        }
    }
    let solve_seconds = t.elapsed().as_secs_f64();
    let c: Vec<[f64; 3]> = space
        .control_points()
        .iter()
        .zip(&delta)
        .map(|(c, d)| [c[0] + d[0], c[1] + d[1], c[2] + d[2]])
        .collect();
    Ok((
        c,
        FitInfo {
            cg,
            unknowns: k.n,
            nonzeros: k.data.len(),
            assembly_seconds,
            solve_seconds,
        },
    ))
}

impl FitSpace for crate::spline::SplineSpace {
    fn dim(&self) -> usize {
        self.dim
    }
    fn n_elements(&self) -> usize {
        crate::spline::SplineSpace::n_elements(self)
    }
    fn control_points(&self) -> &[[f64; 3]] {
        &self.control_points
    }
    fn element_rows(
        &self,
        e: usize,
        offsets: &mut Vec<usize>,
        cols: &mut Vec<u32>,
        weights: &mut Vec<f64>,
    ) {
        let mut rows = crate::spline::ElementRows::default();
        self.extraction.rows(e, &mut rows);
        *offsets = rows.offsets;
        *cols = rows.cols;
        *weights = rows.weights;
    }
    fn bezier_net_with(&self, e: usize, cps: &[[f64; 3]]) -> [[f64; 3]; 27] {
        self.element_bezier_with(e, cps)
    }
    /// By sum factorisation: E_e = (M_z ⊗ M_y ⊗ M_x) N_e with N_e the local nodes' control
    /// point entries, so E_eᵀ f applies the transposed 1D matrices direction by direction
    /// (3 · 3^d · 3 multiply-adds each) and then N_eᵀ, instead of expanding the rows.
    fn add_transposed(&self, e: usize, f: &[[f64; 3]; 27], out: &mut Vec<(u32, [f64; 3])>) {
        let x = &self.extraction;
        let m = x.matrices(e);
        let n = x.n_local();
        let mut t = *f;
        for (d, md) in m.iter().enumerate().take(self.dim) {
            let stride = [1, 3, 9][d];
            let mut u = [[0.0; 3]; 27];
            for (o, u) in u.iter_mut().enumerate().take(n) {
                let l = (o / stride) % 3;
                let base = o - l * stride;
                for (b, row) in md.iter().enumerate() {
                    let w = row[l];
                    if w != 0.0 {
                        let v = t[base + b * stride];
                        for c in 0..3 {
                            u[c] += w * v[c];
                        }
                    }
                }
            }
            t = u;
        }
        for (l, &node) in x.element_nodes(e).iter().enumerate() {
            for (g, w) in x.node_entries(node) {
                out.push((g, t[l].map(|v| w * v)));
            }
        }
    }
    /// Elements whose local nodes are all plain control points (spline elements, and Q2
    /// elements made only of own nodes): E_e = (M_z ⊗ M_y ⊗ M_x) · selection, keyed by the
    /// three 1D operators.
    fn element_pattern(&self, e: usize, ids: &mut Vec<u32>) -> Option<u64> {
        let x = &self.extraction;
        let nodes = x.element_nodes(e);
        if nodes.iter().any(|&n| n as usize >= x.n_control) {
            return None;
        }
        let mut sorted = [0u32; 27];
        let sorted = &mut sorted[..nodes.len()];
        sorted.copy_from_slice(nodes);
        sorted.sort_unstable();
        if sorted.windows(2).any(|w| w[0] == w[1]) {
            return None;
        }
        ids.clear();
        ids.extend_from_slice(nodes);
        Some(x.ops[e].iter().fold(0u64, |k, op| k * 8 + *op as u64))
    }
}
