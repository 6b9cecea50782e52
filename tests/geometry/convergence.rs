//! Convergence of the curved boundary under refinement: O-grid meshes of a disc (quads), a ball
//! and a torus (hexes), generated here with the boundary vertices on the analytic curve or
//! surface, curved by `curve` at order 2 with the fit modes `position`, `frame` and `smooth`;
//! the straight input is the reference. The error is the largest distance of the written
//! boundary (the order-2 output elements are the spline exactly) from the analytic surface,
//! sampled densely on every boundary facet.
//!
//! The measured errors are compared with `tests/data/convergence/reference.json` (within 20%,
//! so regressions and improvements both show). Run with `POLYSPLINE_WRITE_REFERENCE=1` to
//! rewrite that file, and with `--nocapture` to see the table and the written meshes.

use crate::common;

use polyspline::fit::{FitParams, FitTargets, FitWeights, SmoothParams};
use polyspline::io::read_raw;
use polyspline::math::bernstein::net_len;
use polyspline::mesh::HighOrderMesh;
use polyspline::mesh::MeshOptions;
use polyspline::mesh::high_order::lattice_point;
use polyspline::pipeline::{CurveOptions, CurveReport, Geometry, LineSearchMode, curve};
use polyspline::quality::lagrange_1d;
use std::collections::{BTreeMap, HashMap};
use std::f64::consts::PI;
use std::io::Write;
use std::path::{Path, PathBuf};

type Mesh = (Vec<[f64; 3]>, Vec<Vec<u32>>);

/// Disc of radius R: an n×n square block of half-side R/2 and an O-grid ring of m = ⌈n/2⌉
/// layers; boundary vertices at the radial projections of the square's (uniform) boundary
/// points, so their spacing along the circle varies smoothly by a factor of about 2.
fn disc(n: usize, r: f64) -> Mesh {
    let a = 0.5 * r;
    let m = n.div_ceil(2);
    let mut pts: Vec<[f64; 3]> = Vec::new();
    let mut ids: HashMap<(i64, i64), u32> = HashMap::new();
    let mut id = |p: [f64; 3], pts: &mut Vec<[f64; 3]>| {
        let key = ((p[0] * 1e9).round() as i64, (p[1] * 1e9).round() as i64);
        *ids.entry(key).or_insert_with(|| {
            pts.push(p);
            pts.len() as u32 - 1
        })
    };
    let mut cells = Vec::new();
    let s = |i: usize| -a + 2.0 * a * i as f64 / n as f64;
    for j in 0..n {
        for i in 0..n {
            let c = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
                .map(|(i, j)| id([s(i), s(j), 0.0], &mut pts));
            cells.push(c.to_vec());
        }
    }
    // Square boundary, counter-clockwise: 4n points.
    let q = |k: usize| -> [f64; 3] {
        let (side, t) = (k / n % 4, s(k % n));
        match side {
            0 => [t, -a, 0.0],
            1 => [a, t, 0.0],
            2 => [-t, a, 0.0],
            _ => [-a, -t, 0.0],
        }
    };
    let ring = |k: usize, j: usize| -> [f64; 3] {
        let p = q(k);
        let l = (p[0] * p[0] + p[1] * p[1]).sqrt();
        let t = j as f64 / m as f64;
        [
            p[0] + t * (r * p[0] / l - p[0]),
            p[1] + t * (r * p[1] / l - p[1]),
            0.0,
        ]
    };
    for k in 0..4 * n {
        for j in 0..m {
            let c = [(k, j), (k, j + 1), (k + 1, j + 1), (k + 1, j)]
                .map(|(k, j)| id(ring(k % (4 * n), j), &mut pts));
            cells.push(c.to_vec());
        }
    }
    for c in &mut cells {
        let x = c.iter().map(|&v| pts[v as usize]).collect::<Vec<_>>();
        let area: f64 = (0..4)
            .map(|i| x[i][0] * x[(i + 1) % 4][1] - x[(i + 1) % 4][0] * x[i][1])
            .sum();
        if area < 0.0 {
            c.reverse();
        }
    }
    (pts, cells)
}

