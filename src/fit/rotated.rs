//! The fit's normal equations across rotation-periodic seams.
//!
//! Input: a [`FitSpace`] some of whose elements see control points rotated
//! ([`FitSpace::frames`]: element e takes R_{e,c} P_c + t_{e,c} for control point c), the
//! scalar normal matrix K of its rows (as for any space: the glued space's, one matrix for
//! x, y and z) and the element blocks G_e of the weights. Output: the coupling C and the
//! solution of the fit's system (K ⊗ I₃ + C) δ = b.
//!
//! With x_e = Σ_c N_c (R_c P_c) + s, the least-squares matrix couples control points i and j
//! by Σ_e A^e_ij R_iᵀ R_j, A^e = E_eᵀ G_e E_e restricted to the pair (position and frame
//! samples alike); R_iᵀ R_j = I wherever element e sees both points in the same frame, so
//!
//!   K ⊗ I₃ + C,  C_ij = Σ_e A^e_ij (R_{e,i}ᵀ R_{e,j} − I),
//!
//! with C non-zero only on the pairs an element sees in different frames (a few rows along
//! the seams). The right-hand side needs R_{e,c}ᵀ on the rotated points' rows, which
//! [`FitSpace::add_transposed`] applies. The system is solved by [`crate::solve::pcg_coupled`]
//! (one recurrence over the three coordinates), preconditioned by K⁻¹ ⊗ I₃ (K factored where
//! the fit would factor it, and the CG then run to the factorisation's accuracy,
//! [`super::FitSolver::cg_params`]) or by K's pair of block-Jacobi partitions: C has low
//! rank, so the factored preconditioner leaves a few iterations. On a device the same
//! recurrence runs with K's diagonal ⊗ I₃ ([`OnK::Jacobi`], the device CG's preconditioner),
//! C's product a kernel over its block rows ([`Coupling::block_rows`]).
//!
//! Invariant: without frames nothing here runs, and the fit is the ordinary one.

use super::{ElementBlocks, FitSpace, NormalMatrix};
use crate::math::bernstein::net_len;
use crate::math::linalg::DVec3;
use crate::solve::{CgError, CgInfo, CgParams, LinOp, Preconditioner};
use rayon::prelude::*;
use std::collections::HashMap;

type Mat3 = [[f64; 3]; 3];

const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// The coupling C between control points seen in different frames, as 3 × 3 blocks by rows.
#[derive(Clone, Debug)]
pub struct Coupling {
    indptr: Vec<usize>,
    cols: Vec<u32>,
    blocks: Vec<Mat3>,
}

