//! Elastic-analogy curving (paper §2.5), the baseline the IGA method is compared with.
//!
//! Input: the straight-sided order-p mesh of the input ([`HighOrderMesh`], the reference
//! configuration), and a curved mesh with the same numbering whose boundary nodes are the target
//! (the IGA-fitted spline sampled at order p, so both methods share the boundary). Output: the
//! straight mesh with every boundary node moved onto the target and every interior node moved by
//! the displacement that minimises the linear-elastic energy with that boundary displacement
//! prescribed, and an [`ElasticInfo`].
//!
//! Discretisation: order-p tensor-product Lagrange elements on the straight lattice nodes
//! (isoparametric), (p+1)^d Gauss points per element, isotropic material (E, ν). Dirichlet
//! nodes are eliminated: the unknowns are the free nodes' d displacement components, the matrix
//! is a block CSR of d×d nodal blocks (assembled in parallel with atomic adds, like the fit's
//! normal matrix), and K_ff u_f = −K_fb u_b is solved by sparse Cholesky
//! ([`crate::solve::direct`]) while the factor fits [`CHOLESKY_MAX_FACTOR_ENTRIES`], otherwise
//! by [`crate::solve::pcg_coupled`] with a nodal block-Jacobi preconditioner (or pointwise
//! Jacobi, or symmetric block Gauss–Seidel). The factorisation is what makes boundary-layer
//! meshes solvable at all: their thin cells make K as ill-conditioned as the square of the
//! cells' aspect ratio.
//!
//! Invariants: with zero boundary displacement the mesh is unchanged (u = 0 exactly); a
//! displacement that is linear in x on the boundary is reproduced exactly inside (patch test),
//! up to the CG tolerance.

use crate::fit::assembly::atomic_add;
use crate::math::lagrange::lagrange_1d;
use crate::math::quadrature::gauss_legendre;
use crate::mesh::HighOrderMesh;
use crate::mesh::high_order::lattice_point;
use crate::params::{ParamError, num};
use crate::solve::direct::CholeskyPattern;
use crate::solve::{CgError, CgInfo, CgMonitor, CgParams, LinOp, Preconditioner, pcg_coupled};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Highest element order of the elastic solve (the dense element matrix grows as (p+1)^{2d}).
pub const MAX_ELASTIC_ORDER: usize = 6;

/// Preconditioner of the elastic CG solve (`--elastic-preconditioner`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ElasticPreconditioner {
    /// The inverse of the diagonal of K.
    Jacobi,
    /// The inverse of each node's d×d diagonal block of K (couples a node's components,
    /// which matters as ν → 0.5).
    BlockJacobi,
    /// Symmetric block Gauss–Seidel: a forward then a backward sweep over the nodes with the
    /// d×d diagonal blocks inverted (SSOR with ω = 1; sequential, about one matrix product).
    BlockSgs,
}

/// How the elastic system is solved (`--elastic-solver`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ElasticSolver {
    /// Sparse Cholesky when its factor fits [`CHOLESKY_MAX_FACTOR_ENTRIES`], CG otherwise.
    Auto,
    /// Preconditioned CG ([`ElasticPreconditioner`]).
    Cg,
    /// Sparse Cholesky whatever the size of its factor.
    Cholesky,
}

/// Largest Cholesky factor `--elastic-solver auto` computes: 2.4 × 10⁸ entries (1.9 GB).
///
/// The elastic system of a boundary-layer mesh is as ill-conditioned as its cells are thin
/// (condition number ∝ aspect ratio², 10⁸ for the 10⁴ aspect ratios of an airfoil's wall
/// cells), which block-Jacobi CG does not overcome in any affordable number of iterations;
/// the factorisation's cost does not depend on it. Every 2D mesh and the 3D meshes of up to
/// some 10⁵ order-2 nodes stay under the bound; larger 3D systems take CG.
pub const CHOLESKY_MAX_FACTOR_ENTRIES: usize = 240_000_000;

/// Largest system `--elastic-solver auto` analyses for a factorisation at all (scalar
/// unknowns): the ordering alone grows superlinearly, and beyond it the factor of a 3D
/// system is far over [`CHOLESKY_MAX_FACTOR_ENTRIES`].
const CHOLESKY_MAX_UNKNOWNS: usize = 6_000_000;

/// Material and solver parameters.
#[derive(Clone, Copy, Debug)]
pub struct ElasticParams {
    /// Young's modulus E (> 0).
    pub young: f64,
    /// Poisson's ratio ν (−1 < ν < 0.5).
    pub poisson: f64,
    pub cg: CgParams,
    pub preconditioner: ElasticPreconditioner,
    pub solver: ElasticSolver,
    /// Jacobian-based stiffening exponent χ ≥ 0: the stiffness at a point is scaled by
    /// |det J|^−χ of the straight mesh there (0: the paper's homogeneous material).
    pub stiffening: f64,
}

