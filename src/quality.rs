//! Sampled Jacobian quality of high-order Lagrange elements.
//!
//! Input: a [`HighOrderMesh`] (any order, lattice-ordered nodes). Output: per element the
//! minimum Jacobian determinant and minimum scaled Jacobian (det J divided by the product of
//! the column norms of J: 1 for an undistorted corner, ≤ 0 for an inverted point), **sampled**
//! on the equispaced lattice of order 2p (which contains the nodes and the corners). This is a
//! sampled measure, not a certificate: `sample_det_jacobian` may miss a negative region smaller
//! than the sample spacing. The certified bound of quadratic Bézier elements lives with the fit.

// The equispaced Lagrange basis is the foundation's; re-exported for the callers of this path.
pub use crate::math::lagrange::lagrange_1d;
use crate::mesh::HighOrderMesh;
use rayon::prelude::*;
use serde::Serialize;

/// Quality of one element.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ElementQuality {
    pub min_det_jacobian: f64,
    pub min_scaled_jacobian: f64,
}

/// Sampled det J and scaled Jacobian of every element.
pub fn sample_det_jacobian(mesh: &HighOrderMesh) -> Vec<ElementQuality> {
    let p = mesh.order;
    let d = mesh.dim;
    let q = 2 * p; // sample lattice order
    let m = p + 1;
    let ns = q + 1;
    // Tables V[s][i], D[s][i] at the sample parameters.
    let mut v = vec![0.0; ns * m];
    let mut dv = vec![0.0; ns * m];
    for s in 0..ns {
        lagrange_1d(
            p,
            s as f64 / q as f64,
            &mut v[s * m..(s + 1) * m],
            &mut dv[s * m..(s + 1) * m],
        );
    }
    // Scratch of the 3D sum factorisation, one pair per rayon task (not per element).
    let scratch = || {
        if d == 2 {
            (Vec::new(), Vec::new())
        } else {
            (
                vec![[[0.0; 3]; 2]; m * m * ns],
                vec![[[0.0; 3]; 3]; m * ns * ns],
            )
        }
    };
    (0..mesh.n_elements())
        .into_par_iter()
        .map_init(scratch, |(t1, t2), e| {
            let nodes = mesh.element(e);
            let x = |i: usize, j: usize, k: usize| mesh.nodes[nodes[i + m * (j + m * k)] as usize];
            let mut min_det = f64::INFINITY;
            let mut min_sj = f64::INFINITY;
            if d == 2 {
                for b in 0..ns {
                    for a in 0..ns {
                        let mut ju = [0.0; 2];
                        let mut jv = [0.0; 2];
                        for j in 0..m {
                            for i in 0..m {
                                let p = x(i, j, 0);
                                let wu = dv[a * m + i] * v[b * m + j];
                                let wv = v[a * m + i] * dv[b * m + j];
                                for c in 0..2 {
                                    ju[c] += wu * p[c];
                                    jv[c] += wv * p[c];
                                }
                            }
                        }
                        let det = ju[0] * jv[1] - ju[1] * jv[0];
                        let norm = (ju[0].hypot(ju[1])) * (jv[0].hypot(jv[1]));
                        min_det = min_det.min(det);
                        min_sj = min_sj.min(if norm > 0.0 { det / norm } else { 0.0 });
                    }
                }
            } else {
                let x = |n: usize| mesh.nodes[nodes[n] as usize];
                (min_det, min_sj) = match p {
                    1 => hex_quality::<2, 3>(&x, &v, &dv, t1, t2),
                    2 => hex_quality::<3, 5>(&x, &v, &dv, t1, t2),
                    3 => hex_quality::<4, 7>(&x, &v, &dv, t1, t2),
                    4 => hex_quality::<5, 9>(&x, &v, &dv, t1, t2),
                    5 => hex_quality::<6, 11>(&x, &v, &dv, t1, t2),
                    6 => hex_quality::<7, 13>(&x, &v, &dv, t1, t2),
                    7 => hex_quality::<8, 15>(&x, &v, &dv, t1, t2),
                    8 => hex_quality::<9, 17>(&x, &v, &dv, t1, t2),
                    9 => hex_quality::<10, 19>(&x, &v, &dv, t1, t2),
                    10 => hex_quality::<11, 21>(&x, &v, &dv, t1, t2),
                    _ => panic!("order {p} out of range"),
                };
            }
            ElementQuality {
                min_det_jacobian: min_det,
                min_scaled_jacobian: min_sj,
            }
        })
        .collect()
}