impl Coupling {
    /// C of `space` with the element blocks `blocks`; `None` when no element sees a control
    /// point rotated.
    pub fn of(space: &dyn FitSpace, blocks: &ElementBlocks) -> Option<Coupling> {
        if !space.has_frames() {
            return None;
        }
        let nb = net_len(space.dim());
        let per_element: Vec<Vec<((u32, u32), Mat3)>> = (0..space.n_elements())
            .into_par_iter()
            .filter_map(|e| space.frames(e).map(|f| (e, f)))
            .map(|(e, frames)| {
                let (mut o, mut c, mut w) = (Vec::new(), Vec::new(), Vec::new());
                space.element_rows(e, &mut o, &mut c, &mut w);
                let mut ids = c.clone();
                ids.sort_unstable();
                ids.dedup();
                // n_i[b]: control point i's weight in Bernstein point b.
                let mut n = vec![0.0; ids.len() * nb];
                for b in 0..nb {
                    for k in o[b]..o[b + 1] {
                        let i = ids.binary_search(&c[k]).expect("a listed column");
                        n[i * nb + b] += w[k];
                    }
                }
                let (gd, gr) = &blocks.cache[&blocks.masks[e]];
                let frame = |id: u32| frames.iter().find(|f| f.0 == id).map_or(IDENTITY, |f| f.1);
                let mut out = Vec::new();
                for (i, &a) in ids.iter().enumerate() {
                    let ra = frame(a);
                    // G n_i.
                    let gn: Vec<f64> = (0..nb)
                        .map(|r| {
                            (0..nb)
                                .map(|s| (gd[r * nb + s] + gr[r * nb + s]) * n[i * nb + s])
                                .sum()
                        })
                        .collect();
                    for (j, &b) in ids.iter().enumerate() {
                        let rb = frame(b);
                        if ra == rb {
                            continue;
                        }
                        let aij: f64 = (0..nb).map(|r| gn[r] * n[j * nb + r]).sum();
                        if aij == 0.0 {
                            continue;
                        }
                        // A_ij (R_aᵀ R_b − I).
                        let m: Mat3 = std::array::from_fn(|p| {
                            std::array::from_fn(|q| {
                                let rtr: f64 = (0..3).map(|k| ra[k][p] * rb[k][q]).sum();
                                aij * (rtr - IDENTITY[p][q])
                            })
                        });
                        out.push(((a, b), m));
                    }
                }
                out
            })
            .collect();
        let mut sum: HashMap<(u32, u32), Mat3> = HashMap::new();
        for (ij, m) in per_element.into_iter().flatten() {
            let s = sum.entry(ij).or_insert([[0.0; 3]; 3]);
            for p in 0..3 {
                for q in 0..3 {
                    s[p][q] += m[p][q];
                }
            }
        }
        let mut entries: Vec<((u32, u32), Mat3)> = sum.into_iter().collect();
        entries.sort_unstable_by_key(|e| e.0);
        let n = space.control_points().len();
        let mut indptr = vec![0usize; n + 1];
        for ((i, _), _) in &entries {
            indptr[*i as usize + 1] += 1;
        }
        for i in 0..n {
            indptr[i + 1] += indptr[i];
        }
        Some(Coupling {
            indptr,
            cols: entries.iter().map(|e| e.0.1).collect(),
            blocks: entries.into_iter().map(|e| e.1).collect(),
        })
    }

    /// C ← D C D for the diagonal D = diag(`d`) (the fit's symmetric scaling of K).
    pub fn scale_symmetric(&mut self, d: &[f64]) {
        for r in 0..self.indptr.len() - 1 {
            for k in self.indptr[r]..self.indptr[r + 1] {
                let s = d[r] * d[self.cols[k] as usize];
                self.blocks[k] = self.blocks[k].map(|row| row.map(|x| x * s));
            }
        }
    }

    /// The number of 3 × 3 blocks stored.
    pub fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// C restricted to the control points `rows` (increasing; every row and column stored is
    /// one of them) and renumbered by their place in it: a rank's share in its local
    /// numbering (`distributed::cg`).
    pub fn restricted(&self, rows: &[u32]) -> Coupling {
        let at = |g: u32| {
            rows.binary_search(&g)
                .expect("a coupled control point is one of the rows") as u32
        };
        let mut indptr = vec![0usize];
        let (mut cols, mut blocks) = (Vec::new(), Vec::new());
        for &g in rows {
            let g = g as usize;
            for k in self.indptr[g]..self.indptr[g + 1] {
                cols.push(at(self.cols[k]));
                blocks.push(self.blocks[k]);
            }
            indptr.push(cols.len());
        }
        debug_assert_eq!(cols.len(), self.cols.len(), "a coupled row outside `rows`");
        Coupling {
            indptr,
            cols,
            blocks,
        }
    }

    /// y += (C x)_r, row r alone, with x given by its entries.
    pub(crate) fn row_apply_add(&self, r: usize, x: &dyn Fn(usize) -> [f64; 3], y: &mut [f64; 3]) {
        for k in self.indptr[r]..self.indptr[r + 1] {
            let (m, v) = (&self.blocks[k], x(self.cols[k] as usize));
            for p in 0..3 {
                y[p] += m[p][0] * v[0] + m[p][1] * v[1] + m[p][2] * v[2];
            }
        }
    }

