//! The validity check against closed-form Jacobians. Each element here is the Lagrange
//! interpolant of a polynomial map of degree ≤ 2 per direction, which an element of order ≥ 2
//! reproduces exactly, so its det J is known in closed form everywhere:
//!
//! - the bulge `(x0 + l u, h v (1 − a u (1 − u)))`, det J = l h (1 − a u (1 − u)): valid for
//!   a < 4, inverted around u = ½ for a > 4 (its middle nodes are mirrored; its corners are not);
//! - the mirrored square `(x0 + l (1 − u), h v)`, det J = −l h;
//! - in 3D, `(x0 + l u, h v (1 − a u (1 − u)), t w (1 + b v (1 − v)))`, whose Jacobian is
//!   triangular: det J = l h t (1 − a u (1 − u)) (1 + b v (1 − v)).
//!
//! The sampled check (`quality::sample_det_jacobian`, the `check` command and its exit
//! status), the certified bounds (`validity::lagrange_element_bounds`) and Gmsh's own
//! Jacobians of the written file (`tests/external/gmsh_probe.py`, signed in 2D) must all agree
//! with the closed form.

use crate::common;
use polyspline::mesh::HighOrderMesh;
use polyspline::mesh::high_order::lattice_point;
use polyspline::quality::sample_det_jacobian;
use polyspline::validity::lagrange_element_bounds;
use serde_json::{Value, json};
use std::path::Path;

/// A closed-form element: its map on [0,1]^d and its exact det J.
struct Closed {
    map: Box<dyn Fn([f64; 3]) -> [f64; 3]>,
    det: Box<dyn Fn([f64; 3]) -> f64>,
}

fn bulge(a: f64, l: f64, h: f64, x0: f64) -> Closed {
    Closed {
        map: Box::new(move |[u, v, _]| [x0 + l * u, h * v * (1.0 - a * u * (1.0 - u)), 0.0]),
        det: Box::new(move |[u, _, _]| l * h * (1.0 - a * u * (1.0 - u))),
    }
}

fn mirrored(l: f64, h: f64, x0: f64) -> Closed {
    Closed {
        map: Box::new(move |[u, v, _]| [x0 + l * (1.0 - u), h * v, 0.0]),
        det: Box::new(move |_| -l * h),
    }
}

fn bulge_3d(a: f64, b: f64, [l, h, t]: [f64; 3], x0: f64) -> Closed {
    Closed {
        map: Box::new(move |[u, v, w]| {
            [
                x0 + l * u,
                h * v * (1.0 - a * u * (1.0 - u)),
                t * w * (1.0 + b * v * (1.0 - v)),
            ]
        }),
        det: Box::new(move |[u, v, _]| {
            l * h * t * (1.0 - a * u * (1.0 - u)) * (1.0 + b * v * (1.0 - v))
        }),
    }
}

/// The order-`p` mesh of the elements `els` (each its own nodes, lattice order).
fn mesh_of(dim: usize, p: usize, els: &[Closed]) -> HighOrderMesh {
    let n = (p + 1).pow(dim as u32);
    let mut ho = HighOrderMesh {
        dim,
        order: p,
        ..Default::default()
    };
    for el in els {
        for k in 0..n {
            let l = lattice_point(p, dim, k);
            let t = [0, 1, 2].map(|c| l[c] as f64 / p as f64);
            ho.elements.push(ho.nodes.len() as u32);
            ho.nodes.push((el.map)(t));
        }
    }
    ho
}

/// The exact min det J of `el`: the closed form on the grid of step 1/100, which holds every
/// minimiser of these maps (u, v ∈ {0, ½, 1}).
fn exact_min(dim: usize, el: &Closed) -> f64 {
    let n = 100;
    let mut min = f64::INFINITY;
    for k in 0..=if dim == 3 { n } else { 0 } {
        for j in 0..=n {
            for i in 0..=n {
                let t = [i, j, k].map(|c| c as f64 / n as f64);
                min = min.min((el.det)(t));
            }
        }
    }
    min
}

