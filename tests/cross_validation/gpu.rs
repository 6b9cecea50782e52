//! GPU path: naga validation of every shader (no driver needed), and cross-validation of each
//! kernel against its CPU twin, the f64 reference and independent oracles on lavapipe or a
//! hardware GPU. A missing adapter fails under `CI=true` and is a printed skip elsewhere.

use crate::common::{self, real_meshes};
use crate::executors;

use polyspline::exec::cpu;
use polyspline::exec::gpu::{self, AdapterChoice, GpuContext, Precision};
use polyspline::math::BezierNet;

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

use polyspline::exec::gpu::cg::{GpuOperator, SPMV_TOL_F32, SPMV_TOL_F64};
use polyspline::exec::gpu::evaluate::{EVALUATE_TOL_F32, EVALUATE_TOL_F64, lattice_params};
use polyspline::exec::gpu::jacobian_check::rounding_bound;
use polyspline::fit::{FitParams, assemble};
use polyspline::io::read_mesh;
use polyspline::mesh::generate::{grid_2d, grid_3d, star_2d, uniform};
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};
use polyspline::sample::{eval_net, sample};
use polyspline::solve::{CgParams, LinOp};
use polyspline::spline::SplineSpace;
use polyspline::validity::{Certifier, det_jacobian_bernstein, det_jacobian_bounds};
use std::path::PathBuf;

/// A GPU context, or None with a visible skip (a failure under `CI=true`).
fn context(prec: Precision) -> Option<GpuContext> {
    match GpuContext::new(AdapterChoice::Any, Some(prec)) {
        Ok(c) => Some(c),
        Err(e) => {
            common::skip(&common::current_test(), &format!("no GPU adapter ({e})"));
            None
        }
    }
}

/// Generated meshes (2D, 3D, irregular) and every real mesh that reads.
fn meshes() -> Vec<(String, LinearMesh)> {
    let mut v = vec![
        (
            "grid_2d".to_string(),
            grid_2d(&uniform(7, 0.3), &uniform(5, 0.2)),
        ),
        (
            "grid_3d".to_string(),
            grid_3d(&uniform(4, 1e3), &uniform(3, 1e3), &uniform(3, 1e3)),
        ),
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
fn size(dim: usize, net: &BezierNet) -> f64 {
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
                let got =
                    gpu::evaluate::evaluate(&ctx, d, &|e| s.element_bezier(e), &xi, &queries, true)
                        .unwrap();
                for (i, &(e, t)) in queries.iter().enumerate() {
                    let net = s.element_bezier(e as usize);
                    let want = eval_net(d, &net, xi[t as usize]);
                    let h = size(d, &net);
                    let err = (0..3)
                        .map(|k| (got.points[i][k] - want[k]).abs())
                        .fold(0.0, f64::max);
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
                                (got.derivs[i][j][k] - dref[j][k]).abs()
                                    <= 4.0 * tol_eval(prec) * h + 1e-12 * h,
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
            let got =
                gpu::evaluate::evaluate(&ctx, d, &|e| s.element_bezier(e), &xi, &queries, false)
                    .unwrap();
            let params = cpu::evaluate::Params {
                dim: d as u32,
                n_queries: queries.len() as u32,
                with_derivs: 0,
                _pad: 0,
            };
            let flat: Vec<f32> = net
                .iter()
                .flat_map(|p| (0..3).map(move |k| (p[k] - a[k]) as f32))
                .collect();
            let xi4: Vec<[f32; 4]> = xi
                .iter()
                .map(|t| [t[0] as f32, t[1] as f32, t[2] as f32, 0.0])
                .collect();
            let q: Vec<[u32; 2]> = queries.iter().map(|&(_, t)| [0, t]).collect();
            let mut pts = vec![0f32; 3 * q.len()];
            cpu::evaluate::evaluate(&params, &flat, &xi4, &q, &mut pts, &mut []);
            for i in 0..q.len() {
                for k in 0..3 {
                    let twin = a[k] + pts[3 * i + k] as f64;
                    assert!(
                        (got.points[i][k] - twin).abs() <= 2.0 * EVALUATE_TOL_F32 * size(d, &net)
                    );
                }
            }
        }
    }
}

/// An affine map is reproduced exactly up to rounding, with constant derivatives; an output of
/// zeros (a kernel that wrote nothing) fails.
#[test]
fn evaluate_reproduces_affine_maps() {
    let Some(ctx) = context(Precision::F32) else {
        return;
    };
    let a = [[1.5, 0.2, -0.3], [0.1, 2.0, 0.4], [-0.2, 0.3, 0.7]];
    let c = [10.0, -5.0, 3.0];
    let f = |t: [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|k| c[k] + (0..3).map(|j| a[j][k] * t[j]).sum::<f64>())
    };
    let net: BezierNet = std::array::from_fn(|o| {
        f([
            (o % 3) as f64 / 2.0,
            (o / 3 % 3) as f64 / 2.0,
            (o / 9) as f64 / 2.0,
        ])
    });
    let xi = lattice_params(3, 5);
    let q: Vec<(u32, u32)> = (0..3)
        .flat_map(|e| (0..xi.len() as u32).map(move |t| (e, t)))
        .collect();
    let got = gpu::evaluate::evaluate(&ctx, 3, &|_| net, &xi, &q, true).unwrap();
    for (i, &(_, t)) in q.iter().enumerate() {
        let want = f(xi[t as usize]);
        for k in 0..3 {
            assert!(
                (got.points[i][k] - want[k]).abs() < 1e-5,
                "{:?} vs {want:?}",
                got.points[i]
            );
            for j in 0..3 {
                assert!((got.derivs[i][j][k] - a[j][k]).abs() < 1e-5);
            }
        }
    }
}

/// Order 2–4 sampling, one body per executor: the same elements and boundary, nodes within
/// the evaluation tolerance of each node's largest element.
#[test]
fn gpu_sampling_matches_cpu_sampling() {
    const TEST: &str = "gpu_sampling_matches_cpu_sampling";
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        let executors = executors::cpu_and_gpu(&ctx);
        for (name, mesh) in meshes() {
            if mesh.n_elements() > 20_000 {
                continue;
            }
            let topo = Topology::build(&mesh);
            let s = SplineSpace::build(&mesh, &topo);
            for p in 2..=4 {
                let [want, got] = executors::on_each(&executors, |x| {
                    x.sample(&s, &mesh, &topo, p)
                        .unwrap_or_else(|e| panic!("{name} {prec:?} p={p} {}: {e}", x.name()))
                });
                let outputs = || {
                    let case = format!("{name}.{prec:?}.p{p}");
                    executors::dump(TEST, &case, &[("cpu", &want), ("gpu", &got)])
                };
                assert!(
                    got.elements == want.elements,
                    "{name} {prec:?} p={p}: element numbering differs; {}",
                    outputs()
                );
                assert!(
                    got.boundary == want.boundary,
                    "{name} {prec:?} p={p}: boundary differs; {}",
                    outputs()
                );
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
                    assert!(
                        err <= tol_eval(prec) * h[i] + ABS_ROUND * norm(*w),
                        "{name} {prec:?} p={p} node {i}: {g:?} vs {w:?}; {}",
                        outputs()
                    );
                }
            }
        }
    }
}

