//! The fit's normal equations: assembling K and the right-hand side (K row by row into CSR,
//! see `polyspline::fit::assembly`) against applying K matrix-free through the Bézier
//! extraction, per apply and per CG solve, on 3D grids with a curved (cylindrical) boundary;
//! and block-Jacobi CG against the sparse Cholesky of `solve::direct` on the smooth preset's
//! matrix of real 2D meshes (the systems `FitSolver::Auto` factors). `cargo bench --bench
//! fit`; `cargo test --benches` runs each case once.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use polyspline::fit::{FitWeights, MatrixFree, assemble};
use polyspline::mesh::generate::{grid_3d, uniform};
use polyspline::mesh::{LinearMesh, Topology};
use polyspline::solve::{CgParams, LinOp, direct, pcg};
use polyspline::spline::SplineSpace;
use std::hint::black_box;

/// An n×n×n block bent into a quarter of a thick cylinder (curved boundaries, regular topology).
fn bent_block(n: usize) -> LinearMesh {
    let mut m = grid_3d(
        &uniform(n, 1.0 / n as f64),
        &uniform(n, 1.0 / n as f64),
        &uniform(n, 1.0 / n as f64),
    );
    for p in m.coords.iter_mut() {
        let (r, t) = (1.0 + p[0], p[1] * std::f64::consts::FRAC_PI_2);
        *p = [r * t.cos(), r * t.sin(), p[2]];
    }
    m
}

fn fit(c: &mut Criterion) {
    let mut group = c.benchmark_group("fit");
    group.sample_size(10);
    for n in [20usize, 40] {
        let m = bent_block(n);
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let w = FitWeights::position();
        let ne = m.n_elements();
        group.throughput(Throughput::Elements(ne as u64));
        group.bench_with_input(BenchmarkId::new("assemble", ne), &ne, |b, _| {
            b.iter(|| black_box(assemble(&s, &m, &t, &w)))
        });
        let (k, rhs) = assemble(&s, &m, &t, &w);
        let mf = MatrixFree::new(&s, &m, &t, &w);
        let x: Vec<[f64; 3]> = (0..k.n()).map(|i| [i as f64, 1.0, 0.5]).collect();
        let mut y = vec![[0.0; 3]; k.n()];
        group.bench_with_input(BenchmarkId::new("apply_assembled", ne), &ne, |b, _| {
            b.iter(|| k.apply(&x, &mut y))
        });
        group.bench_with_input(BenchmarkId::new("apply_matrix_free", ne), &ne, |b, _| {
            b.iter(|| mf.apply(&x, &mut y))
        });
        group.bench_with_input(BenchmarkId::new("cg_assembled", ne), &ne, |b, _| {
            b.iter(|| {
                let mut d = vec![[0.0; 3]; k.n()];
                black_box(pcg(&k, &rhs, &mut d, &CgParams::default(), |_, _| {}).unwrap())
            })
        });
    }
    group.finish();
}

/// Block-Jacobi CG to 1e-6 against sparse Cholesky on the 2D real meshes' smooth-preset
/// matrices (unstructured: 45-85 CG iterations).
fn solver_2d(c: &mut Criterion) {
    let mut group = c.benchmark_group("fit_solver_2d");
    group.sample_size(10);
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes/real/dealii");
    for name in [
        "unstructured_refined_ball.msh",
        "example.msh",
        "hole8170.msh",
    ] {
        let m = polyspline::io::read_mesh(&root.join(name), &Default::default()).unwrap();
        let t = Topology::build(&m);
        let s = SplineSpace::build(&m, &t);
        let (k, rhs) = assemble(&s, &m, &t, &FitWeights::smooth());
        let n = k.n();
        group.bench_with_input(BenchmarkId::new("cg_block_jacobi", n), &n, |b, _| {
            b.iter(|| {
                let mut d = vec![[0.0; 3]; n];
                black_box(pcg(&k, &rhs, &mut d, &CgParams::default(), |_, _| {}).unwrap())
            })
        });
        group.bench_with_input(BenchmarkId::new("cholesky", n), &n, |b, _| {
            b.iter(|| {
                let mut d = vec![[0.0; 3]; n];
                let (p, i, v) = (k.indptr(), k.indices(), k.data());
                black_box(direct::cholesky(p, i, v, &rhs, &mut d, 2).unwrap())
            })
        });
    }
    group.finish();
}

criterion_group!(benches, fit, solver_2d);
criterion_main!(benches);