/// Ball of radius R: an n³ cube block of half-side R/2 and six O-grid blocks of ⌈n/2⌉ layers
/// (the boundary is a cubed sphere).
fn ball(n: usize, r: f64) -> Mesh {
    let a = 0.5 * r;
    let m = n.div_ceil(2);
    let mut pts: Vec<[f64; 3]> = Vec::new();
    let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
    let mut id = |p: [f64; 3], pts: &mut Vec<[f64; 3]>| {
        let key = p.map(|c| (c * 1e9).round() as i64);
        *ids.entry(key).or_insert_with(|| {
            pts.push(p);
            pts.len() as u32 - 1
        })
    };
    let s = |i: usize| -a + 2.0 * a * i as f64 / n as f64;
    let mut cells = Vec::new();
    let hex = |f: &dyn Fn(usize, usize, usize) -> [f64; 3]| {
        [
            (0, 0, 0),
            (1, 0, 0),
            (1, 1, 0),
            (0, 1, 0),
            (0, 0, 1),
            (1, 0, 1),
            (1, 1, 1),
            (0, 1, 1),
        ]
        .map(|(i, j, k)| f(i, j, k))
    };
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let x = hex(&|di, dj, dk| [s(i + di), s(j + dj), s(k + dk)]);
                cells.push(x.map(|p| id(p, &mut pts)).to_vec());
            }
        }
    }
    for axis in 0..3 {
        for sign in [-1.0, 1.0] {
            let face = |i: usize, j: usize| -> [f64; 3] {
                let mut p = [0.0; 3];
                p[axis] = sign * a;
                p[(axis + 1) % 3] = s(i);
                p[(axis + 2) % 3] = s(j);
                p
            };
            for l in 0..m {
                for j in 0..n {
                    for i in 0..n {
                        let x = hex(&|di, dj, dl| {
                            let p = face(i + di, j + dj);
                            let len = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                            let t = (l + dl) as f64 / m as f64;
                            p.map(|c| c + t * (r * c / len - c))
                        });
                        cells.push(x.map(|p| id(p, &mut pts)).to_vec());
                    }
                }
            }
        }
    }
    orient_hexes(&pts, &mut cells);
    (pts, cells)
}

/// Torus of major radius R and minor radius r: the disc mesh of the cross-section swept around
/// the z axis in 4·(R/r)·n segments (about the boundary spacing of the cross-section).
fn torus(n: usize, big_r: f64, r: f64) -> Mesh {
    let (dp, dc) = disc(n, r);
    let segments = (4.0 * big_r / r).round() as usize * n;
    let np = dp.len() as u32;
    let mut pts = Vec::new();
    for k in 0..segments {
        let phi = 2.0 * PI * k as f64 / segments as f64;
        for p in &dp {
            let rho = big_r + p[0];
            pts.push([rho * phi.cos(), rho * phi.sin(), p[1]]);
        }
    }
    let mut cells = Vec::new();
    for k in 0..segments {
        let (o0, o1) = (k as u32 * np, ((k + 1) % segments) as u32 * np);
        for c in &dc {
            let mut h: Vec<u32> = c.iter().map(|&v| v + o0).collect();
            h.extend(c.iter().map(|&v| v + o1));
            cells.push(h);
        }
    }
    orient_hexes(&pts, &mut cells);
    (pts, cells)
}

fn orient_hexes(pts: &[[f64; 3]], cells: &mut [Vec<u32>]) {
    for c in cells {
        let x = |i: usize| pts[c[i] as usize];
        let d = |a: usize, b: usize| -> [f64; 3] { std::array::from_fn(|k| x(b)[k] - x(a)[k]) };
        let (u, v, w) = (d(0, 1), d(0, 3), d(0, 4));
        let det = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0])
            + u[2] * (v[0] * w[1] - v[1] * w[0]);
        if det < 0.0 {
            let (lo, hi) = c.split_at_mut(4);
            lo.swap_with_slice(hi);
        }
    }
}

/// Gmsh MSH 2.2 ASCII, elements only.
fn write_msh(path: &Path, dim: usize, (pts, cells): &Mesh) {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    writeln!(
        f,
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n{}",
        pts.len()
    )
    .unwrap();
    for (i, p) in pts.iter().enumerate() {
        writeln!(f, "{} {:.17e} {:.17e} {:.17e}", i + 1, p[0], p[1], p[2]).unwrap();
    }
    writeln!(f, "$EndNodes\n$Elements\n{}", cells.len()).unwrap();
    let t = if dim == 2 { 3 } else { 5 };
    for (i, c) in cells.iter().enumerate() {
        let vs: Vec<String> = c.iter().map(|v| (v + 1).to_string()).collect();
        writeln!(f, "{} {t} 2 1 1 {}", i + 1, vs.join(" ")).unwrap();
    }
    writeln!(f, "$EndElements").unwrap();
}