impl Default for ElasticParams {
    /// The paper's material: E = 1.5, ν = 0.49.
    fn default() -> Self {
        ElasticParams {
            young: 1.5,
            poisson: 0.49,
            cg: CgParams::default(),
            preconditioner: ElasticPreconditioner::BlockJacobi,
            solver: ElasticSolver::Auto,
            stiffening: 0.0,
        }
    }
}

impl ElasticParams {
    /// A positive Young's modulus, a Poisson's ratio in (-1, 0.5), and the CG's parameters.
    pub fn check(&self) -> Result<(), ParamError> {
        if !(self.young.is_finite() && self.young > 0.0) {
            return Err(ParamError::new(
                "--young",
                num(self.young),
                "Young's modulus must be positive and finite",
            ));
        }
        if !(self.poisson.is_finite() && self.poisson > -1.0 && self.poisson < 0.5) {
            return Err(ParamError::new(
                "--poisson",
                num(self.poisson),
                "Poisson's ratio must be in (-1, 0.5)",
            ));
        }
        if !(self.stiffening.is_finite() && self.stiffening >= 0.0) {
            return Err(ParamError::new(
                "--elastic-stiffening",
                num(self.stiffening),
                "the stiffening exponent must be non-negative and finite",
            ));
        }
        self.cg.check()
    }
}

/// What the elastic solve did (the `elastic` object of `curve --report`).
#[deny(missing_docs)]
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ElasticInfo {
    /// Young's modulus of the pseudo-material.
    pub young: f64,
    /// Poisson's ratio of the pseudo-material.
    pub poisson: f64,
    /// CG preconditioner (`--elastic-preconditioner`).
    pub preconditioner: ElasticPreconditioner,
    /// The solver that ran: `cg`, or `cholesky` (then `cg.iterations` is 0 and
    /// `cg.rel_residual` the residual measured after the solve).
    pub solver: ElasticSolver,
    /// Entries of the Cholesky factor (0 when CG ran).
    pub factor_entries: usize,
    /// Nodes moved back towards the straight mesh because an element of theirs was not
    /// certified valid ([`hold_back_invalid`]); 0 when the elastic mesh is valid as solved.
    pub held_back_nodes: usize,
    /// Of those, nodes on the boundary: there the mesh leaves the prescribed boundary.
    pub held_back_boundary_nodes: usize,
    /// The smallest fraction of its elastic displacement a node kept (1 when none was held).
    pub min_displacement_fraction: f64,
    /// Scalar unknowns (free nodes × d).
    pub unknowns: usize,
    /// Prescribed (boundary) nodes.
    pub prescribed_nodes: usize,
    /// Stored d×d blocks of K_ff.
    pub nonzero_blocks: usize,
    /// The solve's iterations and residual.
    pub cg: CgInfo,
    /// Seconds spent assembling the stiffness matrix.
    pub assembly_seconds: f64,
    /// Seconds spent solving.
    pub solve_seconds: f64,
}