/// The factor magnitudes of the kernel's rounding bound, computed here in f64 from the
/// anchored net: per factor, max |2 (P[q + e_d] − P[q])| over its coefficients and components
/// (the factors differentiate directions 1, 2, 0 in 3D and 0, 1 in 2D, as the kernel orders
/// them). The test's tolerances come from these, not from the magnitudes the kernel reports,
/// so a kernel reporting a huge magnitude cannot widen its own tolerance.
fn cpu_factor_max(dim: usize, net: &BezierNet) -> [f64; 3] {
    let a = gpu::anchor(dim, net);
    let p = |q: [usize; 3], c: usize| net[q[0] + 3 * q[1] + 9 * q[2]][c] - a[c];
    let dirs: &[usize] = if dim == 3 { &[1, 2, 0] } else { &[0, 1] };
    let mut out = [0.0; 3];
    for (f, &d) in dirs.iter().enumerate() {
        for k in 0..if dim == 3 { 3 } else { 1 } {
            for j in 0..3 {
                for i in 0..3 {
                    let q = [i, j, k];
                    if q[d] == 2 {
                        continue;
                    }
                    let mut hi = q;
                    hi[d] += 1;
                    for c in 0..3 {
                        out[f] = f64::max(out[f], (2.0 * (p(hi, c) - p(q, c))).abs());
                    }
                }
            }
        }
    }
    out
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
            let got =
                gpu::jacobian_check::jacobian_check(&ctx, d, &elems, &|e| s.element_bezier(e))
                    .unwrap();
            let cert =
                gpu::jacobian_check::certify(&ctx, d, &elems, &|e| s.element_bezier(e), 6).unwrap();
            for (i, &e) in elems.iter().enumerate() {
                let net = s.element_bezier(e);
                let exact = det_jacobian_bernstein(d, &net);
                let lo = exact.coef.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = exact.coef.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let (c, xmax) = got[i];
                let fmax = cpu_factor_max(d, &net);
                let err = rounding_bound(prec, d, fmax, xmax);
                // The reported magnitudes are the CPU's, up to the rounding of the anchored input
                // and of one difference (the δ of `rounding_bound`, doubled).
                for k in 0..d {
                    let slack = 2.0 * prec.epsilon() * (4.0 * xmax + fmax[k]);
                    assert!(
                        (c.factor_max[k] - fmax[k]).abs() <= slack,
                        "{name} {prec:?} element {e}: factor magnitudes {:?} vs {fmax:?}",
                        c.factor_max
                    );
                }
                assert!(err > 0.0 && fmax[0] > 0.0, "{name}: empty net {e}");
                assert!(
                    (c.min - lo).abs() <= err,
                    "{name} {prec:?} element {e}: min {} vs {lo} (bound {err:e})",
                    c.min
                );
                assert!(
                    (c.max - hi).abs() <= err,
                    "{name} {prec:?} element {e}: max {} vs {hi}",
                    c.max
                );
                // Certificates: same sign as the CPU's, values within the bound.
                let want = det_jacobian_bounds(d, &net, 6);
                assert_eq!(
                    cert[i].certified_positive(),
                    want.certified_positive(),
                    "{name} element {e}"
                );
                assert!(
                    (cert[i].lower - want.lower).abs() <= 2.0 * err,
                    "{name} element {e}: {:?} vs {want:?}",
                    cert[i]
                );
                assert!(cert[i].lower <= want.lower + 1e-300);
            }
            // Twin, same precision (f32 here), first elements.
            let few = &elems[..elems.len().min(50)];
            let nets: Vec<f32> = few
                .iter()
                .flat_map(|&e| {
                    let net = s.element_bezier(e);
                    let a = gpu::anchor(d, &net);
                    net.into_iter()
                        .flat_map(move |p| (0..3).map(move |k| (p[k] - a[k]) as f32))
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
                let fmax = cpu_factor_max(d, &s.element_bezier(e));
                let err = rounding_bound(Precision::F32, d, fmax, xmax);
                assert!(
                    (twin[2 * i][0] as f64 - c.min).abs() <= 2.0 * err,
                    "{name}: twin {e}"
                );
                assert!(
                    (twin[2 * i][2] as f64 - c.max).abs() <= 2.0 * err,
                    "{name}: twin {e}"
                );
            }
        }
    }
}

/// An affine element has det J = det A everywhere: every coefficient equals it.
#[test]
fn jacobian_check_affine_oracle() {
    let Some(ctx) = context(Precision::F32) else {
        return;
    };
    let a = [[1.5, 0.2, -0.3], [0.1, 2.0, 0.4], [-0.2, 0.3, 0.7]];
    let det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
        - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    let net: BezierNet = std::array::from_fn(|o| {
        let t = [
            (o % 3) as f64 / 2.0,
            (o / 3 % 3) as f64 / 2.0,
            (o / 9) as f64 / 2.0,
        ];
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

/// `op`'s product with a test vector is `k`'s host product, row by row within the spmv
/// tolerance of the row's magnitudes; and with 1 in lane 0, lane 0 is the row sum.
fn assert_product_is_the_hosts(
    op: &GpuOperator,
    k: &polyspline::fit::NormalMatrix,
    prec: Precision,
    case: &str,
) {
    let x: Vec<[f64; 3]> = (0..k.n())
        .map(|i| [1.0, (i % 7) as f64 - 3.0, ((i * 31) % 11) as f64 / 11.0])
        .collect();
    let mut want = vec![[0.0; 3]; k.n()];
    k.apply(&x, &mut want);
    let got = op.try_apply(&x).unwrap();
    let tol = match prec {
        Precision::F32 => SPMV_TOL_F32,
        Precision::F64 => SPMV_TOL_F64,
    };
    for r in 0..k.n() {
        let row = k.indptr()[r]..k.indptr()[r + 1];
        let scale: f64 = row.clone().map(|j| k.data()[j].abs() * 3.0).sum();
        for c in 0..3 {
            assert!(
                (got[r][c] - want[r][c]).abs() <= tol * scale,
                "{case} {prec:?} row {r}: {:?} against {:?}",
                got[r],
                want[r]
            );
        }
        // Oracle: with x = 1 in lane 0, y is the row sum.
        let sum: f64 = row.map(|j| k.data()[j]).sum();
        assert!(
            (got[r][0] - sum).abs() <= tol * scale,
            "{case} {prec:?} row {r}"
        );
    }
}

#[test]
fn spmv_matches_cpu_and_row_sums() {
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        for (name, mesh) in meshes().into_iter().take(6) {
            let (k, _) = normal_system(&mesh);
            let op = GpuOperator::new(&ctx, &k).unwrap();
            assert_product_is_the_hosts(&op, &k, prec, &name);
            assert_eq!(op.nrows(), k.n());
        }
    }
}

/// A cylinder's spline space with uniform knots (shared element matrices, and Q2 elements
/// with constrained nodes, matrices of their own) or graded knots (every element its own).
fn assembly_space(mesh: &LinearMesh, topo: &Topology, graded: bool) -> SplineSpace {
    if !graded {
        return SplineSpace::build(mesh, topo);
    }
    let weights: Vec<_> = (0..mesh.n_elements())
        .map(|e| {
            let f = |k: usize| 0.3 + 0.4 * (((e * 5 + k * 3) % 11) as f64 / 10.0);
            [[f(0), f(1)], [f(2), f(3)], [f(4), f(5)]]
        })
        .collect();
    SplineSpace::build_with_knots(mesh, topo, &[], Some(&weights))
}

/// `assemble.wgsl` on lavapipe sums K into the GPU matrix: in f64 the bits of the host
/// assembly (`fit::assembly::assemble_matrix`, then the symmetric scaling) and of its CPU
/// twin; in f32 the twin's bits, within `ASSEMBLE_TOL_F32` of each entry's sum of term
/// magnitudes from the f64 values; on uniform and graded knots, scaled or not.
#[test]
fn assemble_kernel_matches_twin_and_host_assembly() {
    use polyspline::exec::gpu::assemble::ASSEMBLE_TOL_F32;
    use polyspline::exec::gpu::cg::GpuMatrix;
    use polyspline::fit::assembly::{assemble_deferred, assemble_matrix};
    use polyspline::fit::{ElementBlocks, FitWeights};
    let mesh =
        polyspline::mesh::generate::generate(polyspline::mesh::generate::Kind::Cylinder, 1500);
    let topo = Topology::build(&mesh);
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        for graded in [false, true] {
            let s = assembly_space(&mesh, &topo, graded);
            let blocks = ElementBlocks::new(&s, &mesh, &topo, &FitWeights::position());
            let n = s.control_points.len();
            let d: Vec<f64> = (0..n).map(|i| [1.0, 0.5, 0.125][i % 3]).collect();
            for scale in [None, Some(&d)] {
                let case = format!("{prec:?} graded {graded} scaled {}", scale.is_some());
                let mut host = assemble_matrix(&s, &blocks);
                let mut k = assemble_deferred(&s, &blocks);
                if let Some(d) = scale {
                    host.scale_symmetric(d);
                    k.scale_symmetric(d);
                }
                let m = GpuMatrix::summed_on_device(&ctx, &k).unwrap();
                let got = m.values(&ctx).unwrap();
                assert_eq!(got.len(), host.indices().len(), "{case}");
                let twin: Vec<f64> = match prec {
                    Precision::F64 => cpu::assemble::assemble_all::<f64>(&k, |v| v).unwrap(),
                    Precision::F32 => cpu::assemble::assemble_all::<f32>(&k, |v| v)
                        .unwrap()
                        .into_iter()
                        .map(f64::from)
                        .collect(),
                };
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert!(bits(&got) == bits(&twin), "{case}: kernel and twin differ");
                match prec {
                    Precision::F64 => {
                        assert!(bits(&got) == bits(host.data()), "{case}: not the host's K")
                    }
                    Precision::F32 => {
                        let mags = cpu::assemble::assemble_all::<f64>(&k, f64::abs).unwrap();
                        for (i, ((g, h), m)) in got.iter().zip(host.data()).zip(&mags).enumerate() {
                            assert!(
                                (g - h).abs() <= ASSEMBLE_TOL_F32 * m,
                                "{case}: entry {i}: {g} against {h} (terms {m})"
                            );
                        }
                    }
                }
                assert_eq!(m.n, n);
            }
        }
    }
}

/// The fit under the GPU executor with K summed on the device gives the control points of
/// the same solve with K summed and uploaded by the host, from a cold and from a warm start:
/// bit for bit in f64, with the same iteration count; in f32 they agree to the tolerance.
#[test]
fn fit_with_device_sums_is_the_host_sums_fit() {
    use polyspline::fit::{Summing, fit_with_targets_from};
    let mesh =
        polyspline::mesh::generate::generate(polyspline::mesh::generate::Kind::Cylinder, 1500);
    let topo = Topology::build(&mesh);
    let s = SplineSpace::build(&mesh, &topo);
    let params = FitParams::default();
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        let gpu = polyspline::exec::GpuExecutor::new(&ctx);
        // A warm start: the initial control points moved by a thousandth of the size.
        let warm: Vec<[f64; 3]> = s
            .control_points
            .iter()
            .enumerate()
            .map(|(i, c)| c.map(|v| v + 1e-3 * (i as f64).sin()))
            .collect();
        for start in [None, Some(&warm[..])] {
            let fit = |summing: Summing| {
                let before = ctx.traffic().uploaded_bytes;
                let (c, info) = fit_with_targets_from(
                    &s,
                    &mesh,
                    &topo,
                    &params,
                    None,
                    (start, summing),
                    |k, b, x, cg| {
                        polyspline::exec::Executor::pcg(&gpu, k, b, x, cg, &mut |_, _| {})
                    },
                )
                .unwrap();
                (c, info.cg, ctx.traffic().uploaded_bytes - before)
            };
            let case = format!("{prec:?} warm {}", start.is_some());
            let (host, hi, host_up) = fit(Summing::Host);
            let (device, di, device_up) = fit(Summing::Solver);
            assert!(hi.iterations > 10, "{case}: {hi:?}");
            assert!(
                device_up < host_up,
                "{case}: {device_up} bytes up against {host_up}"
            );
            match prec {
                Precision::F64 => {
                    let flat =
                        |c: &[[f64; 3]]| c.concat().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    assert!(
                        flat(&host) == flat(&device),
                        "{case}: control points differ"
                    );
                    assert_eq!(hi.iterations, di.iterations, "{case}");
                }
                Precision::F32 => {
                    let (lo, hi) = mesh.bounding_box();
                    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
                    for (a, b) in host.iter().zip(&device) {
                        let d = norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]);
                        assert!(d <= 1e-5 * diag, "{case}: {d:e}");
                    }
                }
            }
        }
    }
}