    /// The rows holding blocks, in increasing order: (row, the blocks' columns, the blocks),
    /// each block 3 × 3 by rows (what a device kernel over C's block rows uploads).
    pub fn block_rows(&self) -> impl Iterator<Item = (usize, &[u32], &[Mat3])> {
        (0..self.indptr.len() - 1)
            .filter(|&r| self.indptr[r + 1] > self.indptr[r])
            .map(|r| {
                let k = self.indptr[r]..self.indptr[r + 1];
                (r, &self.cols[k.clone()], &self.blocks[k])
            })
    }

    /// y += C x.
    pub fn apply_add(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        for (r, y) in y.iter_mut().enumerate() {
            for k in self.indptr[r]..self.indptr[r + 1] {
                let (m, v) = (&self.blocks[k], x[self.cols[k] as usize]);
                for p in 0..3 {
                    y[p] += m[p][0] * v[0] + m[p][1] * v[1] + m[p][2] * v[2];
                }
            }
        }
    }
}

/// K ⊗ I₃ + C.
struct Rotated<'a> {
    k: &'a NormalMatrix,
    c: &'a Coupling,
}

impl LinOp for Rotated<'_> {
    fn nrows(&self) -> usize {
        self.k.n()
    }
    fn apply(&self, x: &[[f64; 3]], y: &mut [[f64; 3]]) {
        self.k.apply(x, y);
        self.c.apply_add(x, y);
    }
    fn diagonal(&self) -> Vec<f64> {
        // C's diagonal blocks vanish (R_iᵀ R_i = I).
        self.k.diagonal()
    }
}

/// Which approximation of K⁻¹ ⊗ I₃ preconditions the coupled CG ([`solve`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnK {
    /// K's sparse Cholesky factor (the fit's small systems on the CPU).
    #[serde(rename = "cholesky")]
    Factor,
    /// K's pair of block-Jacobi partitions ([`crate::solve::block_jacobi::BlockJacobiPair`]).
    BlockJacobiPair,
    /// K's diagonal: the device CG's preconditioner, and its CPU reference.
    Jacobi,
}

impl OnK {
    /// The name the report gives it (`coupled_fit_preconditioner`): `cholesky`,
    /// `block-jacobi-pair` or `jacobi`, as `--fit-solver` and `--cg-preconditioner` spell them.
    pub fn name(self) -> &'static str {
        match self {
            OnK::Factor => "cholesky",
            OnK::BlockJacobiPair => "block-jacobi-pair",
            OnK::Jacobi => "jacobi",
        }
    }
}

/// K⁻¹ ⊗ I₃ as [`OnK`] chose it.
enum OnKBuilt {
    Factor(crate::solve::direct::SparseCholesky),
    Blocks(crate::solve::block_jacobi::BlockJacobiPair),
    Jacobi(crate::solve::Jacobi),
}

impl Preconditioner for OnKBuilt {
    fn apply(&self, r: &[[f64; 3]], z: &mut [[f64; 3]]) {
        match self {
            OnKBuilt::Blocks(b) => b.apply(r, z),
            OnKBuilt::Jacobi(j) => j.apply(r, z),
            OnKBuilt::Factor(f) => {
                let mut m = faer::Mat::<f64>::from_fn(r.len(), 3, |i, c| r[i][c]);
                f.solve_in_place(&mut m)
                    .expect("the solve's scratch was allocated for the factor");
                for (i, z) in z.iter_mut().enumerate() {
                    *z = [m[(i, 0)], m[(i, 1)], m[(i, 2)]];
                }
            }
        }
    }
}