/// Failures of the elastic solve.
#[derive(Clone, Debug, thiserror::Error)]
pub enum ElasticError {
    #[error("elastic material: {0}")]
    Material(String),
    #[error("elastic analogy supports orders 1..={MAX_ELASTIC_ORDER}, not {0}")]
    Order(usize),
    #[error("elastic solve: {0}")]
    Solve(#[from] CgError),
}

/// Lamé parameters (λ, μ) of (E, ν).
fn lame(young: f64, poisson: f64) -> Result<(f64, f64), ElasticError> {
    if !(young > 0.0 && young.is_finite()) {
        return Err(ElasticError::Material(format!(
            "Young's modulus must be positive and finite, got {young}"
        )));
    }
    if !(poisson > -1.0 && poisson < 0.5) {
        return Err(ElasticError::Material(format!(
            "Poisson's ratio must lie in (-1, 0.5), got {poisson}"
        )));
    }
    let lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
    let mu = young / (2.0 * (1.0 + poisson));
    Ok((lambda, mu))
}

/// Reference derivatives of the (p+1)^d Lagrange basis at the Gauss points, with weights.
struct Quadrature {
    /// Per point: weight, then for each node its d reference derivatives.
    weights: Vec<f64>,
    grads: Vec<[f64; 3]>,
    n_nodes: usize,
}

impl Quadrature {
    fn new(dim: usize, p: usize) -> Quadrature {
        let m = p + 1;
        let (xs, ws) = gauss_legendre(m);
        let mut v = vec![vec![0.0; m]; m];
        let mut d = vec![vec![0.0; m]; m];
        for g in 0..m {
            lagrange_1d(p, xs[g], &mut v[g], &mut d[g]);
        }
        let n_nodes = m.pow(dim as u32);
        let (mut weights, mut grads) = (Vec::new(), Vec::new());
        for q in 0..n_nodes {
            let g = lattice_point(p, dim, q);
            weights.push((0..dim).map(|k| ws[g[k]]).product());
            for a in 0..n_nodes {
                let l = lattice_point(p, dim, a);
                let mut grad = [0.0; 3];
                for c in 0..dim {
                    grad[c] = (0..dim)
                        .map(|k| if k == c { d[g[k]][l[k]] } else { v[g[k]][l[k]] })
                        .product();
                }
                grads.push(grad);
            }
        }
        Quadrature {
            weights,
            grads,
            n_nodes,
        }
    }
}

/// Invert a d×d matrix (d = 2, 3) held in the top-left of `a`; returns det and the inverse.
fn invert(dim: usize, a: &[[f64; 3]; 3]) -> (f64, [[f64; 3]; 3]) {
    let mut inv = [[0.0; 3]; 3];
    if dim == 2 {
        let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
        inv[0][0] = a[1][1] / det;
        inv[0][1] = -a[0][1] / det;
        inv[1][0] = -a[1][0] / det;
        inv[1][1] = a[0][0] / det;
        (det, inv)
    } else {
        let c = |i: usize, j: usize| {
            let (i1, i2, j1, j2) = ((i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3);
            a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1]
        };
        let det = a[0][0] * c(0, 0) + a[0][1] * c(0, 1) + a[0][2] * c(0, 2);
        for i in 0..3 {
            for j in 0..3 {
                inv[j][i] = c(i, j) / det;
            }
        }
        (det, inv)
    }
}

/// Dense element stiffness, index ((a·d + i)·n·d + b·d + j) for nodes a, b and components i, j.
fn element_stiffness(
    dim: usize,
    quad: &Quadrature,
    x: &[[f64; 3]],
    lambda: f64,
    mu: f64,
    stiffening: f64,
) -> Vec<f64> {
    let n = quad.n_nodes;
    let nd = n * dim;
    let mut k = vec![0.0; nd * nd];
    let mut g = vec![[0.0; 3]; n];
    for (q, &w) in quad.weights.iter().enumerate() {
        let ref_grads = &quad.grads[q * n..(q + 1) * n];
        // J[r][c] = ∂x_r/∂ξ_c.
        let mut jac = [[0.0; 3]; 3];
        for (a, rg) in ref_grads.iter().enumerate() {
            for r in 0..dim {
                for c in 0..dim {
                    jac[r][c] += x[a][r] * rg[c];
                }
            }
        }
        let (det, inv) = invert(dim, &jac);
        // ∇_x N = J⁻ᵀ ∇_ξ N.
        for (a, rg) in ref_grads.iter().enumerate() {
            g[a] = [0.0; 3];
            for i in 0..dim {
                g[a][i] = (0..dim).map(|c| inv[c][i] * rg[c]).sum();
            }
        }
        // Jacobian-based stiffening: the energy density weighted by |det J|^−χ, so that small
        // (thin) cells are stiffer and move with the boundary instead of absorbing its motion.
        let f = if stiffening == 0.0 {
            w * det.abs()
        } else {
            w * det.abs().powf(1.0 - stiffening)
        };
        for a in 0..n {
            for b in 0..n {
                let dot: f64 = (0..dim).map(|i| g[a][i] * g[b][i]).sum();
                for i in 0..dim {
                    let row = (a * dim + i) * nd + b * dim;
                    for j in 0..dim {
                        let mut v = lambda * g[a][i] * g[b][j] + mu * g[a][j] * g[b][i];
                        if i == j {
                            v += mu * dot;
                        }
                        k[row + j] += f * v;
                    }
                }
            }
        }
    }
    k
}

/// K_ff in block CSR: d×d blocks per (free node, free node).
pub struct BlockMatrix {
    dim: usize,
    indptr: Vec<usize>,
    indices: Vec<u32>,
    /// d·d values per block, row-major.
    values: Vec<f64>,
}

impl BlockMatrix {
    fn block(&self, k: usize) -> &[f64] {
        let dd = self.dim * self.dim;
        &self.values[k * dd..(k + 1) * dd]
    }
    fn diagonal_block(&self, row: usize) -> &[f64] {
        let cols = &self.indices[self.indptr[row]..self.indptr[row + 1]];
        let at = cols.binary_search(&(row as u32)).expect("diagonal block");
        self.block(self.indptr[row] + at)
    }
}

impl BlockMatrix {
    /// The same matrix with one row and column per scalar unknown (`node · d + component`);
    /// columns stay sorted since a block's columns are consecutive.
    fn scalar_csr(&self) -> ScalarCsr {
        let d = self.dim;
        let n = self.nrows();
        let nnz = self.indices.len() * d * d;
        let mut out = ScalarCsr {
            indptr: Vec::with_capacity(n * d + 1),
            indices: Vec::with_capacity(nnz),
            data: Vec::with_capacity(nnz),
        };
        out.indptr.push(0);
        for r in 0..n {
            for i in 0..d {
                for k in self.indptr[r]..self.indptr[r + 1] {
                    let c = self.indices[k] as usize;
                    let b = self.block(k);
                    for j in 0..d {
                        out.indices.push((c * d + j) as u32);
                        out.data.push(b[i * d + j]);
                    }
                }
                out.indptr.push(out.indices.len());
            }
        }
        out
    }
}

impl LinOp for BlockMatrix {
    fn nrows(&self) -> usize {
        self.indptr.len() - 1
    }
    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        let d = self.dim;
        y.par_iter_mut().enumerate().for_each(|(r, y)| {
            *y = [0.0; 3];
            for k in self.indptr[r]..self.indptr[r + 1] {
                let xc = x[self.indices[k] as usize];
                let b = self.block(k);
                for i in 0..d {
                    for j in 0..d {
                        y[i] += b[i * d + j] * xc[j];
                    }
                }
            }
        });
    }
    /// Per node, the mean of its block's diagonal.
    fn diagonal(&self) -> Vec<f64> {
        let d = self.dim;
        (0..self.nrows())
            .map(|r| {
                let b = self.diagonal_block(r);
                (0..d).map(|i| b[i * d + i]).sum::<f64>() / d as f64
            })
            .collect()
    }
}