/// A matrix larger than one storage binding goes up as row blocks. With the context's binding
/// limit lowered to half of K's values (the element tables still fit), `assemble.wgsl` sums every block from its own rows
/// (the host's bits in f64, the f32 tolerance otherwise), the product over the blocks is the
/// host's, and the device CG over the blocks is the one-block CG: in f64 the same control
/// points bit for bit and the same iterations (a row's sum does not depend on its block).
#[test]
fn row_blocks_sum_multiply_and_solve_as_one_matrix() {
    use polyspline::exec::gpu::assemble::ASSEMBLE_TOL_F32;
    use polyspline::exec::gpu::cg::GpuMatrix;
    use polyspline::fit::assembly::{assemble_deferred, assemble_matrix};
    use polyspline::fit::{ElementBlocks, FitWeights, Summing, fit_with_targets_from};
    let mesh =
        polyspline::mesh::generate::generate(polyspline::mesh::generate::Kind::Cylinder, 1500);
    let topo = Topology::build(&mesh);
    let s = SplineSpace::build(&mesh, &topo);
    let blocks = ElementBlocks::new(&s, &mesh, &topo, &FitWeights::position());
    // Scaled symmetrically, as the fit's K is: the kernel reads each row's scale by its
    // global row number.
    let d: Vec<f64> = (0..s.control_points.len())
        .map(|i| [1.0, 0.5, 0.125][i % 3])
        .collect();
    let mut host = assemble_matrix(&s, &blocks);
    host.scale_symmetric(&d);
    let mut k = assemble_deferred(&s, &blocks);
    k.scale_symmetric(&d);
    let params = FitParams::default();
    for prec in [Precision::F32, Precision::F64] {
        let Some(whole) = context(prec) else { return };
        let fit = |ctx: &GpuContext| {
            let gpu = polyspline::exec::GpuExecutor::new(ctx);
            fit_with_targets_from(
                &s,
                &mesh,
                &topo,
                &params,
                None,
                (None, Summing::Solver),
                |k, b, x, cg| polyspline::exec::Executor::pcg(&gpu, k, b, x, cg, &mut |_, _| {}),
            )
            .unwrap()
        };
        let (one, one_info) = fit(&whole);
        drop(whole);
        let Some(mut ctx) = context(prec) else { return };
        let sz = prec.size() as u64;
        ctx.limits.max_storage_buffer_binding_size = sz * host.indices().len() as u64 / 2 + 64;
        let case = format!("{prec:?}");

        let m = GpuMatrix::summed_on_device(&ctx, &k).unwrap();
        assert!(m.n_blocks() >= 2, "{case}: {} row blocks", m.n_blocks());
        let got = m.values(&ctx).unwrap();
        assert_eq!(got.len(), host.indices().len(), "{case}");
        let mags = cpu::assemble::assemble_all::<f64>(&k, f64::abs).unwrap();
        for (i, ((g, h), m)) in got.iter().zip(host.data()).zip(&mags).enumerate() {
            match prec {
                Precision::F64 => assert_eq!(g.to_bits(), h.to_bits(), "{case}: entry {i}"),
                Precision::F32 => assert!(
                    (g - h).abs() <= ASSEMBLE_TOL_F32 * m,
                    "{case}: entry {i}: {g} against {h} (terms {m})"
                ),
            }
        }

        let op = GpuOperator::new(&ctx, &host).unwrap();
        assert!(op.n_blocks() >= 2, "{case}: {} row blocks", op.n_blocks());
        assert_product_is_the_hosts(&op, &host, prec, &case);

        let (split, split_info) = fit(&ctx);
        let flat = |c: &[[f64; 3]]| c.concat().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        match prec {
            Precision::F64 => {
                assert!(flat(&one) == flat(&split), "{case}: control points differ");
                assert_eq!(one_info.cg.iterations, split_info.cg.iterations, "{case}");
            }
            Precision::F32 => {
                let (lo, hi) = mesh.bounding_box();
                let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
                for (a, b) in one.iter().zip(&split) {
                    let d = norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]);
                    assert!(d <= 1e-5 * diag, "{case}: {d:e}");
                }
            }
        }
    }
}

/// Point-Jacobi PCG, one body per executor: each solution's residual checked in f64, the two
/// solutions within 1e-5 of each other, and in f64 the same iteration count give or take.
#[test]
fn gpu_cg_matches_cpu_cg() {
    const TEST: &str = "gpu_cg_matches_cpu_cg";
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        let executors = executors::cpu_and_gpu(&ctx);
        for (name, mesh) in meshes().into_iter().take(6) {
            let (k, b) = normal_system(&mesh);
            // The GPU solver is point-Jacobi PCG; compare it with the same CPU algorithm.
            let params = CgParams {
                rel_tol: 1e-9,
                preconditioner: polyspline::solve::CgPreconditioner::Jacobi,
                ..Default::default()
            };
            let [(want, ci), (got, gi)] = executors::on_each(&executors, |x| {
                let mut sol = vec![[0.0; 3]; k.n()];
                let info = x
                    .pcg(k.clone(), &b, &mut sol, &params, &mut |_, _| {})
                    .unwrap_or_else(|e| panic!("{name} {prec:?} {}: {e}", x.name()));
                (sol, info)
            });
            let outputs = || {
                let case = format!("{name}.{prec:?}");
                let (ci, gi) = (executors::Debugged(ci), executors::Debugged(gi));
                executors::dump(
                    TEST,
                    &case,
                    &[
                        ("cpu", &want),
                        ("gpu", &got),
                        ("cpu.info", &ci),
                        ("gpu.info", &gi),
                    ],
                )
            };
            // Independent check of each residual in f64.
            for (executor, sol) in [("cpu", &want), ("gpu", &got)] {
                let mut ax = vec![[0.0; 3]; k.n()];
                k.apply(sol, &mut ax);
                for c in 0..3 {
                    let bn = b.iter().map(|v| v[c] * v[c]).sum::<f64>().sqrt();
                    let rn = b
                        .iter()
                        .zip(&ax)
                        .map(|(b, a)| (b[c] - a[c]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    assert!(
                        rn <= 1e-9 * bn + 1e-300,
                        "{name} {prec:?} {executor}: residual {rn:e} vs |b| {bn:e}; {}",
                        outputs()
                    );
                }
            }
            let xn = want
                .iter()
                .flatten()
                .map(|v| v * v)
                .sum::<f64>()
                .sqrt()
                .max(1e-300);
            let dn = want
                .iter()
                .zip(&got)
                .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).powi(2)))
                .sum::<f64>()
                .sqrt();
            assert!(
                dn <= 1e-5 * xn,
                "{name} {prec:?}: solutions differ by {dn:e} (|x| {xn:e}); {}",
                outputs()
            );
            if prec == Precision::F64 {
                assert!(
                    gi.iterations.abs_diff(ci.iterations) <= 3 + ci.iterations / 20,
                    "{name}: {gi:?} vs {ci:?}; {}",
                    outputs()
                );
            }
        }
    }
}