/// `polyspline check --json FILE`: its exit status and report.
fn check_cli(file: &Path) -> (Option<i32>, Value) {
    let out = common::polyspline()
        .args(["check", "--json"])
        .arg(file)
        .output()
        .unwrap();
    let report = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "{e}: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (out.status.code(), report)
}

fn close(got: f64, want: f64, scale: f64) -> bool {
    (got - want).abs() <= 1e-12 * scale.max(1.0)
}

#[test]
fn check_exits_3_on_inverted_elements_and_0_on_valid_ones() {
    let dir = common::test_dir();
    // Valid, inverted inside (corners fine: a corner-based check passes it), mirrored.
    let els = [
        bulge(2.0, 1.0, 1.0, 0.0),
        bulge(8.0, 1.0, 2.0, 3.0),
        mirrored(1.0, 0.5, 6.0),
    ];
    let bad = dir.join("inverted.msh");
    polyspline::pipeline::write_high_order(&mesh_of(2, 2, &els), &bad, &Default::default(), &[])
        .unwrap();
    let (status, r) = check_cli(&bad);
    assert_eq!(status, Some(3), "{r}");
    assert_eq!(r["invalid"], 2, "{r}");
    // The inverted bulge: 1·2·(1 − 8/4) = −2 at u = ½.
    let min = r["min_det_jacobian"].as_f64().unwrap();
    assert!(close(min, -2.0, 2.0), "{r}");
    // The table form gates the same way.
    let out = common::polyspline()
        .arg("check")
        .arg(&bad)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stdout).contains("invalid elements      2"));

    let good = dir.join("valid.msh");
    let els = [bulge(2.0, 1.0, 1.0, 0.0), bulge(3.5, 2.0, 1.0, 3.0)];
    polyspline::pipeline::write_high_order(&mesh_of(2, 2, &els), &good, &Default::default(), &[])
        .unwrap();
    let (status, r) = check_cli(&good);
    assert_eq!(status, Some(0), "{r}");
    assert_eq!(r["invalid"], 0, "{r}");
    // min(1·1·(1 − 2/4), 2·1·(1 − 3.5/4)) = 0.25.
    assert!(
        close(r["min_det_jacobian"].as_f64().unwrap(), 0.25, 1.0),
        "{r}"
    );

    // 3D: one hex inverted inside.
    let els = [
        bulge_3d(1.0, 0.5, [1.0, 1.0, 1.0], 0.0),
        bulge_3d(6.0, 0.5, [1.0, 1.0, 1.0], 2.0),
    ];
    let hex = dir.join("inverted_hex.msh");
    polyspline::pipeline::write_high_order(&mesh_of(3, 2, &els), &hex, &Default::default(), &[])
        .unwrap();
    let (status, r) = check_cli(&hex);
    assert_eq!(status, Some(3), "{r}");
    assert_eq!(r["invalid"], 1, "{r}");
}

#[test]
fn sampled_and_certified_det_j_match_the_closed_form() {
    for p in [2, 3] {
        let cases: [(usize, Vec<Closed>); 2] = [
            (
                2,
                vec![
                    bulge(0.0, 2.0, 0.5, 0.0),
                    bulge(3.0, 1.0, 1.5, 3.0),
                    bulge(6.0, 1.0, 1.0, 6.0),
                    mirrored(0.5, 0.25, 9.0),
                ],
            ),
            (
                3,
                vec![
                    bulge_3d(2.0, 1.0, [1.0, 2.0, 0.5], 0.0),
                    bulge_3d(5.0, 2.0, [1.0, 1.0, 1.0], 3.0),
                ],
            ),
        ];
        for (dim, els) in &cases {
            let ho = mesh_of(*dim, p, els);
            let q = sample_det_jacobian(&ho);
            for (e, el) in els.iter().enumerate() {
                let want = exact_min(*dim, el);
                let ctx = format!("{dim}D order {p} element {e}: exact min det J {want}");
                // Every minimiser is on the sampling lattice of order 2p.
                assert!(
                    close(q[e].min_det_jacobian, want, want.abs()),
                    "{ctx}, sampled {}",
                    q[e].min_det_jacobian
                );
                // The certificate brackets the exact minimum; it certifies the valid elements
                // and proves the others invalid (upper, a value of det J, is ≤ 0).
                let b = lagrange_element_bounds(&ho, e, 12);
                let tol = 1e-9 * want.abs().max(1.0);
                assert!(
                    b.lower <= want + tol && want <= b.upper + tol,
                    "{ctx}, {b:?}"
                );
                assert_eq!(b.certified_positive(), want > 0.0, "{ctx}, {b:?}");
                assert_eq!(b.upper <= 0.0, want <= 0.0, "{ctx}, {b:?}");
                assert_eq!(q[e].min_det_jacobian > 0.0, want > 0.0, "{ctx}");
            }
            if *dim == 2 {
                // Scaled Jacobian of the bulge: sign(f) l / |(l, h v a (2u − 1))|, smallest at
                // v = 1, u ∈ {0, 1} when valid, −1 along u = ½ when inverted; −1 when mirrored.
                let sj = |a: f64, l: f64, h: f64| l / l.hypot(h * a);
                let want = [sj(0.0, 2.0, 0.5), sj(3.0, 1.0, 1.5), -1.0, -1.0];
                for (e, w) in want.iter().enumerate() {
                    assert!(
                        close(q[e].min_scaled_jacobian, *w, 1.0),
                        "order {p} element {e}: scaled Jacobian {} vs {w}",
                        q[e].min_scaled_jacobian
                    );
                }
            }
        }
    }
}