/// Nodal (block) Jacobi: per node a 3×3 matrix applied to the residual.
struct NodalPreconditioner(Vec<[[f64; 3]; 3]>);

impl NodalPreconditioner {
    fn new(k: &BlockMatrix, kind: ElasticPreconditioner) -> Result<Self, CgError> {
        let d = k.dim;
        let mut out = Vec::with_capacity(k.nrows());
        for r in 0..k.nrows() {
            let b = k.diagonal_block(r);
            let mut a = [[0.0; 3]; 3];
            for i in 0..d {
                for j in 0..d {
                    a[i][j] = b[i * d + j];
                }
            }
            if let Some(i) = (0..d).find(|&i| !(a[i][i] > 0.0)) {
                return Err(CgError::BadDiagonal {
                    row: r * d + i,
                    value: a[i][i],
                });
            }
            out.push(match kind {
                ElasticPreconditioner::Jacobi => {
                    let mut m = [[0.0; 3]; 3];
                    for i in 0..d {
                        m[i][i] = 1.0 / a[i][i];
                    }
                    m
                }
                ElasticPreconditioner::BlockJacobi | ElasticPreconditioner::BlockSgs => {
                    invert(d, &a).1
                }
            });
        }
        Ok(NodalPreconditioner(out))
    }
}

impl Preconditioner for NodalPreconditioner {
    fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
        z.par_iter_mut()
            .zip(r.par_iter().zip(self.0.par_iter()))
            .for_each(|(z, (r, m))| {
                for i in 0..3 {
                    z[i] = m[i][0] * r[0] + m[i][1] * r[1] + m[i][2] * r[2];
                }
            });
    }
}

/// Symmetric block Gauss–Seidel: z = (D + U)⁻¹ D (D + L)⁻¹ r, with D⁻¹ from a
/// [`NodalPreconditioner`] of block-Jacobi kind.
struct BlockSgs<'a> {
    k: &'a BlockMatrix,
    dinv: NodalPreconditioner,
}

impl Preconditioner for BlockSgs<'_> {
    fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
        let (k, d) = (self.k, self.k.dim);
        let n = k.nrows();
        let forward = |i: usize, mut rhs: [f64; 3], z: &[[f64; 3]]| -> [f64; 3] {
            for at in k.indptr[i]..k.indptr[i + 1] {
                let j = k.indices[at] as usize;
                if j < i {
                    let b = k.block(at);
                    for a in 0..d {
                        for c in 0..d {
                            rhs[a] -= b[a * d + c] * z[j][c];
                        }
                    }
                }
            }
            let m = &self.dinv.0[i];
            std::array::from_fn(|a| (0..3).map(|c| m[a][c] * rhs[c]).sum())
        };
        // Forward: (D + L) w = r.
        for i in 0..n {
            z[i] = forward(i, r[i], z);
        }
        // Backward: (D + U) z = D w, i.e. z_i = w_i − D_i⁻¹ Σ_{j>i} K_ij z_j.
        for i in (0..n).rev() {
            let m = &self.dinv.0[i];
            let w = z[i];
            let mut sum = [0.0; 3];
            for at in k.indptr[i]..k.indptr[i + 1] {
                let j = k.indices[at] as usize;
                if j > i {
                    let b = k.block(at);
                    for a in 0..d {
                        for c in 0..d {
                            sum[a] += b[a * d + c] * z[j][c];
                        }
                    }
                }
            }
            z[i] = std::array::from_fn(|a| w[a] - (0..3).map(|c| m[a][c] * sum[c]).sum::<f64>());
        }
    }
}

/// Marks a prescribed node in the free numbering.
const FIXED: u32 = u32::MAX;