/// Largest distance from the analytic surface (`dist`) over `s`+1 points per direction of
/// every boundary side of the written mesh.
/// Also the largest distance over the points where `regular` holds.
fn boundary_error(
    ho: &HighOrderMesh,
    dist: &dyn Fn([f64; 3]) -> f64,
    regular: &dyn Fn([f64; 3]) -> bool,
    s: usize,
) -> (f64, f64) {
    let (p, dim) = (ho.order, ho.dim);
    // Boundary sides: corner node sets that occur once.
    let corner_lattice: Vec<[usize; 3]> = (0..1usize << dim)
        .map(|c| [c & 1, (c >> 1) & 1, (c >> 2) & 1].map(|b| b * p))
        .collect();
    let npe = ho.nodes_per_element();
    let lattice: Vec<[usize; 3]> = (0..npe).map(|n| lattice_point(p, dim, n)).collect();
    let side_key = |e: usize, k: usize, sgn: usize| -> Vec<u32> {
        let el = ho.element(e);
        let mut key: Vec<u32> = corner_lattice
            .iter()
            .filter(|l| l[k] == sgn * p)
            .map(|l| el[lattice.iter().position(|m| m == l).unwrap()])
            .collect();
        key.sort_unstable();
        key
    };
    let mut count: HashMap<Vec<u32>, usize> = HashMap::new();
    for e in 0..ho.n_elements() {
        for k in 0..dim {
            for sgn in 0..2 {
                *count.entry(side_key(e, k, sgn)).or_default() += 1;
            }
        }
    }
    let (mut worst, mut worst_regular) = (0.0f64, 0.0f64);
    let (mut v, mut dv) = (vec![vec![0.0; p + 1]; 3], vec![0.0; p + 1]);
    for e in 0..ho.n_elements() {
        let el = ho.element(e);
        for k in 0..dim {
            for sgn in 0..2 {
                if count[&side_key(e, k, sgn)] != 1 {
                    continue;
                }
                let others: Vec<usize> = (0..dim).filter(|&j| j != k).collect();
                let n2 = if dim == 3 { s + 1 } else { 1 };
                for a in 0..=s {
                    for b in 0..n2 {
                        let mut u = [0.0; 3];
                        u[k] = sgn as f64;
                        u[others[0]] = a as f64 / s as f64;
                        if dim == 3 {
                            u[others[1]] = b as f64 / s as f64;
                        }
                        for j in 0..dim {
                            lagrange_1d(p, u[j], &mut v[j], &mut dv);
                        }
                        let mut x = [0.0; 3];
                        for (n, l) in lattice.iter().enumerate() {
                            let w = (0..dim).map(|j| v[j][l[j]]).product::<f64>();
                            let node = ho.nodes[el[n] as usize];
                            for c in 0..3 {
                                x[c] += w * node[c];
                            }
                        }
                        worst = worst.max(dist(x));
                        if regular(x) {
                            worst_regular = worst_regular.max(dist(x));
                        }
                    }
                }
            }
        }
    }
    (worst, worst_regular)
}

struct Shape {
    name: &'static str,
    dim: usize,
    levels: &'static [usize],
    make: fn(usize) -> Mesh,
    dist: fn([f64; 3]) -> f64,
    /// Points away from the irregular boundary vertices (the cubed sphere's 8 corners).
    regular: fn([f64; 3]) -> bool,
}

/// `smooth_no_kinks` is `smooth` with the kink detection off (`--kink-angle 180`).
const MODES: [&str; 5] = ["linear", "position", "frame", "smooth", "smooth_no_kinks"];

