//! The element degeneration energy (src/energy): gradient against finite differences, the
//! analytic value on affine images of the input, the minimisers' invariants (descent, every
//! accepted iterate certified valid, thread-count independence), the colouring property, and
//! the quality gain over the least-squares fit on a boundary-layer mesh whose least-squares step
//! had to be shortened.

use polyspline::energy::colored::color_control_points;
use polyspline::energy::{Energy, EnergyParams, EnergyScale, EnergySolver, Validity, minimize};
use polyspline::fit::{FitParams, FitSpace, FitWeights};
use polyspline::math::BezierNet;
use polyspline::math::bernstein::net_len;
use polyspline::mesh::generate::{extrude, grid_2d, star_2d, uniform};
use polyspline::mesh::{LinearMesh, Topology};
use polyspline::pipeline::{CurveOptions, curve_in_memory};
use polyspline::sample::multilinear;
use polyspline::spline::SplineSpace;
use polyspline::validity::{CpuCertifier, det_jacobian_bounds};

/// A half annulus r ∈ [1, 2] with `n` radial layers graded geometrically by `ratio` from the
/// inner boundary (thin boundary-layer cells there) and `m` cells around.
fn half_annulus(m: usize, n: usize, first: f64, ratio: f64) -> LinearMesh {
    let xs: Vec<f64> = (0..=m).map(|i| i as f64 / m as f64).collect();
    let mut ys = vec![0.0];
    let mut h = first;
    for _ in 0..n {
        ys.push(ys.last().unwrap() + h);
        h *= ratio;
    }
    let top = *ys.last().unwrap();
    let mut mesh = grid_2d(&xs, &ys);
    for c in mesh.coords.iter_mut() {
        let (t, r) = (std::f64::consts::PI * (1.0 - c[0]), 1.0 + c[1] / top);
        *c = [r * t.cos(), r * t.sin(), 0.0];
    }
    mesh
}

fn meshes() -> Vec<LinearMesh> {
    vec![
        star_2d(3),
        half_annulus(12, 6, 0.01, 2.0),
        extrude(&half_annulus(8, 4, 0.05, 1.8), &uniform(2, 0.3)),
    ]
}

/// Least-squares solution of the smooth fit, and a valid start near it.
fn fitted(m: &LinearMesh, t: &Topology, s: &SplineSpace) -> Vec<[f64; 3]> {
    polyspline::fit::fit(s, m, t, &FitParams::smooth(), |_, _| {})
        .unwrap()
        .0
}

/// The energy with the smooth fit's least-squares term and `params`.
fn energy<'a>(
    s: &'a SplineSpace,
    m: &LinearMesh,
    t: &Topology,
    c_star: &[[f64; 3]],
    params: &EnergyParams,
) -> Energy<'a> {
    Energy::new(s, m, t, &FitParams::smooth(), c_star, params).unwrap()
}

#[test]
fn gradient_matches_finite_differences() {
    for m in meshes() {
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let c_star = fitted(&m, &t, &s);
        let e = energy(
            &s,
            &m,
            &t,
            &c_star,
            &EnergyParams {
                weight: 0.7,
                ..Default::default()
            },
        );
        // A point between the initial map and the fit, off any symmetry.
        let c: Vec<[f64; 3]> = s
            .control_points
            .iter()
            .zip(&c_star)
            .enumerate()
            .map(|(i, (a, b))| {
                let w = 0.3 + 0.4 * ((i as f64) * 0.77).sin().abs();
                let mut p = [0.0; 3];
                for k in 0..m.dim {
                    p[k] = a[k] + w * (b[k] - a[k]);
                }
                p
            })
            .collect();
        let mut g = vec![[0.0; 3]; c.len()];
        let q = e.value_and_gradient(&c, &mut g);
        assert!(q.is_finite());
        assert!((q - e.value(&c)).abs() <= 1e-12 * q.abs().max(1e-30));
        let (lo, hi) = m.bounding_box();
        let h = 1e-7 * (hi[0] - lo[0]);
        let gmax = g.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
        for i in (0..c.len()).step_by(1 + c.len() / 25) {
            for k in 0..m.dim {
                let (mut cp, mut cm) = (c.clone(), c.clone());
                cp[i][k] += h;
                cm[i][k] -= h;
                let fd = (e.value(&cp) - e.value(&cm)) / (2.0 * h);
                assert!(
                    (fd - g[i][k]).abs() <= 1e-5 * gmax,
                    "control point {i} component {k}: finite difference {fd}, analytic {}",
                    g[i][k]
                );
            }
        }
    }
}

