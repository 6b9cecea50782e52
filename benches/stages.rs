//! Every stage of `curve` on generated thick-walled cylinders (`polyspline generate cylinder`:
//! O-grid hexes with valence-3 lines, curved boundaries), reported in elements per second:
//! read (MSH 4.1 binary), topology, spline space, fit assembly (K and right-hand side), CG
//! (block Jacobi, the same preconditioner through the generic PCG, and point Jacobi),
//! certificate (Bernstein det J bounds; `certificate_screened` with the cheap screen first, as
//! the line searches run it), sampling at order 2 and writing (MSH 4.1 ASCII).
//!
//! `cargo bench --bench stages` runs 10k, 100k and 1M elements (`POLYSPLINE_BENCH_SIZES=
//! 10000,100000` to choose); `cargo test --benches` (CI) runs every stage once on 2k elements,
//! so the benchmark cannot rot.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use polyspline::fit::{FitSpace, FitWeights, assemble};
use polyspline::io::read_mesh;
use polyspline::mesh::generate::{Kind, generate};
use polyspline::mesh::{MeshOptions, Topology};
use polyspline::pipeline::{OutputOptions, write_high_order};
use polyspline::sample::sample;
use polyspline::solve::{CgParams, CgPreconditioner, pcg, pcg_with, preconditioner};
use polyspline::spline::SplineSpace;
use polyspline::validity::{CpuCertifier, certify_elements, certify_screened};
use std::hint::black_box;

/// Element counts: quick under `cargo test --benches` (no `--bench` argument).
fn sizes() -> Vec<usize> {
    if let Ok(s) = std::env::var("POLYSPLINE_BENCH_SIZES") {
        return s
            .split(',')
            .map(|x| x.trim().parse().expect("a size"))
            .collect();
    }
    if std::env::args().any(|a| a == "--bench") {
        vec![10_000, 100_000, 1_000_000]
    } else {
        vec![2_000]
    }
}

fn stages(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("polyspline-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut group = c.benchmark_group("stages");
    group.sample_size(10);
    for target in sizes() {
        let mesh = generate(Kind::Cylinder, target);
        let ne = mesh.n_elements();
        group.throughput(Throughput::Elements(ne as u64));
        let topo = Topology::build(&mesh);
        let input = dir.join(format!("cyl{ne}.msh"));
        let linear = sample(&mesh, &mesh, &topo, 1);
        let binary = OutputOptions {
            binary: true,
            ..Default::default()
        };
        write_high_order(&linear, &input, &binary, &[]).unwrap();
        drop(linear);
        let id = |name: &str| BenchmarkId::new(name, ne);
        group.bench_function(id("read"), |b| {
            b.iter(|| black_box(read_mesh(&input, &MeshOptions::default()).unwrap()))
        });
        group.bench_function(id("topology"), |b| {
            b.iter(|| black_box(Topology::build(&mesh)))
        });
        group.bench_function(id("spline_space"), |b| {
            b.iter(|| black_box(SplineSpace::build(&mesh, &topo)))
        });
        let space = SplineSpace::build(&mesh, &topo);
        // The default fit's weights (`--fit smooth`): their 0.05 interior midpoints make the
        // system the CG stages meet in `curve`, which the position preset's would not.
        let w = FitWeights::smooth();
        group.bench_function(id("assembly"), |b| {
            b.iter(|| black_box(assemble(&space, &mesh, &topo, &w)))
        });
        let (k, rhs) = assemble(&space, &mesh, &topo, &w);
        for (name, pre) in [
            ("cg_block_jacobi", CgPreconditioner::default()),
            ("cg_jacobi", CgPreconditioner::Jacobi),
            (
                "cg_block_sgs",
                CgPreconditioner::BlockSgs {
                    size: polyspline::solve::block_jacobi::DEFAULT_BLOCK,
                },
            ),
            (
                "cg_block_jacobi_pair",
                CgPreconditioner::BlockJacobiPair {
                    size: polyspline::solve::block_jacobi::DEFAULT_BLOCK,
                },
            ),
        ] {
            let params = CgParams {
                preconditioner: pre,
                ..Default::default()
            };
            group.bench_function(id(name), |b| {
                b.iter(|| {
                    let mut x = vec![[0.0; 3]; k.n()];
                    black_box(pcg(&k, &rhs, &mut x, &params, |_, _| {}).unwrap())
                })
            });
        }
        // The generic PCG with the same block-Jacobi preconditioner (CSR product, separate
        // vector passes): the baseline of the reordered template solver above.
        group.bench_function(id("cg_block_jacobi_generic"), |b| {
            let params = CgParams::default();
            b.iter(|| {
                let mut x = vec![[0.0; 3]; k.n()];
                let pre = preconditioner(&k, &params).unwrap();
                black_box(pcg_with(&k, pre.as_ref(), &rhs, &mut x, &params, |_, _| {}).unwrap())
            })
        });
        let mut delta = vec![[0.0; 3]; k.n()];
        pcg(&k, &rhs, &mut delta, &CgParams::default(), |_, _| {}).unwrap();
        drop(k);
        let mut fitted = space.clone();
        for (c, d) in fitted.control_points.iter_mut().zip(&delta) {
            for i in 0..3 {
                c[i] += d[i];
            }
        }
        group.bench_function(id("certificate"), |b| {
            b.iter(|| {
                black_box(certify_elements(
                    space.dim(),
                    ne,
                    |e| fitted.element_bezier(e),
                    6,
                ))
            })
        });
        group.bench_function(id("certificate_screened"), |b| {
            let all: Vec<usize> = (0..ne).collect();
            b.iter(|| {
                black_box(certify_screened(
                    &CpuCertifier,
                    space.dim(),
                    &all,
                    &|e| fitted.element_bezier(e),
                    6,
                    &|_| 0.0,
                ))
            })
        });
        group.bench_function(id("sample_p2"), |b| {
            b.iter(|| black_box(sample(&fitted, &mesh, &topo, 2)))
        });
        let curved = sample(&fitted, &mesh, &topo, 2);
        let output = dir.join(format!("cyl{ne}_p2.msh"));
        group.bench_function(id("write_msh_ascii"), |b| {
            b.iter(|| write_high_order(&curved, &output, &OutputOptions::default(), &[]).unwrap())
        });
        std::fs::remove_file(&input).ok();
        std::fs::remove_file(&output).ok();
    }
    group.finish();
    std::fs::remove_dir_all(&dir).ok();
}

criterion_group!(benches, stages);
criterion_main!(benches);
