//! Topology construction on structured and irregular synthetic meshes, 10k to 1M elements.
//!
//! `cargo bench --bench topology` measures; `cargo test --benches` runs each case once so the
//! benchmark cannot rot.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use polyspline::mesh::Topology;
use polyspline::mesh::generate::{extrude, grid_3d, star_2d, uniform};
use std::hint::black_box;

fn topology(c: &mut Criterion) {
    let mut group = c.benchmark_group("topology");
    group.sample_size(10);
    for n in [22usize, 47, 100] {
        // n^3 hexes: 10.6k, 104k, 1M.
        let mesh = grid_3d(&uniform(n, 1.0), &uniform(n, 1.0), &uniform(n, 1.0));
        group.throughput(Throughput::Elements(mesh.n_elements() as u64));
        group.bench_with_input(
            BenchmarkId::new("hex_grid", mesh.n_elements()),
            &mesh,
            |b, m| b.iter(|| black_box(Topology::build(m))),
        );
    }
    // An irregular mesh: a valence-5 star extruded (edges of valence 3, 4 and 5).
    let mesh = extrude(&star_2d(5), &uniform(2000, 0.01));
    group.throughput(Throughput::Elements(mesh.n_elements() as u64));
    group.bench_with_input(
        BenchmarkId::new("star5_extruded", mesh.n_elements()),
        &mesh,
        |b, m| b.iter(|| black_box(Topology::build(m))),
    );
    group.finish();
}

criterion_group!(benches, topology);
criterion_main!(benches);