/// Solve (K ⊗ I₃ + C) δ = `b` from `delta` by [`crate::solve::pcg_coupled`], preconditioned by
/// K factored, by K's block-Jacobi pair or by K's diagonal (`on_k`; module docs). `progress`
/// sees every iteration and may cancel the solve ([`crate::solve::CgMonitor`]).
pub fn solve(
    k: &NormalMatrix,
    c: &Coupling,
    b: &[[f64; 3]],
    delta: &mut [[f64; 3]],
    params: &CgParams,
    on_k: OnK,
    progress: &mut dyn crate::solve::CgMonitor,
) -> Result<CgInfo, CgError> {
    let pre = match on_k {
        OnK::Factor => OnKBuilt::Factor(crate::solve::direct::SparseCholesky::new(
            k.indptr(),
            k.indices(),
            k.data(),
        )?),
        OnK::BlockJacobiPair => OnKBuilt::Blocks(crate::solve::block_jacobi::BlockJacobiPair::new(
            k.indptr(),
            k.indices(),
            k.data(),
            crate::solve::block_jacobi::DEFAULT_BLOCK,
        )?),
        // The diagonal of K ⊗ I₃ + C is K's (C's diagonal blocks vanish).
        OnK::Jacobi => OnKBuilt::Jacobi(crate::solve::Jacobi::new(k)?),
    };
    crate::solve::pcg_coupled(&Rotated { k, c }, &pre, b, delta, params, progress)
}

/// Rᵀ applied to `v`.
pub(crate) fn rotate_back(r: &Mat3, v: DVec3) -> DVec3 {
    DVec3::new(
        r[0][0] * v.x + r[1][0] * v.y + r[2][0] * v.z,
        r[0][1] * v.x + r[1][1] * v.y + r[2][1] * v.z,
        r[0][2] * v.x + r[1][2] * v.y + r[2][2] * v.z,
    )
}

#[cfg(test)]
pub(crate) mod tests {
    use crate::fit::{FitParams, FitSolver};
    use crate::math::linalg::DVec3;
    use crate::mesh::periodic::{PeriodicSpec, resolve};
    use crate::mesh::{LinearMesh, Topology};
    use crate::spline::SplineSpace;
    use crate::spline::seam::{Glued, glue, glue_translations, interior_view, unwrap};

    /// Quads of the annulus 1 ≤ r ≤ 2 over `cells` of `around` cells of `step` degrees, `nr`
    /// cells across; `closed`: the last column meets the first (a whole ring, `cells` ·
    /// `step` = 360). Sides tagged 3 (hub), 4 (shroud) and, open, 1 (θ = 0), 2 (the end).
    fn annulus(nr: usize, cells: usize, step: f64, closed: bool) -> LinearMesh {
        let angles: Vec<f64> = (0..=cells).map(|j| step * j as f64).collect();
        annulus_at(nr, &angles, closed)
    }