/// Free numbering of the nodes: the free index of each node, or [`FIXED`]; and the count.
fn free_numbering(prescribed: &[Option<[f64; 3]>]) -> (Vec<u32>, usize) {
    let mut free = vec![FIXED; prescribed.len()];
    let mut nf = 0u32;
    for (n, slot) in free.iter_mut().enumerate() {
        if prescribed[n].is_none() {
            *slot = nf;
            nf += 1;
        }
    }
    (free, nf as usize)
}

/// Block sparsity of K_ff: row (free node) → sorted free nodes of the elements around it, as
/// CSR `indptr`, `indices`.
fn pattern(reference: &HighOrderMesh, free: &[u32], nf: usize) -> (Vec<usize>, Vec<u32>) {
    let ne = reference.n_elements();
    let mut count = vec![0usize; nf + 1];
    for &n in &reference.elements {
        let f = free[n as usize];
        if f != FIXED {
            count[f as usize + 1] += 1;
        }
    }
    for i in 0..nf {
        count[i + 1] += count[i];
    }
    let mut around = vec![0u32; count[nf]];
    let mut fill = count.clone();
    for e in 0..ne {
        for &n in reference.element(e) {
            let f = free[n as usize];
            if f != FIXED {
                around[fill[f as usize]] = e as u32;
                fill[f as usize] += 1;
            }
        }
    }
    let rows: Vec<Vec<u32>> = (0..nf)
        .into_par_iter()
        .map(|r| {
            let mut cols: Vec<u32> = around[count[r]..count[r + 1]]
                .iter()
                .flat_map(|&e| reference.element(e as usize))
                .map(|&n| free[n as usize])
                .filter(|&f| f != FIXED)
                .collect();
            cols.sort_unstable();
            cols.dedup();
            cols
        })
        .collect();
    let mut indptr = Vec::with_capacity(nf + 1);
    indptr.push(0);
    for r in &rows {
        indptr.push(indptr.last().unwrap() + r.len());
    }
    (indptr, rows.into_iter().flatten().collect())
}

/// Assemble K_ff on the pattern and the load −K_fb u_b (element matrices in parallel, atomic
/// adds into the shared blocks).
fn assemble(
    reference: &HighOrderMesh,
    prescribed: &[Option<[f64; 3]>],
    free: &[u32],
    (indptr, indices): (Vec<usize>, Vec<u32>),
    (lambda, mu, stiffening): (f64, f64, f64),
) -> (BlockMatrix, Vec<[f64; 3]>) {
    let (dim, p) = (reference.dim, reference.order);
    let nf = indptr.len() - 1;
    let npe = reference.nodes_per_element();
    let dd = dim * dim;
    let values: Vec<AtomicU64> = (0..indices.len() * dd).map(|_| AtomicU64::new(0)).collect();
    let rhs: Vec<[AtomicU64; 3]> = (0..nf).map(|_| Default::default()).collect();
    let quad = Quadrature::new(dim, p);
    (0..reference.n_elements()).into_par_iter().for_each(|e| {
        let ids = reference.element(e);
        if ids.iter().all(|&n| free[n as usize] == FIXED) {
            return;
        }
        let x: Vec<[f64; 3]> = ids.iter().map(|&n| reference.nodes[n as usize]).collect();
        let k = element_stiffness(dim, &quad, &x, lambda, mu, stiffening);
        let nd = npe * dim;
        for (a, &na) in ids.iter().enumerate() {
            let r = free[na as usize];
            if r == FIXED {
                continue;
            }
            let r = r as usize;
            let cols = &indices[indptr[r]..indptr[r + 1]];
            let mut load = [0.0; 3];
            for (b, &nb) in ids.iter().enumerate() {
                match prescribed[nb as usize] {
                    None => {
                        let c = free[nb as usize];
                        let at = indptr[r] + cols.binary_search(&c).expect("column in pattern");
                        for i in 0..dim {
                            for j in 0..dim {
                                let v = k[(a * dim + i) * nd + b * dim + j];
                                atomic_add(&values[at * dd + i * dim + j], v);
                            }
                        }
                    }
                    Some(u) => {
                        for i in 0..dim {
                            for j in 0..dim {
                                load[i] -= k[(a * dim + i) * nd + b * dim + j] * u[j];
                            }
                        }
                    }
                }
            }
            for i in 0..dim {
                if load[i] != 0.0 {
                    atomic_add(&rhs[r][i], load[i]);
                }
            }
        }
    });
    let matrix = BlockMatrix {
        dim,
        indptr,
        indices,
        values: values
            .into_iter()
            .map(|v| f64::from_bits(v.into_inner()))
            .collect(),
    };
    let b: Vec<[f64; 3]> = rhs
        .iter()
        .map(|r| std::array::from_fn(|i| f64::from_bits(r[i].load(Ordering::Relaxed))))
        .collect();
    (matrix, b)
}