/// The CG kernels' CPU twins driven through the same loop as the GPU (spmv, dot_partial,
/// finalize_alpha, update_xr, dot_partial, finalize_beta, update_p) solve the system too.
#[test]
fn cg_twins_solve_the_system() {
    use cpu::cg::{Scalars, finalize_alpha, finalize_beta, update_p, update_xr};
    let mesh = grid_2d(&uniform(6, 0.3), &uniform(4, 0.2));
    let mesh = {
        // Perturb so the fit has work to do.
        let mut m = mesh;
        for (i, c) in m.coords.iter_mut().enumerate() {
            c[0] += 0.01
                * ((i * 7 % 5) as f64 - 2.0)
                * if c[0] > 0.0 && c[0] < 1.5 { 1.0 } else { 0.0 };
        }
        m
    };
    let (k, b) = normal_system(&mesh);
    let n = k.n();
    let inv: Vec<f64> = k.diagonal().iter().map(|d| 1.0 / d).collect();
    let v4 =
        |v: &[[f64; 3]]| -> Vec<[f64; 4]> { v.iter().map(|x| [x[0], x[1], x[2], 0.0]).collect() };
    let mut x = vec![[0.0; 4]; n];
    let mut r = v4(&b);
    let mut z: Vec<[f64; 4]> = r.iter().zip(&inv).map(|(r, d)| r.map(|v| v * d)).collect();
    let mut p = z.clone();
    let mut ap = vec![[0.0; 4]; n];
    let dot = |a: &[[f64; 4]], b: &[[f64; 4]]| -> [f64; 4] {
        let mut s = [0.0; 4];
        for (x, y) in a.iter().zip(b) {
            for c in 0..4 {
                s[c] += x[c] * y[c];
            }
        }
        s
    };
    let bn = dot(&r, &r);
    let mut sc = Scalars {
        rz: dot(&r, &z),
        rr: bn,
        target2: bn.map(|v| if v > 0.0 { 1e-20 * v } else { f64::MAX }),
        ..Default::default()
    };
    let mut st = cpu::cg::CgState::default();
    let kp = cpu::cg::CgKernelParams {
        n: n as u32,
        n_partials: 4,
        max_iters: 10_000,
        coupled: 0,
    };
    let indptr: Vec<u32> = k.indptr().iter().map(|&v| v as u32).collect();
    let sp = cpu::spmv::SpmvParams {
        n_rows: n as u32,
        row_base: 0,
        _pad0: 0,
        _pad1: 0,
    };
    let dp = cpu::dot::DotParams {
        n: n as u32,
        ..Default::default()
    };
    let mut partials = vec![[0.0; 4]; 8];
    for _ in 0..5000 {
        cpu::spmv::spmv(&sp, &indptr, k.indices(), k.data(), &p, &mut ap);
        cpu::dot::dot_partial(&dp, &p, &ap, &mut partials, 4);
        finalize_alpha(&kp, &mut sc, &mut st, &partials);
        update_xr(&kp, &sc, &mut x, &mut r, &mut z, &p, &ap, &inv);
        cpu::dot::dot_partial(&dp, &r, &z, &mut partials, 4);
        finalize_beta(&kp, &mut sc, &st, &partials);
        update_p(&kp, &sc, &z, &mut p);
        if st.done != 0 {
            break;
        }
    }
    assert!(
        st.done == 1 && st.breakdown == 0 && st.iterations > 0,
        "{st:?}"
    );
    let xs: Vec<[f64; 3]> = x.iter().map(|v| [v[0], v[1], v[2]]).collect();
    let mut ax = vec![[0.0; 3]; n];
    k.apply(&xs, &mut ax);
    for c in 0..2 {
        let rn: f64 = b
            .iter()
            .zip(&ax)
            .map(|(b, a)| (b[c] - a[c]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(
            rn <= 1e-8 * bn[c].sqrt() + 1e-300,
            "component {c}: residual {rn:e}"
        );
    }
    // And the GPU agrees with the twins' solution.
    if let Some(ctx) = context(Precision::F64) {
        let mut got = vec![[0.0; 3]; n];
        gpu::cg::pcg(
            &ctx,
            &k,
            &b,
            &mut got,
            &CgParams {
                rel_tol: 1e-10,
                ..Default::default()
            },
            |_, _| {},
        )
        .unwrap();
        let xn = xs.iter().flatten().map(|v| v * v).sum::<f64>().sqrt();
        let dn: f64 = xs
            .iter()
            .zip(&got)
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).powi(2)))
            .sum::<f64>()
            .sqrt();
        assert!(dn <= 1e-6 * xn, "{dn:e} vs {xn:e}");
    }
}

/// `--backend gpu` without any Vulkan driver: one line on stderr, exit status 1, no panic.
#[test]
fn backend_gpu_without_adapter_is_a_clear_error() {
    let input =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real/mfem/cylinder-hex.mesh");
    let out = std::env::temp_dir().join("polyspline_gpu_noadapter.msh");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .args([
            "curve",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--backend",
            "gpu",
        ])
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("XDG_RUNTIME_DIR", "/tmp")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("polyspline: error"))
        .collect();
    assert_eq!(lines.len(), 1, "{err}");
    assert!(lines[0].contains("no GPU adapter"), "{err}");
    // `auto` falls back to the CPU.
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .args([
            "curve",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--backend",
            "auto",
        ])
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}

/// The full `curve` job on the GPU (lavapipe, f32 and f64) and the CPU, one body per backend:
/// same structure, nodes within the evaluation tolerance of the CG solution's difference,
/// every element certified. Both outputs stay in `target/tmp/cross_validation/` and the
/// assertion messages name them.
#[test]
fn curve_gpu_matches_cpu() {
    use polyspline::exec::gpu::Backend;
    use polyspline::pipeline::{CurveOptions, Geometry, LineSearchMode, curve};
    const TEST: &str = "curve_gpu_matches_cpu";
    let mut gpus = Vec::new();
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        gpus.push((prec, std::sync::Arc::new(ctx)));
    }
    for mesh in [
        "mfem/cylinder-hex.mesh",
        "sfepy/hsphere8.vtk",
        "su2-testcases/n0012_113-33.su2",
    ] {
        let input = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("meshes/real")
            .join(mesh);
        let run = |backend: Backend, case: &str| {
            let name = polyspline::exec::executor(&backend).name();
            let out = executors::output_path(TEST, case, name, "vtu");
            let opts = CurveOptions {
                order: 3,
                geometry: Geometry::SplineFitted,
                // Tight, so the two solutions differ by the solver's rounding only.
                fit: polyspline::fit::FitParams {
                    cg: CgParams {
                        rel_tol: 1e-10,
                        ..Default::default()
                    },
                    ..Default::default()
                },
                line_search_mode: LineSearchMode::Local,
                backend,
                ..Default::default()
            };
            let r = curve(&input, &out, &opts)
                .unwrap_or_else(|e| panic!("{mesh} {name}: {e}; output {}", out.display()));
            assert_eq!(r.backend, name, "{mesh}");
            assert_eq!(r.invalid_elements, 0, "{mesh} {name}: {}", out.display());
            let ho =
                polyspline::mesh::HighOrderMesh::from_raw(polyspline::io::read_raw(&out).unwrap())
                    .unwrap();
            (r, ho, out)
        };
        let (rc, hc, pc) = run(Backend::Cpu, mesh);
        for (prec, ctx) in &gpus {
            let (rg, hg, pg) = run(Backend::Gpu(ctx.clone()), &format!("{mesh}.{prec:?}"));
            let outputs = format!("outputs: {} and {}", pc.display(), pg.display());
            assert_eq!(rg.adapter.as_ref().unwrap().name, ctx.adapter.name);
            assert!(
                hc.elements == hg.elements,
                "{mesh}: elements differ; {outputs}"
            );
            let (lo, hi) = read_mesh(&input, &MeshOptions::default())
                .unwrap()
                .bounding_box();
            let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
            runs_agree(
                &format!("{mesh} {prec:?}"),
                (rc.damped_control_points, &hc.nodes),
                (rg.damped_control_points, &hg.nodes),
                diag,
                &outputs,
            );
        }
    }
}

