//! Construction and evaluation of the poly-spline space on generated meshes.

use criterion::{Criterion, criterion_group, criterion_main};
use polyspline::mesh::Topology;
use polyspline::mesh::generate::{extrude, grid_2d, grid_3d, star_2d, uniform};
use polyspline::spline::SplineSpace;
use std::hint::black_box;

fn build(c: &mut Criterion) {
    let cases = [
        (
            "grid_2d_200x200",
            grid_2d(&uniform(200, 1.0), &uniform(200, 1.0)),
        ),
        (
            "grid_3d_30x30x30",
            grid_3d(&uniform(30, 1.0), &uniform(30, 1.0), &uniform(30, 1.0)),
        ),
        (
            "grid_3d_100x100x100",
            grid_3d(&uniform(100, 1.0), &uniform(100, 1.0), &uniform(100, 1.0)),
        ),
        (
            "extruded_star5_x10",
            extrude(&star_2d(5), &uniform(10, 0.1)),
        ),
    ];
    let mut group = c.benchmark_group("spline_build");
    group.sample_size(10);
    for (name, mesh) in &cases {
        let topo = Topology::build(mesh);
        group.bench_function(*name, |b| {
            b.iter(|| black_box(SplineSpace::build(black_box(mesh), black_box(&topo))))
        });
    }
    group.finish();
}

fn evaluate(c: &mut Criterion) {
    let mesh = grid_3d(&uniform(20, 1.0), &uniform(20, 1.0), &uniform(20, 1.0));
    let topo = Topology::build(&mesh);
    let space = SplineSpace::build(&mesh, &topo);
    c.bench_function("spline_bezier_nets_20x20x20", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for e in 0..space.n_elements() {
                acc += space.element_bezier(e)[13][0];
            }
            black_box(acc)
        })
    });
}

criterion_group!(benches, build, evaluate);
criterion_main!(benches);