/// Solve the elasticity problem on the order-p mesh `reference` with the displacements of the
/// nodes in `prescribed` fixed (`None`: free). Returns the displacement of every node.
pub fn solve_displacement(
    reference: &HighOrderMesh,
    prescribed: &[Option<[f64; 3]>],
    params: &ElasticParams,
) -> Result<(Vec<[f64; 3]>, ElasticInfo), ElasticError> {
    solve_displacement_with_progress(reference, prescribed, params, &mut |_, _| {})
}

/// [`solve_displacement`], its CG (where it runs instead of the factorisation) reporting every
/// iteration to `progress`, which may stop it ([`CgError::Cancelled`]).
pub fn solve_displacement_with_progress(
    reference: &HighOrderMesh,
    prescribed: &[Option<[f64; 3]>],
    params: &ElasticParams,
    progress: &mut dyn CgMonitor,
) -> Result<(Vec<[f64; 3]>, ElasticInfo), ElasticError> {
    let (dim, p) = (reference.dim, reference.order);
    if !(1..=MAX_ELASTIC_ORDER).contains(&p) {
        return Err(ElasticError::Order(p));
    }
    let (lambda, mu) = lame(params.young, params.poisson)?;
    if !(params.stiffening >= 0.0 && params.stiffening.is_finite()) {
        return Err(ElasticError::Material(format!(
            "the stiffening exponent must be non-negative and finite, got {}",
            params.stiffening
        )));
    }
    let material = (lambda, mu, params.stiffening);
    let start = Instant::now();
    let nn = reference.nodes.len();
    assert_eq!(prescribed.len(), nn);
    let (free, nf) = free_numbering(prescribed);
    let csr = pattern(reference, &free, nf);
    let (matrix, b) = assemble(reference, prescribed, &free, csr, material);
    let assembly_seconds = start.elapsed().as_secs_f64();

    let solve_start = Instant::now();
    let mut u = vec![[0.0; 3]; nf];
    let (cg, solver, factor_entries) = if nf == 0 {
        let none = CgInfo {
            iterations: 0,
            rel_residual: 0.0,
        };
        (none, params.solver, 0)
    } else {
        let direct = match factorisation(&matrix, params.solver)? {
            Some((scalar, pattern)) => {
                let entries = pattern.factor_entries();
                match solve_direct(&matrix, &scalar, pattern, &b, &mut u) {
                    Ok(info) => Some((info, entries)),
                    // `auto` falls back to CG when the factorisation breaks down.
                    Err(_) if params.solver == ElasticSolver::Auto => None,
                    Err(e) => return Err(e.into()),
                }
            }
            None => None,
        };
        match direct {
            Some((info, entries)) => (info, ElasticSolver::Cholesky, entries),
            None => {
                u.iter_mut().for_each(|x| *x = [0.0; 3]);
                let info = solve_cg(&matrix, params, &b, &mut u, progress)?;
                (info, ElasticSolver::Cg, 0)
            }
        }
    };
    let displacement = (0..nn)
        .map(|n| match prescribed[n] {
            Some(v) => v,
            None => u[free[n] as usize],
        })
        .collect();
    Ok((
        displacement,
        ElasticInfo {
            young: params.young,
            poisson: params.poisson,
            preconditioner: params.preconditioner,
            solver,
            factor_entries,
            held_back_nodes: 0,
            held_back_boundary_nodes: 0,
            min_displacement_fraction: 1.0,
            unknowns: nf * dim,
            prescribed_nodes: nn - nf,
            nonzero_blocks: matrix.indices.len(),
            cg,
            assembly_seconds,
            solve_seconds: solve_start.elapsed().as_secs_f64(),
        },
    ))
}

/// K_ff by block-preconditioned CG.
fn solve_cg(
    matrix: &BlockMatrix,
    params: &ElasticParams,
    b: &[[f64; 3]],
    u: &mut [[f64; 3]],
    progress: &mut dyn CgMonitor,
) -> Result<CgInfo, CgError> {
    let nodal = NodalPreconditioner::new(matrix, params.preconditioner)?;
    if params.preconditioner == ElasticPreconditioner::BlockSgs {
        let pre = BlockSgs {
            k: matrix,
            dinv: nodal,
        };
        pcg_coupled(matrix, &pre, b, u, &params.cg, progress)
    } else {
        pcg_coupled(matrix, &nodal, b, u, &params.cg, progress)
    }
}

/// The scalar CSR of K_ff (row and column `node · d + component`) and its Cholesky pattern,
/// when `solver` asks for the factorisation or allows it at this size; `None` means CG.
fn factorisation(
    matrix: &BlockMatrix,
    solver: ElasticSolver,
) -> Result<Option<(ScalarCsr, CholeskyPattern)>, CgError> {
    let unknowns = matrix.nrows() * matrix.dim;
    let try_it = match solver {
        ElasticSolver::Cg => false,
        ElasticSolver::Cholesky => true,
        ElasticSolver::Auto => unknowns <= CHOLESKY_MAX_UNKNOWNS,
    };
    if !try_it {
        return Ok(None);
    }
    let scalar = matrix.scalar_csr();
    let pattern = CholeskyPattern::new(&scalar.indptr, &scalar.indices)?;
    if solver == ElasticSolver::Auto && pattern.factor_entries() > CHOLESKY_MAX_FACTOR_ENTRIES {
        return Ok(None);
    }
    Ok(Some((scalar, pattern)))
}