/// A discontinuous space whose element nets are the input elements' own degree-elevated
/// multilinear maps: the energy's value on an affine image of the input is known exactly.
struct OwnNets {
    dim: usize,
    cps: Vec<[f64; 3]>,
}

impl OwnNets {
    fn new(m: &LinearMesh, map: impl Fn([f64; 3]) -> [f64; 3]) -> Self {
        let nb = net_len(m.dim);
        let mut cps = Vec::new();
        for e in 0..m.n_elements() {
            let x = m.element_coords(e);
            for a in 0..nb {
                let l = [a % 3, (a / 3) % 3, a / 9];
                cps.push(map(multilinear(m.dim, &x, l.map(|c| c as f64 / 2.0))));
            }
        }
        OwnNets { dim: m.dim, cps }
    }
    fn nb(&self) -> usize {
        net_len(self.dim)
    }
}

impl FitSpace for OwnNets {
    fn dim(&self) -> usize {
        self.dim
    }
    fn n_elements(&self) -> usize {
        self.cps.len() / self.nb()
    }
    fn control_points(&self) -> &[[f64; 3]] {
        &self.cps
    }
    fn element_rows(&self, e: usize, o: &mut Vec<usize>, c: &mut Vec<u32>, w: &mut Vec<f64>) {
        let nb = self.nb();
        *o = (0..=nb).collect();
        *c = (0..nb).map(|a| (e * nb + a) as u32).collect();
        *w = vec![1.0; nb];
    }
    fn bezier_net_with(&self, e: usize, cps: &[[f64; 3]]) -> BezierNet {
        let mut n = [[0.0; 3]; 27];
        n[..self.nb()].copy_from_slice(&cps[e * self.nb()..(e + 1) * self.nb()]);
        n
    }
}

/// Element volume (area) of a straight element by a 4^d Gauss-free exact formula: the
/// shoelace formula in 2D, the divergence theorem over the bilinear faces of an extruded hex
/// in 3D (prism height × base area, valid for the extruded meshes used here).
fn element_volume(m: &LinearMesh, e: usize) -> f64 {
    let x = m.element_coords(e);
    let area = |p: &[[f64; 3]]| {
        0.5 * (0..4)
            .map(|i| p[i][0] * p[(i + 1) % 4][1] - p[(i + 1) % 4][0] * p[i][1])
            .sum::<f64>()
    };
    if m.dim == 2 {
        area(&x[..4])
    } else {
        area(&x[..4]) * (x[4][2] - x[0][2])
    }
}

