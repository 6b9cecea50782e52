//! The normal equations: the assembled matrix and the matrix-free operator agree, K is
//! symmetric positive definite, and the fit solves the least-squares problem (its residual is
//! orthogonal to every basis direction).

use polyspline::fit::{FitSpace, FitWeights, MatrixFree, assemble};
use polyspline::io::read_mesh;
use polyspline::math::bernstein::net_len;
use polyspline::mesh::generate::{extrude, star_2d, uniform};
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};
use polyspline::solve::LinOp;
use polyspline::spline::SplineSpace;
use std::path::PathBuf;

fn meshes() -> Vec<LinearMesh> {
    let real = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real");
    vec![
        star_2d(5),
        extrude(&star_2d(3), &uniform(3, 0.7)),
        read_mesh(&real.join("dealii/example.msh"), &MeshOptions::default()).unwrap(),
        read_mesh(
            &real.join("mfem/cylinder-hex.mesh"),
            &MeshOptions::default(),
        )
        .unwrap(),
    ]
}

#[test]
fn assembled_and_matrix_free_operators_agree() {
    for m in meshes() {
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        for w in [FitWeights::position(), FitWeights::frame()] {
            let (k, _) = assemble(&s, &m, &t, &w);
            let mf = MatrixFree::new(&s, &m, &t, &w);
            let n = k.nrows();
            let x: Vec<[f64; 3]> = (0..n)
                .map(|i| [(i as f64 * 0.37).sin(), (i as f64 * 0.11).cos(), 1.0])
                .collect();
            let (mut y1, mut y2) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
            k.apply(&x, &mut y1);
            mf.apply(&x, &mut y2);
            let scale = y1
                .iter()
                .flat_map(|v| v.iter())
                .fold(0.0f64, |a, b| a.max(b.abs()));
            for (a, b) in y1.iter().zip(&y2) {
                for d in 0..3 {
                    assert!((a[d] - b[d]).abs() <= 1e-12 * scale, "{a:?} vs {b:?}");
                }
            }
            for (a, b) in k.diagonal().iter().zip(mf.diagonal()) {
                assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0));
                assert!(*a > 0.0, "K is positive definite: its diagonal is positive");
            }
            // Symmetry: yᵀ K x = xᵀ K y.
            let z: Vec<[f64; 3]> = (0..n)
                .map(|i| [(i as f64 * 0.91).cos(), 0.5, (i as f64).sin()])
                .collect();
            let mut kz = vec![[0.0; 3]; n];
            k.apply(&z, &mut kz);
            for d in 0..3 {
                let a: f64 = (0..n).map(|i| z[i][d] * y1[i][d]).sum();
                let b: f64 = (0..n).map(|i| x[i][d] * kz[i][d]).sum();
                assert!((a - b).abs() <= 1e-10 * a.abs().max(1.0));
            }
        }
    }
}

/// At the least-squares minimum, moving any one control point in any direction does not
/// decrease Q: the gradient, evaluated by finite differences of Q itself, vanishes.
#[test]
fn the_fit_minimises_the_objective() {
    let m = star_2d(5);
    let t = Topology::build(&m);
    let s = SplineSpace::build(&m, &t);
    let w = FitWeights::position();
    let params = polyspline::fit::FitParams {
        weights: w,
        cg: polyspline::solve::CgParams {
            rel_tol: 1e-13,
            ..Default::default()
        },
        ..Default::default()
    };
    let (c, _) = polyspline::fit::fit(&s, &m, &t, &params, |_, _| {}).unwrap();
    // Q = Σ_e Σ_i w_i |x_e(u_i) - P_e(u_i)|² over the 3x3 lattice.
    let q = |cps: &[[f64; 3]]| -> f64 {
        let mut total = 0.0;
        for e in 0..m.n_elements() {
            let x = m.element_coords(e);
            let net = s.bezier_net_with(e, cps);
            for j in 0..3 {
                for i in 0..3 {
                    let u = [i as f64 / 2.0, j as f64 / 2.0, 0.0];
                    let corner = i != 1 && j != 1;
                    let c_idx = match (i, j) {
                        (0, 0) => 0,
                        (2, 0) => 1,
                        (2, 2) => 2,
                        (0, 2) => 3,
                        _ => 0,
                    };
                    let wd = if corner {
                        if t.vertex_on_boundary[m.element(e)[c_idx] as usize] {
                            w.boundary_corner
                        } else {
                            w.corner
                        }
                    } else {
                        w.midpoint
                    };
                    let p = polyspline::sample::multilinear(2, &x, u);
                    let y = polyspline::sample::eval_net(2, &net, u);
                    total += wd * ((y[0] - p[0]).powi(2) + (y[1] - p[1]).powi(2));
                }
            }
        }
        total
    };
    let q0 = q(&c);
    let h = 1e-4;
    for i in (0..c.len()).step_by(3) {
        for d in 0..2 {
            let mut plus = c.clone();
            plus[i][d] += h;
            let mut minus = c.clone();
            minus[i][d] -= h;
            let grad = (q(&plus) - q(&minus)) / (2.0 * h);
            assert!(grad.abs() < 1e-6, "dQ/dC[{i}][{d}] = {grad}");
            assert!(q(&plus) >= q0 - 1e-12 && q(&minus) >= q0 - 1e-12);
        }
    }
}