/// K_ff u = b by sparse Cholesky, reported as [`CgInfo`] with 0 iterations and the relative
/// residual ‖b − K u‖/‖b‖ measured afterwards.
fn solve_direct(
    matrix: &BlockMatrix,
    scalar: &ScalarCsr,
    pattern: CholeskyPattern,
    b: &[[f64; 3]],
    u: &mut [[f64; 3]],
) -> Result<CgInfo, CgError> {
    let d = matrix.dim;
    // Symmetric diagonal scaling D^−½ K D^−½ (unit diagonal): the stiffening spreads the
    // diagonal over many orders of magnitude, which the factorisation's pivots do not survive
    // unscaled.
    let scale: Vec<f64> = (0..scalar.indptr.len() - 1)
        .map(|r| {
            let at = scalar.indptr[r]
                + scalar.indices[scalar.indptr[r]..scalar.indptr[r + 1]]
                    .binary_search(&(r as u32))
                    .expect("diagonal entry");
            1.0 / scalar.data[at].sqrt()
        })
        .collect();
    let mut data = scalar.data.clone();
    for r in 0..scale.len() {
        for k in scalar.indptr[r]..scalar.indptr[r + 1] {
            data[k] *= scale[r] * scale[scalar.indices[k] as usize];
        }
    }
    let factor = pattern.factor(&data)?;
    drop(data);
    let mut rhs = faer::Mat::<f64>::from_fn(b.len() * d, 1, |i, _| b[i / d][i % d] * scale[i]);
    factor.solve_in_place(&mut rhs)?;
    for (i, x) in u.iter_mut().enumerate() {
        for c in 0..d {
            x[c] = rhs[(i * d + c, 0)] * scale[i * d + c];
        }
    }
    let mut ku = vec![[0.0; 3]; u.len()];
    matrix.apply(u, &mut ku);
    let (mut rr, mut bb) = (0.0f64, 0.0f64);
    for (k, bi) in ku.iter().zip(b) {
        for c in 0..d {
            rr += (bi[c] - k[c]).powi(2);
            bb += bi[c] * bi[c];
        }
    }
    Ok(CgInfo {
        iterations: 0,
        rel_residual: if bb > 0.0 {
            (rr / bb).sqrt()
        } else {
            rr.sqrt()
        },
    })
}

/// A scalar CSR matrix (sorted columns).
struct ScalarCsr {
    indptr: Vec<usize>,
    indices: Vec<u32>,
    data: Vec<f64>,
}

/// The elastic-analogy mesh: `straight` with its boundary nodes moved onto those of `curved`
/// (same numbering) and its interior nodes moved by the elastic displacement.
pub fn elastic_analogy(
    straight: &HighOrderMesh,
    curved: &HighOrderMesh,
    params: &ElasticParams,
) -> Result<(HighOrderMesh, ElasticInfo), ElasticError> {
    elastic_analogy_with_progress(straight, curved, params, &mut |_, _| {})
}

/// [`elastic_analogy`], its CG reporting to `progress` ([`solve_displacement_with_progress`]).
pub fn elastic_analogy_with_progress(
    straight: &HighOrderMesh,
    curved: &HighOrderMesh,
    params: &ElasticParams,
    progress: &mut dyn CgMonitor,
) -> Result<(HighOrderMesh, ElasticInfo), ElasticError> {
    assert_eq!(straight.nodes.len(), curved.nodes.len(), "same numbering");
    let mut prescribed = vec![None; straight.nodes.len()];
    for &n in &curved.boundary {
        let n = n as usize;
        prescribed[n] = Some(std::array::from_fn(|k| {
            curved.nodes[n][k] - straight.nodes[n][k]
        }));
    }
    let (u, info) = solve_displacement_with_progress(straight, &prescribed, params, progress)?;
    let mut out = straight.clone();
    for (n, x) in out.nodes.iter_mut().enumerate() {
        *x = match prescribed[n] {
            // Boundary nodes take the target positions exactly (no round-off from x + u).
            Some(_) => curved.nodes[n],
            None => std::array::from_fn(|k| x[k] + u[n][k]),
        };
    }
    Ok((out, info))
}

/// Halvings of a node's displacement before it is put back on the straight mesh.
pub const MAX_HOLD_BACK_HALVINGS: u32 = 40;