#[test]
fn energy_of_an_affine_image_is_known() {
    let no_fit = FitParams {
        weights: FitWeights {
            corner: 0.0,
            boundary_corner: 0.0,
            midpoint: 0.0,
            deep_midpoint: None,
            extraordinary_midpoint: 0.0,
            boundary_midpoint: 0.0,
            frame_corner: 0.0,
            frame_midpoint: 0.0,
            feature: 0.0,
        },
        ..Default::default()
    };
    for m in [
        half_annulus(6, 3, 0.1, 1.5),
        extrude(&star_2d(3), &uniform(2, 0.4)),
    ] {
        let t = Topology::build(&m);
        let d = m.dim;
        let (c, s) = (0.6f64.cos(), 0.6f64.sin());
        // A rotation: f = 0, ∇ = 0.
        let rot = |p: [f64; 3]| {
            [
                c * p[0] - s * p[1] + 1.0,
                s * p[0] + c * p[1] - 2.0,
                p[2] + 0.5,
            ]
        };
        // Stretch by 2 and 1/2 after the rotation: singular values 2, 1/2 (, 1):
        // f = (4 + 1/4 + 4 + 1/4 (+ 2) − 2d) / (2d) = 4.5 / (2d).
        let stretch = |p: [f64; 3]| {
            let r = rot(p);
            [2.0 * r[0], 0.5 * r[1], r[2]]
        };
        let expected_f = 4.5 / (2.0 * d as f64);
        let n = m.n_elements();
        let vols: Vec<f64> = (0..n).map(|el| element_volume(&m, el)).collect();
        let mean = vols.iter().sum::<f64>() / n as f64;
        let maps = [
            (&rot as &dyn Fn([f64; 3]) -> [f64; 3], 0.0),
            (&stretch, expected_f),
        ];
        for ((map, f), scale_kind) in maps
            .into_iter()
            .flat_map(|m| [(m, EnergyScale::Element), (m, EnergyScale::Mean)])
        {
            let space = OwnNets::new(&m, map);
            let cps = space.cps.clone();
            let w = 1.3;
            let params = EnergyParams {
                weight: w,
                scale: scale_kind,
                ..Default::default()
            };
            let e = Energy::new(&space, &m, &t, &no_fit, &cps, &params).unwrap();
            let mut g = vec![[0.0; 3]; cps.len()];
            let q = e.value_and_gradient(&cps, &mut g);
            let h2 = |el: usize| match scale_kind {
                EnergyScale::Element => vols[el].powf(2.0 / d as f64),
                EnergyScale::Mean => mean.powf(2.0 / d as f64),
            };
            let expected: f64 = (0..n).map(|el| w * h2(el) * f).sum();
            let scale: f64 = (0..n).map(h2).sum();
            assert!(
                (q - expected).abs() <= 1e-10 * scale,
                "energy {q}, expected {expected}"
            );
            if f == 0.0 {
                let gmax = g.iter().flatten().fold(0.0f64, |a, b| a.max(b.abs()));
                let (lo, hi) = m.bounding_box();
                assert!(
                    gmax <= 1e-9 * scale / (hi[0] - lo[0]),
                    "gradient {gmax} at a rotation"
                );
            }
        }
    }
}

/// Both minimisers lower Q, keep it finite, and every accepted iterate is certified valid
/// above the required bound (checked independently with the Bernstein certificate on the
/// space's own nets).
#[test]
fn minimisers_descend_through_certified_iterates() {
    for m in meshes() {
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let c_star = fitted(&m, &t, &s);
        let e = energy(&s, &m, &t, &c_star, &EnergyParams::default());
        // Start from the initial map (certified for these meshes). Demand that every element
        // keeps 90 % of its starting det J bound, so the acceptance test decides steps.
        let start = s.control_points.clone();
        let required: Vec<f64> = (0..s.n_elements())
            .map(|el| 0.9 * det_jacobian_bounds(m.dim, &s.element_bezier_with(el, &start), 6).lower)
            .collect();
        let validity = Validity::for_start(&e, &CpuCertifier, 6, &required, &start).unwrap();
        for solver in [EnergySolver::Lbfgs, EnergySolver::Colored] {
            let params = EnergyParams {
                solver,
                max_iterations: 30,
                ..Default::default()
            };
            let mut seen = 0;
            let mut last = e.value(&start);
            let (c, info) = minimize(&e, &validity, &start, &params, &mut |c| {
                seen += 1;
                for (el, &req) in required.iter().enumerate() {
                    let b = det_jacobian_bounds(m.dim, &s.element_bezier_with(el, c), 6);
                    assert!(
                        b.certified_positive() && b.lower > req,
                        "{solver:?}: element {el} not certified above {req}"
                    );
                }
                let q = e.value(c);
                assert!(
                    q.is_finite() && q <= last,
                    "{solver:?}: Q rose {last} -> {q}"
                );
                last = q;
            })
            .unwrap();
            assert_eq!(seen, info.iterations);
            assert!(info.iterations > 0, "{solver:?} made no step");
            assert!(info.final_energy < info.initial_energy, "{info:?}");
            assert!((info.final_energy - e.value(&c)).abs() <= 1e-12 * info.final_energy.abs());
        }
    }
}

