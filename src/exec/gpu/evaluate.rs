//! `shaders/evaluate.wgsl`: Bézier nets → points and parametric derivatives at parameters,
//! and the GPU sampling stage built on it. CPU twin: [`crate::exec::cpu::evaluate`].

use super::{GpuContext, GpuError, ITEM_WORKGROUP, anchor, bytes_to_reals, groups, reals_to_bytes};
use crate::math::{BezierElements, BezierNet};
use crate::mesh::HighOrderMesh;
use crate::mesh::high_order::{Lattice, lattice_index, lattice_point};
use crate::mesh::{LinearMesh, Topology};
use crate::sample::sample_with;
use rayon::prelude::*;

/// The uniform block lives beside the CPU twin, which both sides fill the same way.
pub use crate::exec::cpu::evaluate::Params;

pub const SOURCE: &str = include_str!("../../../shaders/evaluate.wgsl");

/// Points (and derivatives d/du, d/dv, d/dw when asked for) per query, in f64.
#[derive(Clone, Debug, Default)]
pub struct Evaluation {
    pub points: Vec<[f64; 3]>,
    pub derivs: Vec<[[f64; 3]; 3]>,
}

/// Agreement of f32 evaluation with the f64 reference, relative to the element's size (the
/// largest distance of a control point from the element anchor): the 27 Bernstein weights are
/// non-negative and sum to one, so the result has ≈ 27·2 roundings of quantities bounded by
/// that size, plus the rounding of the anchored input. Derivatives carry a factor 4 more
/// (weights up to 2 in magnitude, differences). Adding the anchor back (in f64) rounds once
/// more, by ε₆₄ relative to the coordinates.
pub const EVALUATE_TOL_F32: f64 = 64.0 * f32::EPSILON as f64;
/// The same for f64 kernels.
pub const EVALUATE_TOL_F64: f64 = 64.0 * f64::EPSILON;

