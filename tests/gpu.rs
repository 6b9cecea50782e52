//! GPU path: naga validation of every shader (no driver needed), and cross-validation of each
//! kernel against its CPU twin, the f64 reference and independent oracles on lavapipe or a
//! hardware GPU. A missing adapter fails under `CI=true` and is a printed skip elsewhere.

use polyspline::cpu;
use polyspline::gpu::{self, AdapterChoice, GpuContext, Precision};

/// Every shader parses and validates, at both precisions.
#[test]
fn shaders_validate_with_naga() {
    for (name, src) in gpu::SHADERS {
        for prec in [Precision::F32, Precision::F64] {
            let text = gpu::shader_source(src, prec);
            assert!(text.contains("alias real"), "{name}: no `alias real`");
            let module = naga::front::wgsl::parse_str(&text)
                .unwrap_or_else(|e| panic!("{name} ({prec:?}): {}", e.emit_to_string(&text)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::FLOAT64,
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name} ({prec:?}): {e:?}"));
        }
    }
    // Every .wgsl in shaders/ is covered.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    for f in std::fs::read_dir(dir).unwrap() {
        let f = f.unwrap().file_name().into_string().unwrap();
        if f.ends_with(".wgsl") {
            assert!(
                gpu::SHADERS.iter().any(|(n, _)| *n == f),
                "{f} is not validated"
            );
        }
    }
}

use polyspline::fit::{FitParams, assemble};
use polyspline::gpu::cg::{GpuOperator, SPMV_TOL_F32, SPMV_TOL_F64};
use polyspline::gpu::evaluate::{EVALUATE_TOL_F32, EVALUATE_TOL_F64, lattice_params};
use polyspline::gpu::jacobian_check::rounding_bound;
use polyspline::io::read_mesh;
use polyspline::mesh::generate::{grid_2d, grid_3d, star_2d, uniform};
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};
use polyspline::sample::{eval_net, sample};
use polyspline::solve::{CgParams, LinOp, pcg};
use polyspline::spline::SplineSpace;
use polyspline::validity::{det_jacobian_bernstein, det_jacobian_bounds};
use std::path::PathBuf;

/// A GPU context, or None with a visible skip (a failure under `CI=true`).
fn context(prec: Precision) -> Option<GpuContext> {
    match GpuContext::new(AdapterChoice::Any, Some(prec)) {
        Ok(c) => Some(c),
        Err(e) => {
            if std::env::var("CI").as_deref() == Ok("true") {
                panic!("CI=true but no usable GPU adapter: {e}");
            }
            println!("SKIPPED: no GPU adapter ({e})");
            eprintln!("SKIPPED: no GPU adapter ({e})");
            None
        }
    }
}

fn real_meshes() -> Vec<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real");
    let mut out = Vec::new();
    for d in std::fs::read_dir(root).unwrap() {
        let d = d.unwrap().path();
        if d.is_dir() {
            for f in std::fs::read_dir(d).unwrap() {
                out.push(f.unwrap().path());
            }
        }
    }
    out.sort();
    out
}

/// Generated meshes (2D, 3D, irregular) and every real mesh that reads.
fn meshes() -> Vec<(String, LinearMesh)> {
    let mut v = vec![
        ("grid_2d".to_string(), grid_2d(&uniform(7, 0.3), &uniform(5, 0.2))),
        ("grid_3d".to_string(), grid_3d(&uniform(4, 1e3), &uniform(3, 1e3), &uniform(3, 1e3))),
        ("star_2d".to_string(), star_2d(5)),
    ];
    for p in real_meshes() {
        if let Ok(m) = read_mesh(&p, &MeshOptions::default()) {
            v.push((p.file_name().unwrap().to_string_lossy().into(), m));
        }
    }
    v
}

/// Largest distance of a control point from the element's anchor.
fn size(dim: usize, net: &[[f64; 3]; 27]) -> f64 {
    let a = gpu::anchor(dim, net);
    net.iter()
        .flat_map(|p| (0..3).map(move |k| (p[k] - a[k]).abs()))
        .fold(0.0, f64::max)
}

/// Adding the anchor back rounds once more, relative to the coordinates themselves.
const ABS_ROUND: f64 = 4.0 * f64::EPSILON;

fn norm(x: [f64; 3]) -> f64 {
    x.iter().fold(0.0, |m, v| m.max(v.abs()))
}

fn tol_eval(p: Precision) -> f64 {
    match p {
        Precision::F32 => EVALUATE_TOL_F32,
        Precision::F64 => EVALUATE_TOL_F64,
    }
}