#[test]
fn colouring_separates_the_control_points_of_every_element() {
    for m in meshes() {
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let e = energy(&s, &m, &t, &s.control_points, &EnergyParams::default());
        let ids: Vec<&[u32]> = (0..e.n_elements())
            .map(|el| e.element_control_points(el))
            .collect();
        let color = color_control_points(s.n_control_points(), &ids);
        for el in ids {
            let mut seen: Vec<u32> = el.iter().map(|&i| color[i as usize]).collect();
            seen.sort_unstable();
            let n = seen.len();
            seen.dedup();
            assert_eq!(
                seen.len(),
                n,
                "two control points of one element share a colour"
            );
        }
    }
}

/// The same minimisation on 1 and 3 threads gives the same bits.
#[test]
fn results_do_not_depend_on_the_thread_count() {
    let m = half_annulus(12, 6, 0.01, 2.0);
    let t = Topology::build(&m);
    let s = SplineSpace::build(&m, &t);
    let c_star = fitted(&m, &t, &s);
    let run = |threads: usize, solver: EnergySolver| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let e = energy(&s, &m, &t, &c_star, &EnergyParams::default());
                let start = s.control_points.clone();
                let v = Validity::for_start(&e, &CpuCertifier, 6, &[], &start).unwrap();
                let params = EnergyParams {
                    solver,
                    max_iterations: 10,
                    ..Default::default()
                };
                minimize(&e, &v, &start, &params, &mut |_| {}).unwrap().0
            })
    };
    for solver in [EnergySolver::Lbfgs, EnergySolver::Colored] {
        assert!(run(1, solver) == run(3, solver), "{solver:?}");
    }
}

/// On a boundary-layer mesh the energy fit (both solvers) lowers the energy and ends with a
/// minimum scaled Jacobian at least that of its start (the certified least-squares fit).
#[test]
fn energy_fit_improves_quality_where_least_squares_was_shortened() {
    let dir = std::env::temp_dir().join(format!("polyspline-energy-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("annulus.msh");
    let m = half_annulus(24, 8, 0.004, 2.0);
    let t = Topology::build(&m);
    let linear = polyspline::sample::sample(&m, &m, &t, 1);
    polyspline::pipeline::write_high_order(&linear, &path, &Default::default(), &[]).unwrap();
    for solver in [EnergySolver::Lbfgs, EnergySolver::Colored] {
        // The energy's start: the least-squares fit after the certified control-point line
        // search (no energy iterations).
        let start = CurveOptions {
            energy: Some(EnergyParams {
                solver,
                max_iterations: 0,
                ..Default::default()
            }),
            ..Default::default()
        };
        let ls = curve_in_memory(&path, &start).unwrap().report;
        let options = CurveOptions {
            energy: Some(EnergyParams {
                solver,
                ..Default::default()
            }),
            ..Default::default()
        };
        let r = curve_in_memory(&path, &options).unwrap().report;
        let info = r.energy.as_ref().unwrap();
        assert!(info.final_energy < info.initial_energy);
        assert!(
            r.min_scaled_jacobian >= ls.min_scaled_jacobian,
            "{solver:?}: min scaled Jacobian {} vs least squares {}",
            r.min_scaled_jacobian,
            ls.min_scaled_jacobian
        );
        eprintln!(
            "{solver:?}: min SJ {} (least squares {}, input {})",
            r.min_scaled_jacobian, ls.min_scaled_jacobian, ls.input_min_scaled_jacobian
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A bad energy option is a one-line error and a non-zero exit, with nothing written.
#[test]
fn bad_energy_weight_is_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("polyspline-energy-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out.msh");
    let input =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes/real/dealii/example.msh");
    let r = std::process::Command::new(env!("CARGO_BIN_EXE_polyspline"))
        .arg("curve")
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .args(["--fit", "energy", "--energy-weight=-1"])
        .output()
        .unwrap();
    assert!(!r.status.success());
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        err.contains("--energy-weight") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!out.exists());
    std::fs::remove_dir_all(&dir).ok();
}