/// Evaluate element nets at parameters. `queries` are (element, index into `xi`), in any
/// order; they are grouped by element and split into chunks whose nets, queries and outputs
/// each fit one storage binding and one dispatch.
pub fn evaluate(
    ctx: &GpuContext,
    dim: usize,
    nets: &(dyn Fn(usize) -> BezierNet + Sync),
    xi: &[[f64; 3]],
    queries: &[(u32, u32)],
    with_derivs: bool,
) -> Result<Evaluation, GpuError> {
    let prec = ctx.precision;
    let sz = prec.size() as u64;
    let max_q = ((ctx.max_binding() / (9 * sz)) as usize)
        .min(ctx.max_workgroups() as usize * ITEM_WORKGROUP)
        .max(1);
    let max_e = ((ctx.max_binding() / (81 * sz)) as usize).max(1);
    let mut order: Vec<u32> = (0..queries.len() as u32).collect();
    order.par_sort_by_key(|&q| queries[q as usize]);
    let pipeline = ctx.pipeline(SOURCE, "evaluate");
    let xi_buf = ctx.storage(
        "xi",
        &reals_to_bytes(prec, xi.iter().flat_map(|t| [t[0], t[1], t[2], 0.0])),
        false,
    );
    let mut out = Evaluation {
        points: vec![[0.0; 3]; queries.len()],
        derivs: if with_derivs {
            vec![[[0.0; 3]; 3]; queries.len()]
        } else {
            Vec::new()
        },
    };
    let mut start = 0;
    while start < order.len() {
        // Extend the chunk while it has room for the queries and distinct elements.
        let mut end = start;
        let mut elems: Vec<u32> = Vec::new();
        while end < order.len() && end - start < max_q {
            let e = queries[order[end] as usize].0;
            if elems.last() != Some(&e) {
                if elems.len() == max_e {
                    break;
                }
                elems.push(e);
            }
            end += 1;
        }
        let chunk = &order[start..end];
        let local_nets: Vec<([f64; 3], BezierNet)> = elems
            .par_iter()
            .map(|&e| {
                let net = nets(e as usize);
                (anchor(dim, &net), net)
            })
            .collect();
        let net_bytes = reals_to_bytes(
            prec,
            local_nets.iter().flat_map(|(a, net)| {
                net.iter()
                    .flat_map(move |p| (0..3).map(move |k| p[k] - a[k]))
            }),
        );
        // Local element index of every query of the chunk.
        let mut local = Vec::with_capacity(chunk.len());
        let mut li = 0u32;
        for &q in chunk {
            let (e, t) = queries[q as usize];
            while elems[li as usize] != e {
                li += 1;
            }
            local.push([li, t]);
        }
        let n = chunk.len();
        let params = ctx.uniform(
            "evaluate params",
            &Params {
                dim: dim as u32,
                n_queries: n as u32,
                with_derivs: with_derivs as u32,
                _pad: 0,
            },
        );
        let nets_buf = ctx.storage("nets", &net_bytes, false);
        let q_buf = ctx.storage("queries", bytemuck::cast_slice(&local), false);
        let p_buf = ctx.storage_zeroed("points", 3 * sz * n as u64);
        let d_buf = ctx.storage_zeroed("derivs", if with_derivs { 9 * sz * n as u64 } else { 16 });
        let bind = ctx.bind(
            &pipeline,
            &[
                (0, &params),
                (1, &nets_buf),
                (2, &xi_buf),
                (3, &q_buf),
                (4, &p_buf),
                (5, &d_buf),
            ],
        );
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            ctx.dispatch(&mut pass, &pipeline, &bind, groups(n, ITEM_WORKGROUP));
        }
        ctx.submit(enc);
        let pts = bytes_to_reals(prec, &ctx.read_back(&p_buf, 3 * sz * n as u64)?);
        let ders = if with_derivs {
            bytes_to_reals(prec, &ctx.read_back(&d_buf, 9 * sz * n as u64)?)
        } else {
            Vec::new()
        };
        for (i, &q) in chunk.iter().enumerate() {
            let a = local_nets[local[i][0] as usize].0;
            out.points[q as usize] = std::array::from_fn(|k| a[k] + pts[3 * i + k]);
            if with_derivs {
                out.derivs[q as usize] =
                    std::array::from_fn(|j| std::array::from_fn(|k| ders[9 * i + 3 * j + k]));
            }
        }
        start = end;
    }
    Ok(out)
}

/// The equispaced parameters i/p of an order-p lattice, in lattice order.
pub fn lattice_params(dim: usize, p: usize) -> Vec<[f64; 3]> {
    let pf = p as f64;
    (0..(p + 1).pow(dim as u32))
        .map(|n| {
            let l = lattice_point(p, dim, n);
            [l[0] as f64 / pf, l[1] as f64 / pf, l[2] as f64 / pf]
        })
        .collect()
}

/// [`crate::sample::sample`] on the GPU: the same numbering, node positions from the
/// `evaluate` kernel at the lattice parameters.
pub fn sample(
    ctx: &GpuContext,
    source: &dyn BezierElements,
    mesh: &LinearMesh,
    topo: &Topology,
    p: usize,
) -> Result<HighOrderMesh, GpuError> {
    assert_eq!(source.n_elements(), mesh.n_elements());
    let (mut ho, queries) = sample_with(
        mesh,
        topo,
        p,
        |e, lattice: &[Lattice], out: &mut [(u32, u32)]| {
            for (l, q) in lattice.iter().zip(out) {
                *q = (e as u32, lattice_index(p, *l) as u32);
            }
        },
    );
    let xi = lattice_params(mesh.dim, p);
    ho.nodes = evaluate(
        ctx,
        mesh.dim,
        &|e| source.bezier_net(e),
        &xi,
        &queries,
        false,
    )?
    .points;
    Ok(ho)
}