/// Point-Jacobi and block-Jacobi PCG both solve the normal equations: the residual, recomputed
/// here with K, meets the tolerance, the two solutions agree, and the aggregates save
/// iterations.
#[test]
fn jacobi_and_block_jacobi_solve_the_normal_equations() {
    use polyspline::solve::{CgParams, CgPreconditioner, pcg};
    for m in meshes() {
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let (k, b) = assemble(&s, &m, &t, &FitWeights::position());
        let mut sols = Vec::new();
        let mut its = Vec::new();
        for pre in [
            CgPreconditioner::Jacobi,
            CgPreconditioner::BlockJacobi { size: 64 },
        ] {
            let params = CgParams {
                rel_tol: 1e-10,
                preconditioner: pre,
                ..Default::default()
            };
            let mut x = vec![[0.0; 3]; k.n()];
            let info = pcg(&k, &b, &mut x, &params, |_, _| {}).unwrap();
            let mut kx = vec![[0.0; 3]; k.n()];
            k.apply(&x, &mut kx);
            for d in 0..3 {
                let bn: f64 = b.iter().map(|v| v[d] * v[d]).sum::<f64>().sqrt();
                let rn: f64 = b
                    .iter()
                    .zip(&kx)
                    .map(|(b, a)| (b[d] - a[d]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                assert!(rn <= 1.01e-10 * bn + 1e-300, "{pre:?}: {rn:e} vs {bn:e}");
            }
            sols.push(x);
            its.push(info.iterations);
        }
        let scale = sols[0]
            .iter()
            .flatten()
            .fold(0.0f64, |a, b| a.max(b.abs()))
            .max(1e-300);
        for (a, b) in sols[0].iter().zip(&sols[1]) {
            for d in 0..3 {
                assert!((a[d] - b[d]).abs() <= 1e-6 * scale, "{a:?} vs {b:?}");
            }
        }
        assert!(
            its[1] * 10 <= its[0] * 7,
            "block Jacobi {} vs Jacobi {} iterations",
            its[1],
            its[0]
        );
    }
}

/// E_eᵀ f by sum factorisation (what the right-hand side uses) equals the product with the
/// explicitly expanded extraction rows, on spline and constrained Q2 elements.
#[test]
fn transposed_extraction_by_sum_factorisation_matches_the_rows() {
    for m in meshes() {
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let n = s.control_points().len();
        let nb = net_len(s.dim());
        for e in 0..s.n_elements() {
            let f: polyspline::math::BezierNet = std::array::from_fn(|i| {
                let x = (e * 31 + i) as f64;
                [x.sin(), x.cos(), (0.3 * x).sin()]
            });
            let mut pairs = Vec::new();
            s.add_transposed(e, &f, &mut pairs);
            let mut got = vec![[0.0; 3]; n];
            for (g, v) in pairs {
                for c in 0..3 {
                    got[g as usize][c] += v[c];
                }
            }
            let (mut o, mut cols, mut w) = (Vec::new(), Vec::new(), Vec::new());
            s.element_rows(e, &mut o, &mut cols, &mut w);
            let mut want = vec![[0.0; 3]; n];
            for i in 0..nb {
                for k in o[i]..o[i + 1] {
                    for c in 0..3 {
                        want[cols[k] as usize][c] += w[k] * f[i][c];
                    }
                }
            }
            for (a, b) in got.iter().zip(&want) {
                for c in 0..3 {
                    assert!((a[c] - b[c]).abs() <= 1e-12, "element {e}: {a:?} vs {b:?}");
                }
            }
        }
    }
}

/// The row-parallel assembly on a mesh with spline elements, Q2 elements of own nodes and Q2
/// elements with constrained nodes (a generated cylinder: valence-3 edges and a boundary):
/// K equals the matrix-free operator on random vectors, its columns are sorted and unique,
/// and it is bitwise the same on one and on two threads.
#[test]
fn row_parallel_assembly_matches_the_matrix_free_operator() {
    use polyspline::mesh::generate::{Kind, generate};
    let m = generate(Kind::Cylinder, 400);
    let t = Topology::build(&m);
    let s = SplineSpace::build(&m, &t);
    let mut ids = Vec::new();
    let own = (0..s.n_elements())
        .filter(|&e| s.element_pattern(e, &mut ids).is_none())
        .count();
    assert!(
        own > 0 && own < s.n_elements(),
        "{own} of {}",
        s.n_elements()
    );
    assert!(t.vertex_on_boundary.iter().any(|&b| b));
    for w in [FitWeights::position(), FitWeights::frame()] {
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| assemble(&s, &m, &t, &w))
        };
        let ((k, b), (k2, b2)) = (on(1), on(2));
        assert_eq!(k.indptr(), k2.indptr());
        assert_eq!(k.indices(), k2.indices());
        assert!(
            k.data()
                .iter()
                .zip(k2.data())
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
        assert!(
            b.iter()
                .zip(&b2)
                .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits))
        );
        for r in 0..k.n() {
            let cols = &k.indices()[k.indptr()[r]..k.indptr()[r + 1]];
            assert!(
                cols.windows(2).all(|p| p[0] < p[1]),
                "row {r} not sorted/unique"
            );
            assert!(
                cols.binary_search(&(r as u32)).is_ok(),
                "row {r} lacks its diagonal"
            );
        }
        let mf = MatrixFree::new(&s, &m, &t, &w);
        let n = k.nrows();
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rand = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..3 {
            let x: Vec<[f64; 3]> = (0..n).map(|_| [rand(), rand(), rand()]).collect();
            let (mut y1, mut y2) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
            k.apply(&x, &mut y1);
            mf.apply(&x, &mut y2);
            let scale = y2.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
            for (a, b) in y1.iter().zip(&y2) {
                for d in 0..3 {
                    assert!((a[d] - b[d]).abs() <= 1e-12 * scale, "{a:?} vs {b:?}");
                }
            }
        }
    }
}