/// What [`hold_back_invalid`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HoldBack {
    /// Nodes whose displacement was shortened.
    pub nodes: usize,
    /// Of those, nodes on the boundary.
    pub boundary_nodes: usize,
    /// The smallest fraction of its displacement a node kept (1 when none was shortened).
    pub min_fraction: f64,
}

/// Make every element of `moved` certified valid by moving nodes back along the straight line
/// to their positions in `straight` (same numbering): each round halves the displacement of
/// the interior nodes of every element that `certify` does not certify (of its boundary nodes
/// only once its interior nodes are straight), then re-certifies the elements around those
/// nodes. A node halved [`MAX_HOLD_BACK_HALVINGS`] times goes back to
/// the straight mesh, so the loop ends with every element either certified or made only of
/// straight nodes, which is the straight element itself.
///
/// Linear elasticity does not keep thin boundary-layer cells valid when the boundary moves by
/// more than their height; this is the elastic analogy's counterpart of the IGA's blend from
/// the straight elevation, so that both methods always give a certified mesh.
///
/// Returns the elements still uncertified (only straight elements that `certify` does not
/// certify either; empty for a valid input) and what was held back.
pub fn hold_back_invalid(
    straight: &HighOrderMesh,
    moved: &mut HighOrderMesh,
    certify: impl Fn(&HighOrderMesh, usize) -> bool + Sync,
) -> (Vec<usize>, HoldBack) {
    let ne = moved.n_elements();
    let mut bad: Vec<usize> = (0..ne)
        .into_par_iter()
        .filter(|&e| !certify(moved, e))
        .collect();
    if bad.is_empty() {
        return (
            bad,
            HoldBack {
                min_fraction: 1.0,
                ..Default::default()
            },
        );
    }
    let nn = moved.nodes.len();
    let incident = node_elements(moved);
    let mut boundary = vec![false; nn];
    for &n in &moved.boundary {
        boundary[n as usize] = true;
    }
    let mut halvings = vec![0u32; nn];
    let mut touched = vec![false; nn];
    let mut mark = vec![false; ne];
    let elastic = moved.nodes.clone();
    while !bad.is_empty() {
        // Interior nodes first: the boundary is the one the caller prescribed, and it moves
        // only for an element whose interior nodes are all straight already.
        let movable = |n: &u32| halvings[*n as usize] < MAX_HOLD_BACK_HALVINGS;
        let mut nodes: Vec<u32> = Vec::new();
        for &e in &bad {
            let start = nodes.len();
            let ids = moved.element(e);
            nodes.extend(ids.iter().filter(|&n| !boundary[*n as usize] && movable(n)));
            if nodes.len() == start {
                nodes.extend(ids.iter().filter(|&n| movable(n)));
            }
        }
        nodes.sort_unstable();
        nodes.dedup();
        if nodes.is_empty() {
            // Every node of the remaining elements is straight already.
            break;
        }
        let mut around = Vec::new();
        for &n in &nodes {
            let n = n as usize;
            halvings[n] += 1;
            touched[n] = true;
            let f = fraction(halvings[n]);
            moved.nodes[n] = std::array::from_fn(|k| {
                straight.nodes[n][k] + f * (elastic[n][k] - straight.nodes[n][k])
            });
            for &e in &incident.1[incident.0[n]..incident.0[n + 1]] {
                if !mark[e as usize] {
                    mark[e as usize] = true;
                    around.push(e as usize);
                }
            }
        }
        for &e in &around {
            mark[e] = false;
        }
        let current: &HighOrderMesh = moved;
        bad = around
            .into_par_iter()
            .filter(|&e| !certify(current, e))
            .collect();
    }
    let held: Vec<usize> = (0..nn).filter(|&n| touched[n]).collect();
    let info = HoldBack {
        nodes: held.len(),
        boundary_nodes: held.iter().filter(|&&n| boundary[n]).count(),
        min_fraction: held
            .iter()
            .map(|&n| fraction(halvings[n]))
            .fold(1.0, f64::min),
    };
    (bad, info)
}

/// The share of its displacement a node keeps after `halvings` halvings (0 at the last).
fn fraction(halvings: u32) -> f64 {
    if halvings >= MAX_HOLD_BACK_HALVINGS {
        0.0
    } else {
        0.5f64.powi(halvings as i32)
    }
}

/// For every node, the elements that contain it: CSR offsets and element ids.
fn node_elements(ho: &HighOrderMesh) -> (Vec<usize>, Vec<u32>) {
    let nn = ho.nodes.len();
    let mut offsets = vec![0usize; nn + 1];
    for &n in &ho.elements {
        offsets[n as usize + 1] += 1;
    }
    for i in 0..nn {
        offsets[i + 1] += offsets[i];
    }
    let mut fill = offsets.clone();
    let mut ids = vec![0u32; ho.elements.len()];
    for e in 0..ho.n_elements() {
        for &n in ho.element(e) {
            ids[fill[n as usize]] = e as u32;
            fill[n as usize] += 1;
        }
    }
    (offsets, ids)
}