/// At most `cap` elements, spread over the mesh.
fn subset(n: usize, cap: usize) -> Vec<usize> {
    let step = n.div_ceil(cap).max(1);
    (0..n).step_by(step).collect()
}

#[test]
fn evaluate_matches_reference_twin_and_affine_oracle() {
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        for (name, mesh) in meshes() {
            let topo = Topology::build(&mesh);
            let s = SplineSpace::build(&mesh, &topo);
            let d = mesh.dim;
            let elems = subset(s.n_elements(), 2000);
            for p in 2..=4 {
                let xi = lattice_params(d, p);
                let queries: Vec<(u32, u32)> = elems
                    .iter()
                    .flat_map(|&e| (0..xi.len() as u32).map(move |t| (e as u32, t)))
                    .collect();
                let got = gpu::evaluate::evaluate(&ctx, d, &|e| s.element_bezier(e), &xi, &queries, true)
                    .unwrap();
                for (i, &(e, t)) in queries.iter().enumerate() {
                    let net = s.element_bezier(e as usize);
                    let want = eval_net(d, &net, xi[t as usize]);
                    let h = size(d, &net);
                    let err = (0..3).map(|k| (got.points[i][k] - want[k]).abs()).fold(0.0, f64::max);
                    assert!(
                        err <= tol_eval(prec) * h + ABS_ROUND * norm(want),
                        "{name} {prec:?} p={p} element {e}: {:?} vs {want:?} (size {h:e})",
                        got.points[i]
                    );
                    // Derivatives against the spline's own evaluation.
                    let (_, dref) = s.eval_with_derivatives(e as usize, xi[t as usize]);
                    for j in 0..d {
                        for k in 0..3 {
                            assert!(
                                (got.derivs[i][j][k] - dref[j][k]).abs() <= 4.0 * tol_eval(prec) * h + 1e-12 * h,
                                "{name} {prec:?} derivative {j} of element {e}: {:?} vs {:?}",
                                got.derivs[i],
                                dref
                            );
                        }
                    }
                }
            }
            // The CPU twin on the same anchored f32/f64 input agrees closely.
            let e0 = elems[0];
            let net = s.element_bezier(e0);
            let a = gpu::anchor(d, &net);
            let xi = lattice_params(d, 3);
            let queries: Vec<(u32, u32)> = (0..xi.len() as u32).map(|t| (e0 as u32, t)).collect();
            let got = gpu::evaluate::evaluate(&ctx, d, &|e| s.element_bezier(e), &xi, &queries, false).unwrap();
            let params = cpu::evaluate::Params {
                dim: d as u32,
                n_queries: queries.len() as u32,
                with_derivs: 0,
                _pad: 0,
            };
            let flat: Vec<f32> = net.iter().flat_map(|p| (0..3).map(move |k| (p[k] - a[k]) as f32)).collect();
            let xi4: Vec<[f32; 4]> = xi.iter().map(|t| [t[0] as f32, t[1] as f32, t[2] as f32, 0.0]).collect();
            let q: Vec<[u32; 2]> = queries.iter().map(|&(_, t)| [0, t]).collect();
            let mut pts = vec![0f32; 3 * q.len()];
            cpu::evaluate::evaluate(&params, &flat, &xi4, &q, &mut pts, &mut []);
            for i in 0..q.len() {
                for k in 0..3 {
                    let twin = a[k] + pts[3 * i + k] as f64;
                    assert!((got.points[i][k] - twin).abs() <= 2.0 * EVALUATE_TOL_F32 * size(d, &net));
                }
            }
        }
    }
}

/// An affine map is reproduced exactly up to rounding, with constant derivatives; an output of
/// zeros (a kernel that wrote nothing) fails.
#[test]
fn evaluate_reproduces_affine_maps() {
    let Some(ctx) = context(Precision::F32) else { return };
    let a = [[1.5, 0.2, -0.3], [0.1, 2.0, 0.4], [-0.2, 0.3, 0.7]];
    let c = [10.0, -5.0, 3.0];
    let f = |t: [f64; 3]| -> [f64; 3] { std::array::from_fn(|k| c[k] + (0..3).map(|j| a[j][k] * t[j]).sum::<f64>()) };
    let net: [[f64; 3]; 27] = std::array::from_fn(|o| f([(o % 3) as f64 / 2.0, (o / 3 % 3) as f64 / 2.0, (o / 9) as f64 / 2.0]));
    let xi = lattice_params(3, 5);
    let q: Vec<(u32, u32)> = (0..3).flat_map(|e| (0..xi.len() as u32).map(move |t| (e, t))).collect();
    let got = gpu::evaluate::evaluate(&ctx, 3, &|_| net, &xi, &q, true).unwrap();
    for (i, &(_, t)) in q.iter().enumerate() {
        let want = f(xi[t as usize]);
        for k in 0..3 {
            assert!((got.points[i][k] - want[k]).abs() < 1e-5, "{:?} vs {want:?}", got.points[i]);
            for j in 0..3 {
                assert!((got.derivs[i][j][k] - a[j][k]).abs() < 1e-5);
            }
        }
    }
}