fn options(mode: &str) -> CurveOptions {
    let (geometry, fit, order) = match mode {
        "linear" => (Geometry::Straight, FitParams::default(), 1),
        "position" => (Geometry::SplineFitted, FitParams::default(), 2),
        "frame" => (
            Geometry::SplineFitted,
            FitParams {
                weights: FitWeights::frame(),
                ..Default::default()
            },
            2,
        ),
        "smooth" => (Geometry::SplineFitted, FitParams::smooth(), 2),
        "smooth_no_kinks" => (
            Geometry::SplineFitted,
            FitParams {
                targets: FitTargets::Smooth(SmoothParams {
                    kink_angle_deg: 180.0,
                    ..Default::default()
                }),
                ..FitParams::smooth()
            },
            2,
        ),
        _ => unreachable!(),
    };
    CurveOptions {
        order,
        geometry,
        fit,
        line_search_mode: LineSearchMode::Local,
        // The shapes are smooth; their coarse levels turn by up to 60° between facets, which
        // the default feature angle would take for sharp edges.
        features: polyspline::pipeline::FeatureOptions {
            params: polyspline::mesh::features::FeatureParams::off(),
            ..Default::default()
        },
        // The study compares fit targets on one spline space: `auto` could take graded knots
        // for one mode and uniform ones for another.
        knots: polyspline::spline::KnotParams {
            intervals: polyspline::spline::KnotIntervals::Uniform,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn shapes() -> Vec<Shape> {
    vec![
        Shape {
            name: "circle",
            dim: 2,
            levels: &[4, 8, 16, 32],
            make: |n| disc(n, 1.0),
            dist: |x| ((x[0] * x[0] + x[1] * x[1]).sqrt() - 1.0).abs(),
            regular: |_| true,
        },
        Shape {
            name: "sphere",
            dim: 3,
            // 864, 2048 and 6912 hexes: the asymptotic order shows from 864 on.
            levels: &[6, 8, 12],
            make: |n| ball(n, 1.0),
            dist: |x| ((x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt() - 1.0).abs(),
            // More than 30° from every corner direction (±1, ±1, ±1)/√3.
            regular: |x| {
                let l = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
                (x[0].abs() + x[1].abs() + x[2].abs()) / (3f64.sqrt() * l)
                    < 30f64.to_radians().cos()
            },
        },
        Shape {
            name: "torus",
            dim: 3,
            levels: &[2, 3, 4, 6],
            make: |n| torus(n, 1.0, 0.5),
            dist: |x| {
                let rho = (x[0] * x[0] + x[1] * x[1]).sqrt() - 1.0;
                ((rho * rho + x[2] * x[2]).sqrt() - 0.5).abs()
            },
            regular: |_| true,
        },
    ]
}

fn dir() -> PathBuf {
    // The running test's own directory: tests run in parallel and share file names.
    common::test_dir()
}

/// Errors per shape and mode (one per level), the mesh sizes h (largest boundary edge) and the
/// worst boundary-vertex deviation of the `smooth` fit.
#[derive(Default, serde::Serialize, serde::Deserialize)]
struct Study {
    elements: Vec<usize>,
    h: Vec<f64>,
    /// None where `curve` refused (the fit could not be made valid).
    errors: BTreeMap<String, Vec<Option<f64>>>,
    /// The same, only over points away from irregular boundary vertices.
    errors_regular: BTreeMap<String, Vec<Option<f64>>>,
    smooth_vertex_deviation: Vec<f64>,
}

fn max_boundary_edge(ho: &HighOrderMesh, dist: fn([f64; 3]) -> f64) -> f64 {
    // Order-1 output: element edges with both ends on the surface.
    let npe = ho.nodes_per_element();
    let mut h = 0.0f64;
    for e in 0..ho.n_elements() {
        let el = ho.element(e);
        for a in 0..npe {
            for b in a + 1..npe {
                let (la, lb) = (lattice_point(1, ho.dim, a), lattice_point(1, ho.dim, b));
                let diff = (0..3).filter(|&k| la[k] != lb[k]).count();
                let (xa, xb) = (ho.nodes[el[a] as usize], ho.nodes[el[b] as usize]);
                if diff == 1 && dist(xa) < 1e-9 && dist(xb) < 1e-9 {
                    let l = (0..3).map(|k| (xa[k] - xb[k]).powi(2)).sum::<f64>().sqrt();
                    h = h.max(l);
                }
            }
        }
    }
    h
}

fn run(shape: &Shape, modes: &[&str]) -> Study {
    let mut study = Study::default();
    for &n in shape.levels {
        let mesh = (shape.make)(n);
        let ne = mesh.1.len();
        let input = dir().join(format!(
            "{}_{}_{ne}.msh",
            shape.name,
            if shape.dim == 2 { "quad4" } else { "hex8" }
        ));
        write_msh(&input, shape.dim, &mesh);
        study.elements.push(ne);
        for &mode in modes {
            let out = dir().join(format!("{}_{ne}_{mode}.msh", shape.name));
            // Every mode writes a valid mesh (`frame` included: where its initial map is not
            // certified, demotion grows Q2 regions until it is).
            let r: CurveReport = curve(&input, &out, &options(mode))
                .unwrap_or_else(|e| panic!("{} n={n} {mode}: {e}", shape.name));
            assert_eq!(r.invalid_elements, 0);
            let ho = HighOrderMesh::from_raw(read_raw(&out).unwrap()).unwrap();
            let (err, err_regular) =
                boundary_error(&ho, &|x| (shape.dist)(x), &|x| (shape.regular)(x), 16);
            study.errors.entry(mode.into()).or_default().push(Some(err));
            study
                .errors_regular
                .entry(mode.into())
                .or_default()
                .push(Some(err_regular));
            if mode == "linear" {
                study.h.push(max_boundary_edge(&ho, shape.dist));
            }
            if mode == "smooth" {
                study
                    .smooth_vertex_deviation
                    .push(r.boundary_vertex_deviation_max);
            }
        }
    }
    study
}

/// Observed order between consecutive levels (NaN where a level failed).
fn orders(h: &[f64], e: &[Option<f64>]) -> Vec<f64> {
    (1..h.len())
        .map(|i| match (e[i - 1], e[i]) {
            (Some(a), Some(b)) => (a / b).ln() / (h[i - 1] / h[i]).ln(),
            _ => f64::NAN,
        })
        .collect()
}

#[test]
fn boundary_convergence() {
    let reference_path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/convergence/reference.json");
    let write = std::env::var("POLYSPLINE_WRITE_REFERENCE").is_ok();
    let mut all: BTreeMap<String, Study> = BTreeMap::new();
    for shape in shapes() {
        let t = std::time::Instant::now();
        let study = run(&shape, &MODES);
        println!(
            "{}: {:.1} s, elements {:?}, h {:?}",
            shape.name,
            t.elapsed().as_secs_f64(),
            study.elements,
            study.h
        );
        for mode in MODES {
            let e = &study.errors[mode];
            println!(
                "  {mode:9} errors {:?}  orders {:?}",
                e.iter()
                    .map(|x| x.map_or("failed".into(), |x| format!("{x:.3e}")))
                    .collect::<Vec<_>>(),
                orders(&study.h, e)
                    .iter()
                    .map(|x| format!("{x:.2}"))
                    .collect::<Vec<_>>()
            );
        }
        for mode in MODES {
            let e = &study.errors_regular[mode];
            println!(
                "  {mode:9} regular {:?}  orders {:?}",
                e.iter()
                    .map(|x| x.map_or("failed".into(), |x| format!("{x:.3e}")))
                    .collect::<Vec<_>>(),
                orders(&study.h, e)
                    .iter()
                    .map(|x| format!("{x:.2}"))
                    .collect::<Vec<_>>()
            );
        }
        println!(
            "  smooth vertex deviation {:?}",
            study.smooth_vertex_deviation
        );
        all.insert(shape.name.into(), study);
    }
    if write {
        std::fs::create_dir_all(reference_path.parent().unwrap()).unwrap();
        std::fs::write(&reference_path, serde_json::to_string_pretty(&all).unwrap()).unwrap();
    }
    let last = |s: &Study, mode: &str| s.errors[mode].last().unwrap().unwrap();
    let last_order = |s: &Study, mode: &str| *orders(&s.h, &s.errors[mode]).last().unwrap();
    // The straight input converges at second order, and every fit beats it.
    for (name, s) in &all {
        let o = last_order(s, "linear");
        assert!((1.7..2.3).contains(&o), "{name}: linear order {o}");
        for mode in ["position", "smooth"] {
            let bound = if mode == "smooth" { 0.08 } else { 0.5 };
            assert!(last(s, mode) < bound * last(s, "linear"), "{name} {mode}");
        }
    }
    // Smooth targets: third order on smooth boundaries (on the cubed sphere with Q2 elements at
    // the kinks of its grid lines), and a stated gain over the paper's `position` fit.
    let (circle, sphere, torus) = (&all["circle"], &all["sphere"], &all["torus"]);
    for (name, s, gain) in [
        ("circle", circle, 2.5),
        ("torus", torus, 1.2),
        ("sphere", sphere, 5.0),
    ] {
        let ratio = last(s, "position") / last(s, "smooth");
        assert!(
            ratio > gain,
            "{name}: smooth is only {ratio:.2}× better than position"
        );
    }
    for (name, s) in [("circle", circle), ("torus", torus), ("sphere", sphere)] {
        let o = last_order(s, "smooth");
        assert!(o >= 2.7, "{name}: smooth converges at order {o:.2}");
    }
    // The cubed sphere's grid lines kink across its block arcs: without Q2 elements there the
    // C¹ spline stays near second order. The disc and torus grids have no kinks.
    let o = last_order(sphere, "smooth_no_kinks");
    assert!(o < 2.2, "sphere without kink elements: order {o:.2}");
    // (Measured 4.7×: 7.6× with the midpoints weighted alike inside and on the boundary, whose
    // heavier interior samples pulled the spline across the kinks further off the surface.)
    let ratio = last(sphere, "smooth_no_kinks") / last(sphere, "smooth");
    assert!(ratio > 4.0, "sphere: kink elements gain only {ratio:.2}×");
    // (Equal up to the CG tolerance: the two runs need not sum in the same order.)
    for (name, s) in [("circle", circle), ("torus", torus)] {
        for (a, b) in s.errors["smooth"].iter().zip(&s.errors["smooth_no_kinks"]) {
            let (a, b) = (a.unwrap(), b.unwrap());
            assert!((a / b - 1.0).abs() < 1e-3, "{name}: {a:.4e} vs {b:.4e}");
        }
    }
    // `position` stays at second order on the circle (the chords limit it).
    assert!(last_order(circle, "position") < 2.5);
    // Boundary vertices are reproduced (relative to the bounding-box diagonal).
    for (name, s, tol) in [
        ("circle", circle, 1e-5),
        ("torus", torus, 1e-4),
        ("sphere", sphere, 3e-3),
    ] {
        let d = *s.smooth_vertex_deviation.last().unwrap();
        assert!(d < tol, "{name}: boundary vertex deviation {d:.2e}");
    }
    // Regressions (and improvements) against the committed numbers: within 20%.
    let reference: BTreeMap<String, Study> =
        serde_json::from_str(&std::fs::read_to_string(&reference_path).unwrap()).unwrap();
    for (name, s) in &all {
        let r = &reference[name];
        assert_eq!(s.elements, r.elements, "{name}: meshes changed");
        for (table, rtable) in [
            (&s.errors, &r.errors),
            (&s.errors_regular, &r.errors_regular),
        ] {
            for (mode, errs) in table {
                for (level, (got, want)) in errs.iter().zip(&rtable[mode]).enumerate() {
                    match (got, want) {
                        (Some(g), Some(w)) => assert!(
                            (g / w - 1.0).abs() < 0.2,
                            "{name} {mode} level {level}: error {g:.3e}, reference {w:.3e}"
                        ),
                        (None, None) => {}
                        _ => panic!("{name} {mode} level {level}: {got:?} vs reference {want:?}"),
                    }
                }
            }
        }
    }
}

/// The sphere at 16 and 24 cube divisions (16384 and 55296 hexes), default fit only: the order
/// stays at three, and the boundary vertices are reproduced better on the finer mesh. A fixed
/// kink angle leaves a stretch of each block arc C¹ whatever the refinement (order 2.5 here,
/// vertex deviation growing 2.4e-5 → 4.1e-5), and the elements diagonal to the cube corners
/// converge at second order unless they are Q2.
#[test]
fn sphere_third_order_on_finer_levels() {
    let shape = shapes().into_iter().find(|s| s.name == "sphere").unwrap();
    let shape = Shape {
        levels: &[16, 24],
        ..shape
    };
    let s = run(&shape, &["linear", "smooth"]);
    let e: Vec<f64> = s.errors["smooth"].iter().map(|e| e.unwrap()).collect();
    let o = orders(&s.h, &s.errors["smooth"])[0];
    let d = &s.smooth_vertex_deviation;
    println!(
        "sphere {:?} hexes: smooth errors {:.3e} {:.3e}, order {o:.2}; vertex deviation {:.2e} {:.2e}",
        s.elements, e[0], e[1], d[0], d[1]
    );
    assert!(o >= 2.8, "sphere: smooth converges at order {o:.2}");
    assert!(e[1] < 0.02 * s.errors["linear"][1].unwrap());
    assert!(d[1] < 0.6 * d[0], "sphere: vertex deviation {d:?}");
}

/// The smooth-mode targets of boundary midpoints (edge midpoints, face centres) lie on the
/// analytic surface to third order; the chord midpoints only to second.
#[test]
fn smooth_targets_converge() {
    use polyspline::fit::SmoothTargets;
    use polyspline::mesh::Topology;
    use polyspline::sample::multilinear;
    for shape in shapes() {
        let mut rows = Vec::new();
        for &n in shape.levels {
            let mesh = (shape.make)(n);
            let path = dir().join(format!("targets_{}_{n}.msh", shape.name));
            write_msh(&path, shape.dim, &mesh);
            let m = polyspline::io::read_mesh(&path, &MeshOptions::default()).unwrap();
            let t = Topology::build(&m);
            let st = SmoothTargets::build(&m, &t, &SmoothParams::default());
            let (mut chord, mut target) = (0.0f64, 0.0f64);
            for e in 0..m.n_elements() {
                let x = m.element_coords(e);
                let corr = st.element_corrections(&m, &t, e);
                let n_samples = net_len(shape.dim);
                for (i, c) in corr.iter().enumerate().take(n_samples) {
                    let l = [i % 3, (i / 3) % 3, i / 9];
                    let on = (0..shape.dim).any(|k| {
                        l[k] != 1
                            && t.neighbor(e, 2 * k + l[k] / 2) == polyspline::mesh::topology::NONE
                    });
                    if !on || (0..shape.dim).all(|k| l[k] != 1) {
                        continue;
                    }
                    let p = multilinear(shape.dim, &x, l.map(|c| c as f64 / 2.0));
                    let q: [f64; 3] = std::array::from_fn(|k| p[k] + c[k]);
                    chord = chord.max((shape.dist)(p));
                    target = target.max((shape.dist)(q));
                }
            }
            rows.push((n, chord, target, st.smooth_vertices, st.feature_vertices));
        }
        println!("{} targets: {rows:?}", shape.name);
        let (a, b) = (rows[rows.len() - 2], rows[rows.len() - 1]);
        let order = (a.2 / b.2).ln() / (b.0 as f64 / a.0 as f64).ln();
        assert!(
            order > 3.5,
            "{}: targets converge at order {order:.2}",
            shape.name
        );
        assert!(
            b.2 < 0.02 * b.1,
            "{}: targets {} vs chords {}",
            shape.name,
            b.2,
            b.1
        );
        assert_eq!(
            b.4, 0,
            "{}: no feature vertices on a smooth surface",
            shape.name
        );
    }
}

/// Unstructured boundaries: the plate with a hole of `scripts/fidelity_shapes.py` (Gmsh's
/// frontal-Delaunay quads, recombined, so the hole's vertices are irregular and most elements
/// there are Q2) at three levels, each halving the mesh size, curved with default features and
/// the `smooth` and `position` fits. The error is the largest distance of the written boundary
/// from the hole's circle over the points near it (the straight sides are another matter). The
/// smooth fit converges at third order or better and beats the chords; the errors are compared
/// with `tests/data/convergence/unstructured.json` as above (rewritten with
/// `POLYSPLINE_WRITE_REFERENCE=1`).
#[test]
fn unstructured_boundary_convergence() {
    if !common::have_gmsh("unstructured_boundary_convergence (Gmsh makes its meshes)") {
        return;
    }
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/fidelity_shapes.py");
    let hole = |x: [f64; 3]| ((x[0] * x[0] + x[1] * x[1]).sqrt() - 0.5).abs();
    let near_hole = |x: [f64; 3]| (x[0] * x[0] + x[1] * x[1]).sqrt() < 0.75;
    let mut study = Study::default();
    for level in 1..=3 {
        let (input, cad) = (
            dir().join(format!("plate_{level}.msh")),
            dir().join(format!("plate_{level}_cad.msh")),
        );
        let out = common::run_ok(
            common::python()
                .arg(script)
                .args(["make", "plate", &level.to_string()])
                .arg(&input)
                .arg(&cad),
        );
        let made: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        study
            .elements
            .push(made["elements"].as_u64().unwrap() as usize);
        for mode in ["position", "smooth"] {
            let o = CurveOptions {
                order: 2,
                geometry: Geometry::SplineFitted,
                fit: if mode == "smooth" {
                    FitParams::smooth()
                } else {
                    FitParams::default()
                },
                line_search_mode: LineSearchMode::Local,
                ..Default::default()
            };
            let path = dir().join(format!("plate_{level}_{mode}.msh"));
            let r = curve(&input, &path, &o).unwrap();
            assert_eq!(r.invalid_elements, 0);
            let ho = HighOrderMesh::from_raw(read_raw(&path).unwrap()).unwrap();
            let (_, err) = boundary_error(&ho, &|x| hole(x), &|x| near_hole(x), 16);
            study.errors.entry(mode.into()).or_default().push(Some(err));
            if mode == "smooth" {
                // Largest boundary edge on the hole (order-2 output: vertex nodes at corners).
                let mut h = 0.0f64;
                let npe = ho.nodes_per_element();
                for e in 0..ho.n_elements() {
                    let el = ho.element(e);
                    let corners: Vec<[f64; 3]> = (0..npe)
                        .filter(|&n| lattice_point(2, 2, n).iter().all(|&c| c != 1))
                        .map(|n| ho.nodes[el[n] as usize])
                        .collect();
                    for a in 0..corners.len() {
                        for b in a + 1..corners.len() {
                            let (xa, xb) = (corners[a], corners[b]);
                            if hole(xa) < 1e-9 && hole(xb) < 1e-9 {
                                h = h.max(
                                    ((xa[0] - xb[0]).powi(2) + (xa[1] - xb[1]).powi(2)).sqrt(),
                                );
                            }
                        }
                    }
                }
                study.h.push(h);
            }
        }
    }
    let o = orders(&study.h, &study.errors["smooth"]);
    println!(
        "plate hole: elements {:?}, h {:?}, smooth {:?}, position {:?}, smooth orders {o:?}",
        study.elements, study.h, study.errors["smooth"], study.errors["position"]
    );
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/convergence/unstructured.json");
    if std::env::var("POLYSPLINE_WRITE_REFERENCE").is_ok() {
        let mut all = BTreeMap::new();
        all.insert("plate", &study);
        std::fs::write(&path, serde_json::to_string_pretty(&all).unwrap()).unwrap();
    }
    // Measured: orders 4.2 and 4.0 (errors 4.3e-5, 3.4e-6, 2.1e-7). At level 1 every hole
    // element is Q2 but three; from level 2 on, the frontal mesh is regular enough at the hole
    // for spline elements, and the runs of them that the C¹ spline cannot bend onto the circle
    // are made Q2 after the fit (`pipeline::misfit`), so the hole is within 1.2× Gmsh-with-CAD
    // at every level and converges as its Q2 interpolation does. Asserted: at least order 3.5
    // from each level to the next (third order with a margin), and a clear gain over the
    // chords at every level.
    for (step, order) in o.iter().enumerate() {
        assert!(
            *order >= 3.5,
            "plate hole: smooth converges at order {order:.2} from level {} to {} ({o:?})",
            step + 1,
            step + 2
        );
    }
    for (s, p) in study.errors["smooth"].iter().zip(&study.errors["position"]) {
        let (s, p) = (s.unwrap(), p.unwrap());
        assert!(
            p > 5.0 * s,
            "plate hole: smooth {s:.3e} vs position {p:.3e}"
        );
    }
    let reference: BTreeMap<String, Study> =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let r = &reference["plate"];
    assert_eq!(study.elements, r.elements, "Gmsh made different meshes");
    for (mode, errs) in &study.errors {
        for (level, (g, w)) in errs.iter().zip(&r.errors[mode]).enumerate() {
            let (g, w) = (g.unwrap(), w.unwrap());
            assert!(
                (g / w - 1.0).abs() < 0.2,
                "plate {mode} level {level}: error {g:.3e}, reference {w:.3e}"
            );
        }
    }
}