/// The right-hand side is F − K C0 = −½ ∇D(C0), D = Σ_e Σ_i w_i ‖x_e(u_i) − P_e(u_i)‖² the
/// position misfit over the 3×3×3 lattice (the frame term is stationary at C0): checked by
/// central differences of D, evaluated here from the Bézier nets and the multilinear map, on
/// a 3D mesh with Q2 elements, with chord and smooth targets and with and without frames.
#[test]
fn right_hand_side_is_the_gradient_of_the_misfit() {
    use polyspline::fit::{SmoothParams, SmoothTargets, assemble_with_targets};
    use polyspline::mesh::generate::{Kind, generate};
    use polyspline::sample::{eval_net, multilinear};
    let m = generate(Kind::Cylinder, 200);
    let t = Topology::build(&m);
    let s = SplineSpace::build(&m, &t);
    let smooth = SmoothTargets::build(&m, &t, &SmoothParams::default());
    // Lattice corner (x, y, z ∈ {0, 2}) → hex vertex.
    const CORNER: [usize; 8] = [0, 1, 3, 2, 4, 5, 7, 6];
    for w in [FitWeights::position(), FitWeights::frame()] {
        for targets in [None, Some(&smooth)] {
            let (_, rhs) = assemble_with_targets(&s, &m, &t, &w, targets);
            let misfit = |cps: &[[f64; 3]]| -> f64 {
                let mut total = 0.0;
                for e in 0..m.n_elements() {
                    let x = m.element_coords(e);
                    let net = s.bezier_net_with(e, cps);
                    let shift = targets.map(|st| st.element_corrections(&m, &t, e));
                    for i in 0..27 {
                        let l = [i % 3, (i / 3) % 3, i / 9];
                        let u = l.map(|c| c as f64 / 2.0);
                        let wd = if l.contains(&1) {
                            w.midpoint
                        } else {
                            let v = m.element(e)[CORNER[l[0] / 2 + l[1] + 2 * l[2]]];
                            if t.vertex_on_boundary[v as usize] {
                                w.boundary_corner
                            } else {
                                w.corner
                            }
                        };
                        let mut p = multilinear(3, &x, u);
                        if let Some(sh) = &shift {
                            p = std::array::from_fn(|d| p[d] + sh[i][d]);
                        }
                        let y = eval_net(3, &net, u);
                        total += wd * (0..3).map(|d| (y[d] - p[d]).powi(2)).sum::<f64>();
                    }
                }
                total
            };
            let c0 = &s.control_points;
            let scale = rhs.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
            assert!(scale > 0.0);
            let h = 1e-3;
            for c in (0..c0.len()).step_by(7) {
                for d in 0..3 {
                    let (mut plus, mut minus) = (c0.clone(), c0.clone());
                    plus[c][d] += h;
                    minus[c][d] -= h;
                    let grad = (misfit(&plus) - misfit(&minus)) / (2.0 * h);
                    assert!(
                        (rhs[c][d] + 0.5 * grad).abs() <= 1e-7 * scale,
                        "control point {c}, component {d}: {} vs {}",
                        rhs[c][d],
                        -0.5 * grad
                    );
                }
            }
        }
    }
}