#[test]
fn gpu_sampling_matches_cpu_sampling() {
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        for (name, mesh) in meshes() {
            if mesh.n_elements() > 20_000 {
                continue;
            }
            let topo = Topology::build(&mesh);
            let s = SplineSpace::build(&mesh, &topo);
            for p in 2..=4 {
                let want = sample(&s, &mesh, &topo, p);
                let got = gpu::evaluate::sample(&ctx, &s, &mesh, &topo, p).unwrap();
                assert_eq!(got.elements, want.elements);
                assert_eq!(got.boundary, want.boundary);
                // Each node's tolerance from the largest element containing it.
                let mut h = vec![0.0f64; want.nodes.len()];
                for e in 0..want.n_elements() {
                    let he = size(mesh.dim, &s.element_bezier(e));
                    for &n in want.element(e) {
                        h[n as usize] = h[n as usize].max(he);
                    }
                }
                for (i, (g, w)) in got.nodes.iter().zip(&want.nodes).enumerate() {
                    let err = (0..3).map(|k| (g[k] - w[k]).abs()).fold(0.0, f64::max);
                    assert!(err <= tol_eval(prec) * h[i] + ABS_ROUND * norm(*w), "{name} {prec:?} p={p} node {i}: {g:?} vs {w:?}");
                }
            }
        }
    }
}

#[test]
fn jacobian_check_matches_reference_twin_and_oracles() {
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        for (name, mesh) in meshes() {
            let topo = Topology::build(&mesh);
            let s = SplineSpace::build(&mesh, &topo);
            let d = mesh.dim;
            let elems = subset(s.n_elements(), 3000);
            let got = gpu::jacobian_check::jacobian_check(&ctx, d, &elems, &|e| s.element_bezier(e)).unwrap();
            let cert = gpu::jacobian_check::certify(&ctx, d, &elems, &|e| s.element_bezier(e), 6).unwrap();
            for (i, &e) in elems.iter().enumerate() {
                let net = s.element_bezier(e);
                let exact = det_jacobian_bernstein(d, &net);
                let lo = exact.coef.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = exact.coef.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let (c, xmax) = got[i];
                let err = rounding_bound(prec, d, c.factor_max, xmax);
                assert!(err > 0.0 && c.factor_max[0] > 0.0, "{name}: empty GPU result for {e}");
                assert!((c.min - lo).abs() <= err, "{name} {prec:?} element {e}: min {} vs {lo} (bound {err:e})", c.min);
                assert!((c.max - hi).abs() <= err, "{name} {prec:?} element {e}: max {} vs {hi}", c.max);
                // Certificates: same sign as the CPU's, values within the bound.
                let want = det_jacobian_bounds(d, &net, 6);
                assert_eq!(cert[i].certified_positive(), want.certified_positive(), "{name} element {e}");
                assert!((cert[i].lower - want.lower).abs() <= 2.0 * err, "{name} element {e}: {:?} vs {want:?}", cert[i]);
                assert!(cert[i].lower <= want.lower + 1e-300);
            }
            // Twin, same precision (f32 here), first elements.
            let few = &elems[..elems.len().min(50)];
            let nets: Vec<f32> = few
                .iter()
                .flat_map(|&e| {
                    let net = s.element_bezier(e);
                    let a = gpu::anchor(d, &net);
                    net.into_iter().flat_map(move |p| (0..3).map(move |k| (p[k] - a[k]) as f32))
                })
                .collect();
            let mut twin = vec![[0f32; 4]; 2 * few.len()];
            let params = cpu::jacobian_check::Params {
                dim: d as u32,
                n_elements: few.len() as u32,
                _pad0: 0,
                _pad1: 0,
            };
            cpu::jacobian_check::jacobian_check(&params, &nets, &mut twin);
            for (i, &e) in few.iter().enumerate() {
                let (c, xmax) = got[i];
                let err = rounding_bound(Precision::F32, d, c.factor_max, xmax);
                assert!((twin[2 * i][0] as f64 - c.min).abs() <= 2.0 * err, "{name}: twin {e}");
                assert!((twin[2 * i][2] as f64 - c.max).abs() <= 2.0 * err, "{name}: twin {e}");
            }
        }
    }
}