/// The CPU run (damped control points, nodes) and the GPU run of one mesh agree. Both solve the
/// fit to rel_tol 1e-10, so with the same damping their nodes agree far below 1e-5 of the
/// diagonal. The certified line search is a discrete decision per element (lower bound >
/// threshold): solutions that differ by rounding may flip a few near-threshold elements and so
/// the damping of their control points. Then the damping must agree to 5 %, at most a tenth of
/// the nodes may differ by more than 1e-5 of the diagonal, and none by more than 5 % of it (a
/// damped control point moves back toward the straight mesh, by less than the mesh's size).
fn runs_agree(
    ctx: &str,
    (a, cpu): (usize, &[[f64; 3]]),
    (b, gpu): (usize, &[[f64; 3]]),
    diag: f64,
    outputs: &str,
) {
    assert_eq!(cpu.len(), gpu.len(), "{ctx}: node counts; {outputs}");
    let worst = common::max_coordinate_gap(cpu, gpu);
    if a == b {
        assert!(
            worst <= 1e-5 * diag,
            "{ctx}: nodes differ by {worst:e} (diagonal {diag:e}); {outputs}"
        );
        return;
    }
    assert!(
        a.abs_diff(b) * 20 <= a.max(b),
        "{ctx}: damped {a} vs {b}; {outputs}"
    );
    let apart = cpu
        .iter()
        .zip(gpu)
        .filter(|(p, q)| common::dist(**p, **q) > 1e-5 * diag)
        .count();
    assert!(
        apart * 10 <= cpu.len(),
        "{ctx}: {apart} of {} nodes differ; {outputs}",
        cpu.len()
    );
    assert!(
        worst <= 0.05 * diag,
        "{ctx}: nodes differ by {worst:e} (diagonal {diag:e}); {outputs}"
    );
    println!("{ctx}: damped control points {a} (CPU) vs {b} (GPU), nodes differ by {worst:e}");
}

/// [`runs_agree`] when the two runs damp different numbers of control points (which the
/// lavapipe runs of [`curve_gpu_matches_cpu`] do not reach): the nodes are still compared.
/// Runs made here: 100 nodes on a unit diagonal; a few moved within the damping's reach pass,
/// too many moved, one moved too far, or too different a damping fail.
#[test]
fn cpu_gpu_comparison_with_differing_damping_compares_nodes() {
    let cpu: Vec<[f64; 3]> = (0..100).map(|i| [i as f64 / 100.0, 0.0, 0.0]).collect();
    let moved = |n: usize, by: f64| {
        let mut g = cpu.clone();
        for x in g.iter_mut().take(n) {
            x[1] += by;
        }
        g
    };
    let fails = |a: usize, b: usize, gpu: Vec<[f64; 3]>| {
        let cpu = cpu.clone();
        std::panic::catch_unwind(move || runs_agree("made", (a, &cpu), (b, &gpu), 1.0, "")).is_err()
    };
    assert!(!fails(100, 98, moved(5, 0.01)), "a few nodes within reach");
    assert!(!fails(100, 100, moved(100, 1e-7)), "same damping, rounding");
    assert!(
        fails(100, 98, moved(20, 0.01)),
        "a fifth of the nodes moved"
    );
    assert!(
        fails(100, 98, moved(1, 0.2)),
        "one node beyond the damping's reach"
    );
    assert!(fails(100, 80, moved(0, 0.0)), "damping 20 % apart");
    assert!(
        fails(100, 100, moved(1, 1e-3)),
        "same damping, one node off"
    );
}

/// The n³-hex grid: GPU evaluation (order-2 sampling) and certification, checked against the
/// CPU on every element. The certificates' tolerance is the kernel's rounding bound computed
/// from the CPU's f64 net ([`cpu_factor_max`]), twice (one for each side's rounding).
fn large_hex_gpu_sampling_and_certification(n: usize) {
    let Some(ctx) = context(Precision::F32) else {
        return;
    };
    let mesh = grid_3d(&uniform(n, 1.0), &uniform(n, 1.0), &uniform(n, 1.0));
    let topo = Topology::build(&mesh);
    let s = SplineSpace::build(&mesh, &topo);
    let t = std::time::Instant::now();
    let cpu_ho = sample(&s, &mesh, &topo, 2);
    let t_cpu_sample = t.elapsed();
    let t = std::time::Instant::now();
    let gpu_ho = gpu::evaluate::sample(&ctx, &s, &mesh, &topo, 2).unwrap();
    let t_gpu_sample = t.elapsed();
    assert_eq!(gpu_ho.elements, cpu_ho.elements);
    let worst = common::max_coordinate_gap(&cpu_ho.nodes, &gpu_ho.nodes);
    assert!(
        worst <= EVALUATE_TOL_F32 * 1.0 / n as f64 * 2.0,
        "{worst:e}"
    );
    let all: Vec<usize> = (0..s.n_elements()).collect();
    let t = std::time::Instant::now();
    let cpu_b = polyspline::validity::CpuCertifier.certify(3, &all, &|e| s.element_bezier(e), 6);
    let t_cpu_cert = t.elapsed();
    let t = std::time::Instant::now();
    let gpu_b = gpu::jacobian_check::certify(&ctx, 3, &all, &|e| s.element_bezier(e), 6).unwrap();
    let t_gpu_cert = t.elapsed();
    for (e, (c, g)) in cpu_b.iter().zip(&gpu_b).enumerate() {
        assert_eq!(
            c.certified_positive(),
            g.certified_positive(),
            "element {e}"
        );
        let net = s.element_bezier(e);
        let a = gpu::anchor(3, &net);
        let xmax = net
            .iter()
            .flat_map(|p| (0..3).map(move |k| (p[k] - a[k]).abs()))
            .fold(0.0, f64::max);
        let err = rounding_bound(Precision::F32, 3, cpu_factor_max(3, &net), xmax);
        assert!(
            (c.lower - g.lower).abs() <= 2.0 * err,
            "element {e}: {c:?} vs {g:?} (bound {err:e})"
        );
        assert!(g.lower <= c.lower + 1e-300, "element {e}: {c:?} vs {g:?}");
    }
    println!(
        "{} hexes ({} control points, {} output nodes): sample order 2: CPU {t_cpu_sample:.2?}, GPU {t_gpu_sample:.2?}; certify: CPU {t_cpu_cert:.2?}, GPU {t_gpu_cert:.2?} ({})",
        s.n_elements(),
        s.n_control_points(),
        gpu_ho.nodes.len(),
        ctx.adapter.name
    );
}

/// About 100k hexes (47³): run everywhere, on the software rasteriser too.
#[test]
fn hundred_thousand_hex_gpu_sampling_and_certification() {
    large_hex_gpu_sampling_and_certification(47);
}

/// 1M hexes: too slow for the software rasteriser of CI; a manual check on a real GPU:
/// `cargo test --release --test cross_validation million -- --ignored --nocapture`.
#[test]
#[ignore = "large: run with --release -- --ignored --nocapture"]
fn million_hex_gpu_sampling_and_certification() {
    large_hex_gpu_sampling_and_certification(100);
}

