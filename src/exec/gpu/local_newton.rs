//! `shaders/local_newton.wgsl`: value, gradient and Hessian of the coloured energy solver's
//! local problems ([`crate::energy::colored::LocalProblem`]) at the current position, one
//! invocation per control point. CPU twin: [`crate::exec::cpu::local_newton`].

use super::{GpuContext, GpuError, ITEM_WORKGROUP, bytes_to_reals, reals_to_bytes};
pub use crate::energy::colored::LocalDerivatives;
use crate::energy::colored::LocalProblem;

/// The uniform block lives beside the CPU twin, which both sides fill the same way.
pub use crate::exec::cpu::local_newton::Params;

pub const SOURCE: &str = include_str!("../../../shaders/local_newton.wgsl");

/// The kernel's inputs in binding order: coefficients (4 per problem), point ranges, points
/// (13 per point).
pub fn pack(problems: &[LocalProblem]) -> (Vec<f64>, Vec<[u32; 2]>, Vec<f64>) {
    let mut coefs = Vec::with_capacity(4 * problems.len());
    let mut ranges = Vec::with_capacity(problems.len());
    let mut points = Vec::new();
    for p in problems {
        coefs.extend([p.kii, p.b[0], p.b[1], p.b[2]]);
        ranges.push([(points.len() / 13) as u32, p.points.len() as u32]);
        for q in &p.points {
            points.push(q.w);
            points.extend(q.m.iter().flatten());
            points.extend(q.psi);
        }
    }
    (coefs, ranges, points)
}

/// Decode the kernel's 13 outputs per problem.
pub fn unpack(out: &[f64]) -> Vec<LocalDerivatives> {
    out.chunks_exact(13)
        .map(|o| LocalDerivatives {
            value: if o[0] < 0.0 { f64::INFINITY } else { o[0] },
            gradient: [o[1], o[2], o[3]],
            hessian: [
                [o[4], o[5], o[6]],
                [o[7], o[8], o[9]],
                [o[10], o[11], o[12]],
            ],
        })
        .collect()
}

/// Run the kernel on `problems` (all of one dimension), in chunks that fit one binding and one
/// dispatch.
pub fn local_newton(
    ctx: &GpuContext,
    dim: usize,
    problems: &[LocalProblem],
) -> Result<Vec<LocalDerivatives>, GpuError> {
    let prec = ctx.precision;
    let sz = prec.size() as u64;
    let per_problem_points = problems
        .iter()
        .map(|p| p.points.len())
        .max()
        .unwrap_or(1)
        .max(1);
    let max_p = ((ctx.max_binding() / (13 * sz * per_problem_points as u64)) as usize)
        .min(ctx.max_workgroups() as usize * ITEM_WORKGROUP)
        .max(1);
    let pipeline = ctx.pipeline(SOURCE, "local_newton");
    let mut out = Vec::with_capacity(problems.len());
    for chunk in problems.chunks(max_p) {
        let n = chunk.len();
        let (coefs, ranges, points) = pack(chunk);
        let params = ctx.uniform(
            "local_newton params",
            &Params {
                dim: dim as u32,
                n_problems: n as u32,
                _pad0: 0,
                _pad1: 0,
            },
        );
        let coef_buf = ctx.storage("coefs", &reals_to_bytes(prec, coefs.into_iter()), false);
        let range_buf = ctx.storage("ranges", bytemuck::cast_slice(&ranges), false);
        // A binding may not be empty.
        let points = if points.is_empty() {
            vec![0.0; 13]
        } else {
            points
        };
        let point_buf = ctx.storage("points", &reals_to_bytes(prec, points.into_iter()), false);
        let out_buf = ctx.storage_zeroed("local derivatives", 13 * sz * n as u64);
        ctx.run_once(
            &pipeline,
            &[
                (0, &params),
                (1, &coef_buf),
                (2, &range_buf),
                (3, &point_buf),
                (4, &out_buf),
            ],
            n,
        );
        let v = bytes_to_reals(prec, &ctx.read_back(&out_buf, 13 * sz * n as u64)?);
        out.extend(unpack(&v));
    }
    Ok(out)
}