/// An affine element has det J = det A everywhere: every coefficient equals it.
#[test]
fn jacobian_check_affine_oracle() {
    let Some(ctx) = context(Precision::F32) else { return };
    let a = [[1.5, 0.2, -0.3], [0.1, 2.0, 0.4], [-0.2, 0.3, 0.7]];
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    let net: [[f64; 3]; 27] = std::array::from_fn(|o| {
        let t = [(o % 3) as f64 / 2.0, (o / 3 % 3) as f64 / 2.0, (o / 9) as f64 / 2.0];
        std::array::from_fn(|k| 1e4 + (0..3).map(|j| a[j][k] * t[j]).sum::<f64>())
    });
    let got = gpu::jacobian_check::jacobian_check(&ctx, 3, &[0, 1], &|_| net).unwrap();
    for (c, _) in got {
        for v in [c.min, c.max, c.min_corner] {
            assert!((v - det).abs() < 1e-5 * det.abs(), "{v} vs {det}");
        }
    }
}

fn normal_system(mesh: &LinearMesh) -> (polyspline::fit::NormalMatrix, Vec<[f64; 3]>) {
    let topo = Topology::build(mesh);
    let s = SplineSpace::build(mesh, &topo);
    assemble(&s, mesh, &topo, &FitParams::default().weights)
}

#[test]
fn spmv_matches_cpu_and_row_sums() {
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        for (name, mesh) in meshes().into_iter().take(6) {
            let (k, _) = normal_system(&mesh);
            let op = GpuOperator::new(&ctx, &k).unwrap();
            let x: Vec<[f64; 3]> = (0..k.n).map(|i| [1.0, (i % 7) as f64 - 3.0, ((i * 31) % 11) as f64 / 11.0]).collect();
            let mut want = vec![[0.0; 3]; k.n];
            k.apply(&x, &mut want);
            let got = op.try_apply(&x).unwrap();
            let tol = match prec {
                Precision::F32 => SPMV_TOL_F32,
                Precision::F64 => SPMV_TOL_F64,
            };
            for r in 0..k.n {
                let scale: f64 = (k.indptr[r]..k.indptr[r + 1])
                    .map(|j| k.data[j].abs() * 3.0f64.max(1.0))
                    .sum();
                for c in 0..3 {
                    assert!((got[r][c] - want[r][c]).abs() <= tol * scale, "{name} {prec:?} row {r}: {:?} vs {:?}", got[r], want[r]);
                }
                // Oracle: with x = 1 in lane 0, y is the row sum.
                let sum: f64 = (k.indptr[r]..k.indptr[r + 1]).map(|j| k.data[j]).sum();
                assert!((got[r][0] - sum).abs() <= tol * scale);
            }
            assert_eq!(op.nrows(), k.n);
        }
    }
}

#[test]
fn gpu_cg_matches_cpu_cg() {
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        for (name, mesh) in meshes().into_iter().take(6) {
            let (k, b) = normal_system(&mesh);
            let params = CgParams {
                rel_tol: 1e-9,
                ..Default::default()
            };
            let mut want = vec![[0.0; 3]; k.n];
            let ci = pcg(&k, &b, &mut want, &params, |_, _| {}).unwrap();
            let mut got = vec![[0.0; 3]; k.n];
            let gi = gpu::cg::pcg(&ctx, &k, &b, &mut got, &params, |_, _| {})
                .unwrap_or_else(|e| panic!("{name} {prec:?}: {e}"));
            // Independent check of the residual in f64.
            let mut ax = vec![[0.0; 3]; k.n];
            k.apply(&got, &mut ax);
            for c in 0..3 {
                let bn = b.iter().map(|v| v[c] * v[c]).sum::<f64>().sqrt();
                let rn = b.iter().zip(&ax).map(|(b, a)| (b[c] - a[c]).powi(2)).sum::<f64>().sqrt();
                assert!(rn <= 1e-9 * bn + 1e-300, "{name} {prec:?}: residual {rn:e} vs |b| {bn:e}");
            }
            let xn = want.iter().flatten().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
            let dn = want.iter().zip(&got).flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).powi(2))).sum::<f64>().sqrt();
            assert!(dn <= 1e-5 * xn, "{name} {prec:?}: solutions differ by {dn:e} (|x| {xn:e})");
            if prec == Precision::F64 {
                assert!(gi.iterations.abs_diff(ci.iterations) <= 3 + ci.iterations / 20, "{name}: {gi:?} vs {ci:?}");
            }
        }
    }
}