#[test]
fn gmsh_signed_det_j_of_our_files_matches_the_closed_form() {
    let dir = common::test_dir();
    // Gmsh's reference element is [-1,1]^d: its det J is ours (on [0,1]^d) over 2^d.
    let points = [
        [0.5, 0.3, 0.7],
        [0.1, 0.9, 0.2],
        [0.77, 0.2, 0.5],
        [0.0, 1.0, 1.0],
    ];
    let cases: [(usize, usize, Vec<Closed>); 3] = [
        (
            2,
            2,
            vec![
                bulge(3.0, 1.0, 1.5, 0.0),
                bulge(8.0, 1.0, 1.0, 3.0),
                mirrored(1.0, 0.5, 6.0),
            ],
        ),
        (
            2,
            4,
            vec![bulge(2.0, 2.0, 1.0, 0.0), mirrored(0.5, 0.5, 3.0)],
        ),
        (
            3,
            2,
            vec![
                bulge_3d(2.0, 1.0, [1.0, 2.0, 0.5], 0.0),
                bulge_3d(6.0, 2.0, [1.0, 1.0, 1.0], 3.0),
            ],
        ),
    ];
    let mut jobs = Vec::new();
    for (k, (dim, p, els)) in cases.iter().enumerate() {
        let file = dir.join(format!("case{k}.msh"));
        polyspline::pipeline::write_high_order(
            &mesh_of(*dim, *p, els),
            &file,
            &Default::default(),
            &[],
        )
        .unwrap();
        let det_at: Vec<Value> = (0..els.len())
            .flat_map(|e| points.iter().map(move |t| json!([e, t[0], t[1], t[2]])))
            .collect();
        jobs.push(json!({ "file": file, "probes": [], "det_at": det_at }));
    }
    let Some(res) = common::gmsh_probe(&jobs, &dir.join("jobs.json")) else {
        return;
    };
    for (k, (dim, p, els)) in cases.iter().enumerate() {
        let scale = (1u32 << dim) as f64;
        let dets = res[k]["dets"].as_array().unwrap();
        let mut i = 0;
        for (e, el) in els.iter().enumerate() {
            for t in &points {
                let t = if *dim == 2 { [t[0], t[1], 0.0] } else { *t };
                let got = dets[i].as_f64().unwrap() * scale;
                let want = (el.det)(t);
                assert!(
                    (got - want).abs() <= 1e-9 * want.abs().max(1.0),
                    "{dim}D order {p} element {e} at {t:?}: Gmsh's det J {got}, closed form {want}"
                );
                i += 1;
            }
        }
        // Each case holds an inverted or mirrored element: Gmsh's smallest det J is negative.
        let lo = res[k]["min_det_jac"].as_f64().unwrap();
        assert!(lo < 0.0, "{dim}D order {p}: Gmsh's min det J {lo}");
    }
}