/// Smallest sampled det J and scaled Jacobian of one hex of order M − 1 (nodes `x(n)` in
/// lattice order) on the lattice of NS = 2M − 1 points per direction, by sum factorisation:
/// contract k, then j, then i. Loop bounds are constants so each order is unrolled for itself.
fn hex_quality<const M: usize, const NS: usize>(
    x: &dyn Fn(usize) -> [f64; 3],
    v: &[f64],
    dv: &[f64],
    t1: &mut [[[f64; 3]; 2]],
    t2: &mut [[[f64; 3]; 3]],
) -> (f64, f64) {
    let (v, dv) = (&v[..NS * M], &dv[..NS * M]);
    let t1 = &mut t1[..M * M * NS]; // [i][j][c] with V / D along k
    let t2 = &mut t2[..M * NS * NS]; // [i][b][c]: (V_j V_k), (D_j V_k), (V_j D_k)
    let mut min_det = f64::INFINITY;
    let mut min_sj = f64::INFINITY;
    t1.fill([[0.0; 3]; 2]);
    for k in 0..M {
        for j in 0..M {
            for i in 0..M {
                let p = x(i + M * (j + M * k));
                for c in 0..NS {
                    let (wv, wd) = (v[c * M + k], dv[c * M + k]);
                    let t = &mut t1[(i + M * j) * NS + c];
                    for r in 0..3 {
                        t[0][r] += wv * p[r];
                        t[1][r] += wd * p[r];
                    }
                }
            }
        }
    }
    t2.fill([[0.0; 3]; 3]);
    for c in 0..NS {
        for b in 0..NS {
            for i in 0..M {
                let t = &mut t2[(i * NS + b) * NS + c];
                for j in 0..M {
                    let s = t1[(i + M * j) * NS + c];
                    let (wv, wd) = (v[b * M + j], dv[b * M + j]);
                    for r in 0..3 {
                        t[0][r] += wv * s[0][r];
                        t[1][r] += wd * s[0][r];
                        t[2][r] += wv * s[1][r];
                    }
                }
            }
        }
    }
    for c in 0..NS {
        for b in 0..NS {
            for a in 0..NS {
                let mut j = [[0.0; 3]; 3];
                for i in 0..M {
                    let s = t2[(i * NS + b) * NS + c];
                    let (wv, wd) = (v[a * M + i], dv[a * M + i]);
                    for r in 0..3 {
                        j[0][r] += wd * s[0][r];
                        j[1][r] += wv * s[1][r];
                        j[2][r] += wv * s[2][r];
                    }
                }
                let det = j[0][0] * (j[1][1] * j[2][2] - j[1][2] * j[2][1])
                    - j[0][1] * (j[1][0] * j[2][2] - j[1][2] * j[2][0])
                    + j[0][2] * (j[1][0] * j[2][1] - j[1][1] * j[2][0]);
                let n2 = |u: [f64; 3]| u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
                let (na, nb, nc) = (n2(j[0]), n2(j[1]), n2(j[2]));
                // One square root per point; three where the product leaves the normal range
                // of f64 (or is 0).
                let mut norm = (na * nb * nc).sqrt();
                if !norm.is_normal() {
                    norm = na.sqrt() * nb.sqrt() * nc.sqrt();
                }
                min_det = min_det.min(det);
                min_sj = min_sj.min(if norm > 0.0 { det / norm } else { 0.0 });
            }
        }
    }
    (min_det, min_sj)
}

/// Summary of [`sample_det_jacobian`] over a mesh: the `check` report.
#[derive(Clone, Debug, Serialize)]
pub struct CheckReport {
    pub dimension: usize,
    pub elements: usize,
    pub order: usize,
    pub nodes: usize,
    pub boundary_facets: usize,
    /// Elements with a sampled det J ≤ 0.
    pub invalid: usize,
    pub min_scaled_jacobian: f64,
    pub min_det_jacobian: f64,
    /// Element where the minimum scaled Jacobian occurs.
    pub worst_element: usize,
    /// How the Jacobian was evaluated.
    pub method: &'static str,
}

impl CheckReport {
    pub fn new(mesh: &HighOrderMesh) -> CheckReport {
        let q = sample_det_jacobian(mesh);
        let (worst, w) = q
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.min_scaled_jacobian.total_cmp(&b.1.min_scaled_jacobian))
            .map(|(i, w)| (i, *w))
            .unwrap_or((
                0,
                ElementQuality {
                    min_det_jacobian: f64::NAN,
                    min_scaled_jacobian: f64::NAN,
                },
            ));
        CheckReport {
            dimension: mesh.dim,
            elements: mesh.n_elements(),
            order: mesh.order,
            nodes: mesh.nodes.len(),
            boundary_facets: mesh.n_boundary(),
            invalid: q.iter().filter(|e| !(e.min_det_jacobian > 0.0)).count(),
            min_scaled_jacobian: w.min_scaled_jacobian,
            min_det_jacobian: q
                .iter()
                .map(|e| e.min_det_jacobian)
                .fold(f64::INFINITY, f64::min),
            worst_element: worst,
            method: "sampled on the equispaced lattice of order 2p",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lagrange_basis_interpolates_and_differentiates() {
        for p in 1..=6 {
            let mut v = vec![0.0; p + 1];
            let mut d = vec![0.0; p + 1];
            // Kronecker delta at the nodes.
            for i in 0..=p {
                lagrange_1d(p, i as f64 / p as f64, &mut v, &mut d);
                for (j, &x) in v.iter().enumerate() {
                    assert!((x - (i == j) as u8 as f64).abs() < 1e-12);
                }
            }
            // Reproduces t^p and its derivative at an arbitrary point.
            let t = 0.37;
            lagrange_1d(p, t, &mut v, &mut d);
            let f: f64 = (0..=p)
                .map(|i| v[i] * (i as f64 / p as f64).powi(p as i32))
                .sum();
            let df: f64 = (0..=p)
                .map(|i| d[i] * (i as f64 / p as f64).powi(p as i32))
                .sum();
            assert!((f - t.powi(p as i32)).abs() < 1e-12);
            assert!(
                (df - p as f64 * t.powi(p as i32 - 1)).abs() < 1e-10,
                "p={p}"
            );
        }
    }
}