/// The coloured energy solver's local derivatives: the f64 CPU twin against the analytic local
/// problem (`LocalProblem::eval`, FD-tested in src/energy/colored.rs), and the GPU kernel
/// against its twin at the same precision, on local problems of real energy states.
#[test]
fn local_newton_matches_twin_and_local_problem() {
    use polyspline::energy::colored::{LocalProblem, local_problems};
    use polyspline::energy::{Energy, EnergyParams};
    use polyspline::exec::cpu::local_newton as twin;
    use polyspline::exec::gpu::local_newton::{
        LocalDerivatives, Params, local_newton, pack, unpack,
    };
    use polyspline::mesh::generate::extrude;
    let run_twin = |dim: usize, problems: &[LocalProblem], prec: Precision| {
        let (coefs, ranges, points) = pack(problems);
        let params = Params {
            dim: dim as u32,
            n_problems: problems.len() as u32,
            _pad0: 0,
            _pad1: 0,
        };
        let mut out = vec![0.0f64; 13 * problems.len()];
        match prec {
            Precision::F64 => twin::local_newton(&params, &coefs, &ranges, &points, &mut out),
            Precision::F32 => {
                let c: Vec<f32> = coefs.iter().map(|&x| x as f32).collect();
                let p: Vec<f32> = points.iter().map(|&x| x as f32).collect();
                let mut o = vec![0.0f32; out.len()];
                twin::local_newton(&params, &c, &ranges, &p, &mut o);
                out = o.iter().map(|&x| x as f64).collect();
            }
        }
        unpack(&out)
    };
    let close = |a: &LocalDerivatives, b: &LocalDerivatives, tol: f64, what: &str| {
        let scale = a
            .hessian
            .iter()
            .flatten()
            .chain(&a.gradient)
            .fold(a.value.abs(), |m, x| m.max(x.abs()));
        let pairs = std::iter::once((a.value, b.value))
            .chain(a.gradient.iter().copied().zip(b.gradient))
            .chain(
                a.hessian
                    .iter()
                    .flatten()
                    .copied()
                    .zip(b.hessian.iter().flatten().copied()),
            );
        for (x, y) in pairs {
            assert!((x - y).abs() <= tol * scale, "{what}: {a:?} vs {b:?}");
        }
    };
    for m in [star_2d(3), extrude(&star_2d(3), &uniform(2, 0.5))] {
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let fit = FitParams::smooth();
        let c_star = polyspline::fit::fit(&s, &m, &t, &fit, |_, _| {}).unwrap().0;
        let e = Energy::new(&s, &m, &t, &fit, &c_star, &EnergyParams::default()).unwrap();
        let x: Vec<[f64; 3]> = s
            .control_points
            .iter()
            .zip(&c_star)
            .map(|(a, b)| [0, 1, 2].map(|k| 0.5 * (a[k] + b[k])))
            .collect();
        let which: Vec<usize> = (0..x.len()).collect();
        let problems = local_problems(&e, &x, &which);
        let reference = run_twin(m.dim, &problems, Precision::F64);
        for (p, r) in problems.iter().zip(&reference) {
            let (mut g, mut h) = ([0.0; 3], [[0.0; 3]; 3]);
            let value = p.eval([0.0; 3], Some((&mut g, &mut h)));
            let analytic = LocalDerivatives {
                value,
                gradient: g,
                hessian: h,
            };
            close(&analytic, r, 1e-10, "f64 twin vs analytic");
        }
        for prec in [Precision::F32, Precision::F64] {
            let Some(ctx) = context(prec) else { continue };
            if ctx.precision != prec {
                continue;
            }
            let gpu = local_newton(&ctx, m.dim, &problems).unwrap();
            let cpu = run_twin(m.dim, &problems, prec);
            let tol = if prec == Precision::F64 { 1e-9 } else { 1e-3 };
            assert_eq!(gpu.len(), cpu.len());
            for (a, b) in cpu.iter().zip(&gpu) {
                close(a, b, tol, &format!("{prec:?} GPU vs twin"));
            }
        }
    }
}

/// The coloured energy solver, one body per executor (the GPU computes the local
/// derivatives): every accepted iterate is certified valid, Q falls, and the GPU ends where
/// the CPU ends (the derivatives differ only by rounding).
#[test]
fn colored_energy_with_gpu_derivatives_matches_cpu() {
    use polyspline::energy::{Energy, EnergyParams, EnergySolver, Validity, minimize_on};
    use polyspline::validity::CpuCertifier;
    const TEST: &str = "colored_energy_with_gpu_derivatives_matches_cpu";
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { continue };
        if ctx.precision != prec {
            continue;
        }
        let executors = executors::cpu_and_gpu(&ctx);
        let m = star_2d(4);
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let fit = FitParams::smooth();
        let c_star = polyspline::fit::fit(&s, &m, &t, &fit, |_, _| {}).unwrap().0;
        let params = EnergyParams {
            solver: EnergySolver::Colored,
            max_iterations: 5,
            ..Default::default()
        };
        let e = Energy::new(&s, &m, &t, &fit, &c_star, &params).unwrap();
        let start = s.control_points.clone();
        let v = Validity::for_start(&e, &CpuCertifier, 6, &[], &start).unwrap();
        let [(xc, cpu), (xg, gpu)] = executors::on_each(&executors, |x| {
            let (c, info) = minimize_on(&e, &v, &start, &params, x, &mut |c| {
                for el in 0..s.n_elements() {
                    let b = det_jacobian_bounds(2, &s.element_bezier_with(el, c), 6);
                    assert!(
                        b.certified_positive(),
                        "{}: element {el} not certified",
                        x.name()
                    );
                }
            })
            .unwrap_or_else(|err| panic!("{prec:?} {}: {err}", x.name()));
            assert!(
                info.final_energy < info.initial_energy,
                "{}: {info:?}",
                x.name()
            );
            (c, info)
        });
        let tol = if prec == Precision::F64 { 1e-9 } else { 1e-3 };
        assert!(
            (gpu.final_energy - cpu.final_energy).abs()
                <= tol * (cpu.initial_energy - cpu.final_energy),
            "{prec:?}: GPU {} vs CPU {}; {}",
            gpu.final_energy,
            cpu.final_energy,
            executors::dump(
                TEST,
                &format!("{prec:?}"),
                &[
                    ("cpu", &xc),
                    ("gpu", &xg),
                    ("cpu.info", &executors::Debugged(&cpu)),
                    ("gpu.info", &executors::Debugged(&gpu)),
                ],
            )
        );
    }
}