    /// [`annulus`] with its columns at `angles` (degrees; closed: the last is 360, the
    /// first column's).
    fn annulus_at(nr: usize, angles: &[f64], closed: bool) -> LinearMesh {
        let cells = angles.len() - 1;
        let columns = if closed { cells } else { cells + 1 };
        let id = |i: usize, j: usize| ((j % columns) * (nr + 1) + i) as u32;
        let mut coords = Vec::new();
        for j in 0..columns {
            let t = angles[j].to_radians();
            for i in 0..=nr {
                let r = 1.0 + i as f64 / nr as f64;
                coords.push([r * t.cos(), r * t.sin(), 0.0]);
            }
        }
        let (mut elements, mut facets, mut tags) = (Vec::new(), Vec::new(), Vec::new());
        for j in 0..cells {
            for i in 0..nr {
                elements.extend([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
            facets.extend([id(0, j), id(0, j + 1), id(nr, j), id(nr, j + 1)]);
            tags.extend([3, 4]);
        }
        if !closed {
            for i in 0..nr {
                facets.extend([id(i, 0), id(i + 1, 0), id(i, cells), id(i + 1, cells)]);
                tags.extend([1, 2]);
            }
        }
        LinearMesh {
            dim: 2,
            coords,
            elements,
            tagged_facets: facets,
            facet_tags: tags,
            tag_names: [(1, "lo"), (2, "hi"), (3, "hub"), (4, "shroud")]
                .map(|(t, n)| (t, n.to_string()))
                .into(),
            ..Default::default()
        }
    }

    /// The sector of 4 × 3 cells of 7.5° (sides `lo` and `hi`, 30° apart), the whole ring of
    /// 48 such columns, their topologies, and the sector glued through its rotation.
    pub(crate) fn sector_and_ring() -> (LinearMesh, LinearMesh, Topology, Topology, Glued) {
        let (sector, ring) = (annulus(3, 4, 7.5, false), annulus(3, 48, 7.5, true));
        let (st, rt, glued) = glued_to_ring(&sector, &ring);
        (sector, ring, st, rt, glued)
    }

    /// The topologies of `sector` and `ring`, and the sector glued through the rotation
    /// carrying its side `lo` onto `hi` (checked a rotation, glued as one).
    fn glued_to_ring(sector: &LinearMesh, ring: &LinearMesh) -> (Topology, Topology, Glued) {
        let (st, rt) = (Topology::build(sector), Topology::build(ring));
        let spec = PeriodicSpec {
            master: "lo".into(),
            slave: "hi".into(),
            from_file: false,
        };
        let pairs = resolve(sector, &st, &[spec]).expect("the sides are images");
        assert!(!pairs[0].transform.is_translation());
        assert!(glue_translations(sector, &pairs).is_none());
        let glued = glue(sector, &pairs).expect("a manifold glued sector");
        (st, rt, glued)
    }

    /// The sector of 4 × 3 cells of 7.5° glued through its rotation by 30°, and the whole
    /// ring of 48 such columns: the space of the glued sector is the ring's, restricted to
    /// its first four columns, so the nets agree (initial and fitted: the ring's fit is
    /// rotationally symmetric, and the sector's coupled fit must find the same map).
    #[test]
    fn a_rotation_glued_sector_is_the_whole_rings_spline() {
        let (sector, ring, st, rt, glued) = sector_and_ring();
        let mut space = SplineSpace::build_with_knots(&glued.mesh, &glued.topo, &[], None);
        unwrap(&mut space, &sector, &st, &glued).expect("the seam is identified");
        assert!(space.extraction.has_frames());
        let whole = SplineSpace::build_with_knots(&ring, &rt, &[], None);
        assert_eq!(space.n_spline_elements(), sector.n_elements());
        let gap = |a: &SplineSpace, ca: &[[f64; 3]], b: &SplineSpace, cb: &[[f64; 3]]| {
            (0..sector.n_elements())
                .flat_map(|e| {
                    let (x, y) = (a.element_bezier_with(e, ca), b.element_bezier_with(e, cb));
                    (0..9).map(move |l| (DVec3::from(x[l]) - DVec3::from(y[l])).length())
                })
                .fold(0.0, f64::max)
        };
        let initial = gap(&space, &space.control_points, &whole, &whole.control_points);
        assert!(initial < 1e-13, "initial nets differ by {initial:e}");
        let view = interior_view(&sector, &st, &glued);
        let mut params = FitParams::default();
        params.cg.rel_tol = 1e-13;
        for solver in [FitSolver::Cholesky, FitSolver::Cg] {
            params.solver = solver;
            let (cs, info) = crate::fit::fit(&space, &sector, &view.topo, &params, |_, _| {})
                .expect("the coupled fit converges");
            let (cr, _) = crate::fit::fit(&whole, &ring, &rt, &params, |_, _| {})
                .expect("the ring's fit converges");
            let fitted = gap(&space, &cs, &whole, &cr);
            assert!(
                fitted < 1e-10,
                "{solver:?}: fitted nets differ by {fitted:e} ({} iterations)",
                info.cg.iterations
            );
            // The fit moved the map: the comparison is not that of the initial nets.
            assert!(gap(&whole, &whole.control_points, &whole, &cr) > 1e-4);
        }
    }

    /// The smooth targets of the glued `sector` (its [`crate::spline::seam::SeamView`]
    /// `view`) with the walls continued across the seam and the inheritance along `links`.
    fn seamed_targets(
        sector: &LinearMesh,
        view: &crate::spline::seam::SeamView,
        params: &crate::fit::smooth::SmoothParams,
        links: &[crate::fit::smooth::SeamLink],
    ) -> crate::fit::smooth::SmoothTargets {
        let partners = &view.wall_partners;
        crate::fit::smooth::SmoothTargets::build_shared(
            sector, &view.topo, params, None, None, partners, links,
        )
    }

    /// The largest distance between the corrections of the sector's targets `t` and the
    /// ring's `whole` on the sector's elements (the ring's first ones, in the same order).
    fn gap_to_ring(
        t: &crate::fit::smooth::SmoothTargets,
        (sector, topo): (&LinearMesh, &Topology),
        whole: &crate::fit::smooth::SmoothTargets,
        (ring, rt): (&LinearMesh, &Topology),
    ) -> f64 {
        (0..sector.n_elements())
            .flat_map(|e| {
                let (a, b) = (
                    t.element_corrections(sector, topo, e),
                    whole.element_corrections(ring, rt, e),
                );
                (0..9).map(move |l| (DVec3::from(a[l]) - DVec3::from(b[l])).length())
            })
            .fold(0.0, f64::max)
    }

    /// The smooth targets of the glued sector, its hub and shroud continued across the seam
    /// through the rotation ([`crate::fit::SmoothTargets::build_shared`]), are the whole
    /// ring's on the sector's elements, at the seam as in its middle. Built from each side's
    /// wall alone, the seam vertices have no model and their neighbours one-sided ones.
    #[test]
    fn the_glued_sectors_wall_targets_are_the_whole_rings() {
        use crate::fit::smooth::{SmoothParams, SmoothTargets};
        let (sector, ring, st, rt, glued) = sector_and_ring();
        let view = interior_view(&sector, &st, &glued);
        // Hub and shroud end on both sides of the seam.
        assert_eq!(view.wall_partners.iter().flatten().count(), 4);
        let params = SmoothParams::default();
        let whole = SmoothTargets::build(&ring, &rt, &params);
        let gap = |t: &SmoothTargets| gap_to_ring(t, (&sector, &view.topo), &whole, (&ring, &rt));
        let seamed = seamed_targets(&sector, &view, &params, &view.seam_links);
        let apart = SmoothTargets::build(&sector, &view.topo, &params);
        let (both, one) = (gap(&seamed), gap(&apart));
        assert!(both < 1e-14, "seamed targets {both:e} from the ring's");
        assert!(one > 1e-6, "one-sided targets {one:e} from the ring's");
    }

    /// A 30° sector whose hub cells are 1°, 24°, 4° and 1° wide, 8 cells across, and the ring
    /// of 12 such sectors. The seam's interior vertex next to the hub is too far from its own
    /// hub vertex (ℓ = 1°) and from the 29° one to inherit their models: on the ring its
    /// nearest source is the hub vertex 1° past the seam, which in the sector lies across it.
    /// Inheriting along the seam links, the glued sector's targets are the ring's on every
    /// element (interior samples too); inheriting along its own side only, the seam vertex on
    /// the 30° side takes the 25° hub vertex's model instead, and the sector's two sides of
    /// the seam see different targets there.
    #[test]
    fn interior_vertices_inherit_across_a_rotation_seam() {
        use crate::fit::smooth::{SmoothParams, SmoothTargets};
        let pattern = [0.0, 1.0, 25.0, 29.0];
        let sector = annulus_at(8, &[0.0, 1.0, 25.0, 29.0, 30.0], false);
        let angles: Vec<f64> = (0..12)
            .flat_map(|k| pattern.map(|a| a + 30.0 * k as f64))
            .chain([360.0])
            .collect();
        let ring = annulus_at(8, &angles, true);
        let (st, rt, glued) = glued_to_ring(&sector, &ring);
        let view = interior_view(&sector, &st, &glued);
        // Both sides' 9 seam vertices, each way.
        assert_eq!(view.seam_links.len(), 18);
        let params = SmoothParams::default();
        let whole = SmoothTargets::build(&ring, &rt, &params);
        let gap = |t: &SmoothTargets| gap_to_ring(t, (&sector, &view.topo), &whole, (&ring, &rt));
        let build = |links| seamed_targets(&sector, &view, &params, links);
        let (across, own) = (gap(&build(&view.seam_links)), gap(&build(&[])));
        assert!(across < 1e-14, "targets {across:e} from the ring's");
        assert!(own > 1e-5, "own-side inheritance {own:e} from the ring's");
    }
}