/// A fit started from given control points meets the same tolerance as from the initial map:
/// from its own result it needs no iteration and returns it; from a perturbed result it comes
/// back to it within the CG tolerance (on a graded mesh, where the unknowns are rescaled by
/// size level, so the start must be carried into the scaled unknowns correctly).
#[test]
fn a_started_fit_reaches_the_same_control_points() {
    use polyspline::fit::{
        FitParams, Summing, fit_with_targets, fit_with_targets_from, size_levels,
    };
    let real = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real");
    let m = read_mesh(
        &real.join("trixi-juliacon2024-naca4412/NACA4412_2_2D_unique.inp"),
        &MeshOptions::default(),
    )
    .unwrap();
    assert!(size_levels(&m).iter().any(|&l| l > 0), "the mesh is graded");
    let t = Topology::build(&m);
    let s = SplineSpace::build(&m, &t);
    let p = FitParams::smooth();
    let targets = polyspline::fit::smooth_targets(&m, &t, &p);
    fn solve(
        k: polyspline::fit::NormalMatrix,
        b: &[[f64; 3]],
        x: &mut [[f64; 3]],
        cg: &polyspline::solve::CgParams,
    ) -> Result<polyspline::solve::CgInfo, polyspline::solve::CgError> {
        polyspline::solve::pcg(&k, b, x, cg, |_, _| {})
    }
    let (cold, cold_info) = fit_with_targets(&s, &m, &t, &p, targets.as_ref(), solve).unwrap();
    let (lo, hi) = m.bounding_box();
    let diag = (0..3).map(|d| (hi[d] - lo[d]).powi(2)).sum::<f64>().sqrt();
    let far = |a: &[[f64; 3]], b: &[[f64; 3]]| {
        a.iter()
            .zip(b)
            .flat_map(|(a, b)| (0..3).map(move |d| (a[d] - b[d]).abs()))
            .fold(0.0f64, f64::max)
            / diag
    };
    let (again, info) = fit_with_targets_from(
        &s,
        &m,
        &t,
        &p,
        targets.as_ref(),
        (Some(&cold[..]), Summing::Host),
        solve,
    )
    .unwrap();
    assert!(
        info.cg.iterations <= 1,
        "{} iterations from the solution",
        info.cg.iterations
    );
    assert!(far(&again, &cold) < 1e-12, "{:e}", far(&again, &cold));
    let nudged: Vec<[f64; 3]> = cold
        .iter()
        .enumerate()
        .map(|(i, c)| [c[0] + 1e-3 * (i as f64 * 0.37).sin(), c[1], c[2]])
        .collect();
    let (back, info) = fit_with_targets_from(
        &s,
        &m,
        &t,
        &p,
        targets.as_ref(),
        (Some(&nudged[..]), Summing::Host),
        solve,
    )
    .unwrap();
    assert!(info.cg.iterations > 0);
    assert!(info.cg.iterations <= cold_info.cg.iterations + 10);
    // Both stop at the same relative residual: as close to the converged fit as each other.
    let mut tight = p.clone();
    tight.cg.rel_tol = 1e-12;
    let (exact, _) = fit_with_targets(&s, &m, &t, &tight, targets.as_ref(), solve).unwrap();
    let (e_cold, e_back) = (far(&cold, &exact), far(&back, &exact));
    assert!(e_cold < 1e-4 && e_back < 1e-4, "{e_cold:e} {e_back:e}");
    assert!(e_back < 4.0 * e_cold, "{e_cold:e} {e_back:e}");
}