/// The report's `gpu_traffic` counts what the kernels really moved: on a curved cylinder with
/// f32 kernels, the fit's CG uploads at least the normal matrix (a u32 index and an f32 value
/// per stored entry, `matrix_nonzeros`) and reads back at least the solution (a vec4 per
/// control point); it dispatches the 7 kernels of an iteration at least `cg_iterations` times
/// (one matrix block here). The sampling reads back exactly one point (3 f32) per written
/// node, and uploads at least one Bézier net (27 points × 3 f32) per element. Reading,
/// topology and quality run on the CPU and move nothing; every stage's counts agree with each
/// other (a dispatch is submitted, a read-back downloads). The CPU backend reports none.
#[test]
fn gpu_traffic_counts_what_the_kernels_move() {
    use polyspline::exec::gpu::Backend;
    use polyspline::pipeline::{CurveOptions, curve};
    let Some(ctx) = context(Precision::F32) else {
        return;
    };
    let input =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("meshes/real/mfem/cylinder-hex.mesh");
    let run = |backend: Backend| {
        let name = polyspline::exec::executor(&backend).name();
        let out = executors::output_path("gpu_traffic", "cylinder-hex", name, "msh");
        let opts = CurveOptions {
            backend,
            ..Default::default()
        };
        curve(&input, &out, &opts).unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    assert!(run(Backend::Cpu).gpu_traffic.is_none(), "CPU backend");
    let r = run(Backend::Gpu(std::sync::Arc::new(ctx)));
    let traffic = r
        .gpu_traffic
        .as_ref()
        .expect("gpu_traffic under --backend gpu");
    let at = |key: &str| {
        *traffic
            .get(key)
            .unwrap_or_else(|| panic!("no `{key}` in {traffic:?}"))
    };
    for (key, t) in traffic {
        let ctx = format!("{key}: {t:?}");
        assert_eq!(t.dispatches > 0, t.device_bytes > 0, "{ctx}");
        assert_eq!(t.readbacks > 0, t.downloaded_bytes > 0, "{ctx}");
        assert!(t.readbacks <= t.submits, "{ctx}");
        assert!(
            t.dispatches == 0 || (t.submits > 0 && t.readbacks > 0),
            "{ctx}"
        );
        assert!(t.wait_seconds >= 0.0, "{ctx}");
        assert!(r.timings.contains_key(key), "{ctx}: not a stage of timings");
    }
    for key in ["read", "topology", "quality"] {
        assert_eq!(at(key), Default::default(), "{key} runs on the CPU");
    }
    let (n, nnz, iterations) = (
        r.control_points as u64,
        r.matrix_nonzeros.unwrap() as u64,
        r.cg_iterations.unwrap() as u64,
    );
    assert!(iterations > 0 && nnz > 0);
    let fit = at("fit");
    assert!(
        fit.uploaded_bytes >= nnz * (4 + 4) + 3 * 16 * n,
        "fit: {fit:?}, {nnz} nonzeros"
    );
    assert!(
        fit.downloaded_bytes >= 16 * n,
        "fit: {fit:?}, {n} control points"
    );
    assert!(
        fit.dispatches >= 7 * iterations,
        "fit: {fit:?}, {iterations} iterations"
    );
    assert!(
        fit.device_bytes >= iterations * nnz * (4 + 4),
        "fit: {fit:?}"
    );
    assert!(fit.submits * 10 >= iterations, "fit: {fit:?}");
    let sample = at("sample");
    assert_eq!(
        sample.downloaded_bytes,
        3 * 4 * r.output_nodes as u64,
        "sample: {sample:?}"
    );
    assert!(
        sample.uploaded_bytes >= 81 * 4 * r.elements as u64 + 8 * r.output_nodes as u64,
        "sample: {sample:?}, {} elements",
        r.elements
    );
    assert!(sample.dispatches >= 1, "sample: {sample:?}");
    println!("{traffic:#?}");
}

use polyspline::fit::rotated::{Coupling, OnK};

/// The fit's coupled system across rotation seams, (K ⊗ I₃ + C) δ = b, as the fit builds it
/// (scaled): the generated 40° sector (6 columns, 8 cells across graded to hub and shroud,
/// 4 layers over z ∈ [0, 0.5]) glued through its rotation.
fn sector_system() -> (polyspline::fit::NormalMatrix, Coupling, Vec<[f64; 3]>) {
    use polyspline::fit::{CoupledRun, FitSolve, NormalMatrix, Summing, fit_with_solver};
    use polyspline::mesh::generate::boundary_layer::{BoundaryLayer, sector};
    use polyspline::mesh::periodic::{PeriodicSpec, resolve};
    use polyspline::solve::{CgError, CgInfo};
    use polyspline::spline::seam::{glue, interior_view, unwrap};
    /// Keeps the coupled system instead of solving it.
    struct Capture<'a>(&'a mut Option<(NormalMatrix, Coupling, Vec<[f64; 3]>)>);
    impl FitSolve for Capture<'_> {
        fn solve(
            self,
            _: NormalMatrix,
            _: &[[f64; 3]],
            _: &mut [[f64; 3]],
            _: &CgParams,
        ) -> Result<CgInfo, CgError> {
            panic!("the sector's fit is not coupled")
        }
        fn solve_coupled(
            self,
            k: NormalMatrix,
            c: &Coupling,
            b: &[[f64; 3]],
            _: &mut [[f64; 3]],
            _: &CgParams,
            _: bool,
        ) -> Result<(CgInfo, CoupledRun), CgError> {
            *self.0 = Some((k, c.clone(), b.to_vec()));
            let info = CgInfo {
                iterations: 0,
                rel_residual: 0.0,
            };
            let run = CoupledRun {
                device: "none",
                preconditioner: OnK::Jacobi,
            };
            Ok((info, run))
        }
    }
    let p = BoundaryLayer {
        around: 6,
        across: 8,
        first_height: 0.02,
        layers: 4,
        span: 0.5,
        ..Default::default()
    };
    let mesh = sector(&p, 40.0).unwrap().mesh;
    let topo = Topology::build(&mesh);
    let spec = PeriodicSpec {
        master: "periodic_lo".into(),
        slave: "periodic_hi".into(),
        from_file: false,
    };
    let pairs = resolve(&mesh, &topo, &[spec]).unwrap();
    let glued = glue(&mesh, &pairs).expect("a manifold glued sector");
    let mut space = SplineSpace::build_with_knots(&glued.mesh, &glued.topo, &[], None);
    unwrap(&mut space, &mesh, &topo, &glued).expect("the seam is identified");
    let view = interior_view(&mesh, &topo, &glued);
    let mut system = None;
    fit_with_solver(
        &space,
        &mesh,
        &view.topo,
        &FitParams::default(),
        None,
        (None, Summing::Host),
        Capture(&mut system),
    )
    .unwrap();
    system.expect("the sector's fit is coupled")
}

/// The CPU's coupled CG with K's diagonal (`fit::rotated::solve`, `OnK::Jacobi`) on
/// (`k` ⊗ I₃ + `c`) x = `b` to 1e-10 of ‖b‖: its parameters, solution and figures.
fn cpu_coupled_reference(
    k: &polyspline::fit::NormalMatrix,
    c: &Coupling,
    b: &[[f64; 3]],
) -> (CgParams, Vec<[f64; 3]>, polyspline::solve::CgInfo) {
    let params = CgParams {
        rel_tol: 1e-10,
        ..Default::default()
    };
    let mut x = vec![[0.0; 3]; k.n()];
    let info =
        polyspline::fit::rotated::solve(k, c, b, &mut x, &params, OnK::Jacobi, &mut |_, _| {})
            .unwrap();
    (params, x, info)
}

/// (K ⊗ I₃ + C) x on the host, in f64.
fn coupled_product(
    k: &polyspline::fit::NormalMatrix,
    c: &Coupling,
    x: &[[f64; 3]],
) -> Vec<[f64; 3]> {
    let mut y = vec![[0.0; 3]; x.len()];
    k.apply(x, &mut y);
    c.apply_add(x, &mut y);
    y
}

/// ‖a − b‖ over all three coordinates.
fn distance_all(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(a, b)| [0, 1, 2].map(|p| (a[p] - b[p]).powi(2)))
        .sum::<f64>()
        .sqrt()
}

/// ‖v‖ over all three coordinates.
fn norm_all(v: &[[f64; 3]]) -> f64 {
    v.iter().flatten().map(|x| x * x).sum::<f64>().sqrt()
}

/// A test vector of `n` entries.
fn test_vector(n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| [1.0, (i % 7) as f64 - 3.0, ((i * 31) % 11) as f64 / 11.0])
        .collect()
}

/// `coupling.wgsl` adds C x to spmv.wgsl's K x: its f64 CPU twin after the spmv twin is the
/// spmv twin followed by the host's `Coupling::apply_add`, bit for bit; the device's coupled
/// product is the host's (K ⊗ I₃ + C) x row by row within the spmv tolerance of the row's
/// magnitudes (K's and C's terms), in f32 and f64; and the device's coupled product minus
/// its uncoupled one is C x (the coupling's rows move by more than the tolerance).
#[test]
fn coupling_kernel_matches_twin_and_host() {
    use cpu::coupling::{BlockRows, coupling};
    use polyspline::exec::gpu::cg::GpuOperator;
    let (k, c, _) = sector_system();
    let n = k.n();
    let x = test_vector(n);
    let rows = BlockRows::of(&c);
    assert!(
        !rows.rows.is_empty() && rows.rows.len() < n,
        "{} block rows of {n}",
        rows.rows.len()
    );
    // The twin in f64.
    let v4 =
        |v: &[[f64; 3]]| -> Vec<[f64; 4]> { v.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect() };
    let indptr: Vec<u32> = k.indptr().iter().map(|&v| v as u32).collect();
    let sp = cpu::spmv::SpmvParams {
        n_rows: n as u32,
        ..Default::default()
    };
    let mut kx = vec![[0.0f64; 4]; n];
    cpu::spmv::spmv(&sp, &indptr, k.indices(), k.data(), &v4(&x), &mut kx);
    let mut want: Vec<[f64; 3]> = kx.iter().map(|v| [v[0], v[1], v[2]]).collect();
    c.apply_add(&x, &mut want);
    let mut twin = kx.clone();
    coupling(
        &rows.params(),
        &rows.rows,
        &rows.indptr,
        &rows.cols,
        &rows.blocks,
        &v4(&x),
        &mut twin,
    );
    for (r, (t, w)) in twin.iter().zip(&want).enumerate() {
        for p in 0..3 {
            assert_eq!(
                t[p].to_bits(),
                w[p].to_bits(),
                "twin row {r}: {t:?} against {w:?}"
            );
        }
    }
    // Each row's magnitude: Σ |K_rj| |x_j| + Σ |C_rj| |x_j| (bounds the terms' rounding).
    let mut magnitude: Vec<f64> = (0..n)
        .map(|r| {
            (k.indptr()[r]..k.indptr()[r + 1])
                .map(|j| k.data()[j].abs() * norm(x[k.indices()[j] as usize]))
                .sum()
        })
        .collect();
    for (r, cols, blocks) in c.block_rows() {
        for (&j, m) in cols.iter().zip(blocks) {
            magnitude[r] += m.iter().flatten().map(|v| v.abs()).sum::<f64>() * norm(x[j as usize]);
        }
    }
    let host = coupled_product(&k, &c, &x);
    for prec in [Precision::F32, Precision::F64] {
        let Some(ctx) = context(prec) else { return };
        let tol = match prec {
            Precision::F32 => SPMV_TOL_F32,
            Precision::F64 => SPMV_TOL_F64,
        };
        let got = GpuOperator::coupled(&ctx, &k, &c)
            .unwrap()
            .try_apply(&x)
            .unwrap();
        let plain = GpuOperator::new(&ctx, &k).unwrap().try_apply(&x).unwrap();
        for r in 0..n {
            for p in 0..3 {
                assert!(
                    (got[r][p] - host[r][p]).abs() <= tol * magnitude[r],
                    "{prec:?} row {r}: {:?} against {:?}",
                    got[r],
                    host[r]
                );
            }
        }
        // The coupling's part: C x on its rows, nothing elsewhere.
        let mut cx = vec![[0.0; 3]; n];
        c.apply_add(&x, &mut cx);
        let mut moved = 0;
        for r in 0..n {
            let d = [0, 1, 2].map(|p| got[r][p] - plain[r][p]);
            for p in 0..3 {
                assert!(
                    (d[p] - cx[r][p]).abs() <= 2.0 * tol * magnitude[r],
                    "{prec:?} row {r}: C x {:?}, device {d:?}",
                    cx[r]
                );
            }
            moved += usize::from(norm(cx[r]) > 4.0 * tol * magnitude[r]);
        }
        assert!(
            moved > 0,
            "{prec:?}: C x is within rounding of 0 everywhere"
        );
    }
}

/// The device's coupled CG (`exec::gpu::cg::pcg_coupled`, the GPU executor's `pcg_coupled`)
/// against the CPU's coupled CG with the same preconditioner (`fit::rotated::solve`, K's
/// diagonal ⊗ I₃) on the sector's system: each solution's residual (K ⊗ I₃ + C) x − b checked
/// in f64 on the host, the solutions within `COUPLED_TOL` of each other, and in f64 the same
/// iterations (within one: the device sums in another order). The system is coupled: the
/// solution of K x = b alone misses it by far more than the tolerance.
#[test]
fn coupled_cg_on_the_device_is_the_cpu_coupled_cg() {
    use polyspline::exec::{Executor, GpuExecutor};
    /// Relative agreement of the two solutions (both at residual 1e-10 of ‖b‖): f64 rounding
    /// of the device's sums, and in f32 the refinement's inner solves (each to 1e-3 in f32)
    /// meeting the f64 residual (found: 5e-11 in 32 iterations each in f64; 1.5e-8 in f32,
    /// 144 iterations against 32).
    const COUPLED_TOL: [(Precision, f64); 2] = [(Precision::F32, 1e-5), (Precision::F64, 1e-8)];
    let (k, c, b) = sector_system();
    let n = k.n();
    let (params, want, ci) = cpu_coupled_reference(&k, &c, &b);
    let bn = norm_all(&b);
    let residual = |x: &[[f64; 3]]| {
        let ax = coupled_product(&k, &c, x);
        let r: Vec<[f64; 3]> = b
            .iter()
            .zip(&ax)
            .map(|(b, a)| [0, 1, 2].map(|p| b[p] - a[p]))
            .collect();
        norm_all(&r)
    };
    assert!(
        residual(&want) <= 1e-10 * bn,
        "cpu: {:e}",
        residual(&want) / bn
    );
    // The coupling matters: K's own solution is no solution of the coupled system.
    let mut apart = vec![[0.0; 3]; n];
    k.clone().pcg(&b, &mut apart, &params, |_, _| {}).unwrap();
    assert!(
        residual(&apart) > 1e-6 * bn,
        "K x = b solves the coupled system"
    );
    let xn = norm_all(&want);
    for (prec, tol) in COUPLED_TOL {
        let Some(ctx) = context(prec) else { return };
        let mut got = vec![[0.0; 3]; n];
        let gi = GpuExecutor::new(&ctx)
            .pcg_coupled(k.clone(), &c, &b, &mut got, &params, &mut |_, _| {})
            .unwrap_or_else(|e| panic!("{prec:?}: {e}"));
        let outputs = || {
            let case = format!("sector.{prec:?}");
            let (ci, gi) = (executors::Debugged(ci), executors::Debugged(gi));
            executors::dump(
                "coupled_cg_on_the_device_is_the_cpu_coupled_cg",
                &case,
                &[
                    ("cpu", &want),
                    ("gpu", &got),
                    ("cpu.info", &ci),
                    ("gpu.info", &gi),
                ],
            )
        };
        let rn = residual(&got);
        assert!(
            rn <= 1e-10 * bn,
            "{prec:?}: residual {:e} of |b|; {}",
            rn / bn,
            outputs()
        );
        let dn = distance_all(&want, &got);
        assert!(
            dn <= tol * xn,
            "{prec:?}: solutions {:e} apart (|x| {xn:e}); {}",
            dn / xn,
            outputs()
        );
        if prec == Precision::F64 {
            assert!(
                gi.iterations.abs_diff(ci.iterations) <= 1,
                "{gi:?} against {ci:?}; {}",
                outputs()
            );
        }
    }
}

/// The CG kernels' CPU twins in their coupled form (`CgKernelParams::coupled`: spmv and
/// coupling, dot_partial, finalize_alpha, update_xr, dot_partial, finalize_beta, update_p),
/// driven in f64 as the device drives the kernels, are the CPU's coupled CG with K's
/// diagonal: the same iterations (within one) and solutions within 1e-8 of each other.
#[test]
fn coupled_cg_twins_are_the_cpu_coupled_cg() {
    use cpu::cg::{
        CgKernelParams, CgState, Scalars, finalize_alpha, finalize_beta, update_p, update_xr,
    };
    use cpu::coupling::{BlockRows, coupling};
    let (k, c, b) = sector_system();
    let n = k.n();
    let (_, want, ci) = cpu_coupled_reference(&k, &c, &b);
    let inv: Vec<f64> = k.diagonal().iter().map(|d| 1.0 / d).collect();
    let rows = BlockRows::of(&c);
    let indptr: Vec<u32> = k.indptr().iter().map(|&v| v as u32).collect();
    let v4 =
        |v: &[[f64; 3]]| -> Vec<[f64; 4]> { v.iter().map(|x| [x[0], x[1], x[2], 0.0]).collect() };
    let one = |v: [f64; 4]| [v[0] + v[1] + v[2], 0.0, 0.0, 0.0];
    let dot = |a: &[[f64; 4]], b: &[[f64; 4]]| -> [f64; 4] {
        let mut s = [0.0; 4];
        for (x, y) in a.iter().zip(b) {
            for l in 0..4 {
                s[l] += x[l] * y[l];
            }
        }
        s
    };
    let mut x = vec![[0.0; 4]; n];
    let mut r = v4(&b);
    let mut z: Vec<[f64; 4]> = r.iter().zip(&inv).map(|(r, d)| r.map(|v| v * d)).collect();
    let mut p = z.clone();
    let mut ap = vec![[0.0; 4]; n];
    let bb = one(dot(&r, &r));
    let mut sc = Scalars {
        rz: one(dot(&r, &z)),
        rr: bb,
        target2: [1e-20 * bb[0], f64::MAX, f64::MAX, f64::MAX],
        ..Default::default()
    };
    let mut st = CgState::default();
    let kp = CgKernelParams {
        n: n as u32,
        n_partials: 4,
        max_iters: 10_000,
        coupled: 1,
    };
    let sp = cpu::spmv::SpmvParams {
        n_rows: n as u32,
        ..Default::default()
    };
    let dp = cpu::dot::DotParams {
        n: n as u32,
        ..Default::default()
    };
    let mut partials = vec![[0.0; 4]; 8];
    while st.done == 0 {
        cpu::spmv::spmv(&sp, &indptr, k.indices(), k.data(), &p, &mut ap);
        coupling(
            &rows.params(),
            &rows.rows,
            &rows.indptr,
            &rows.cols,
            &rows.blocks,
            &p,
            &mut ap,
        );
        cpu::dot::dot_partial(&dp, &p, &ap, &mut partials, 4);
        finalize_alpha(&kp, &mut sc, &mut st, &partials);
        update_xr(&kp, &sc, &mut x, &mut r, &mut z, &p, &ap, &inv);
        cpu::dot::dot_partial(&dp, &r, &z, &mut partials, 4);
        finalize_beta(&kp, &mut sc, &st, &partials);
        update_p(&kp, &sc, &z, &mut p);
        assert!(st.iterations < 10_000 && st.breakdown == 0, "{st:?}");
    }
    let iterations = st.iterations as usize;
    assert!(
        iterations.abs_diff(ci.iterations) <= 1,
        "twins: {iterations} iterations, cpu: {ci:?}"
    );
    let got: Vec<[f64; 3]> = x.iter().map(|v| [v[0], v[1], v[2]]).collect();
    let dn = distance_all(&want, &got);
    assert!(dn <= 1e-8 * norm_all(&want), "solutions {dn:e} apart");
}
