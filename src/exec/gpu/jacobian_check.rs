//! `shaders/jacobian_check.wgsl`: Bernstein coefficients of det J per element → min/max, the
//! first level of the det J certificate. CPU twin: [`crate::exec::cpu::jacobian_check`].
//!
//! The kernel's result is made certified by a forward rounding-error bound
//! ([`rounding_bound`]): an element is certified on the GPU when min coefficient − bound > 0;
//! every other element is finished on the CPU in f64 by [`det_jacobian_bounds`] (subdivision).
//! The line searches call the certifier only for the elements that the CPU screen
//! ([`crate::validity::screen`]) leaves undecided; the kernel computes the exact coefficients.

use super::{
    GpuContext, GpuError, ITEM_WORKGROUP, Precision, anchor, bytes_to_reals, groups, reals_to_bytes,
};
use crate::math::BezierNet;
use crate::validity::{Certifier, DetBounds, det_jacobian_bounds};
use rayon::prelude::*;

/// The uniform block lives beside the CPU twin, which both sides fill the same way.
pub use crate::exec::cpu::jacobian_check::Params;

pub const SOURCE: &str = include_str!("../../../shaders/jacobian_check.wgsl");

/// Roundings along the longest path of one det J coefficient (product weights, three factor
/// products, sums of up to 18·18 terms per component), generously counted: the arithmetic
/// error of a coefficient is at most this many ε times the sum of the magnitudes of its terms.
pub const JACOBIAN_ARITH_ROUNDINGS: f64 = 256.0;
/// Extra factor on the whole bound, for the rounding of the bound's own inputs.
pub const JACOBIAN_SAFETY: f64 = 2.0;

/// What the kernel returns per element.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoefBounds {
    pub min: f64,
    pub min_corner: f64,
    pub max: f64,
    /// Largest |coefficient| of the three partial-derivative factors (the third is 1 in 2D).
    pub factor_max: [f64; 3],
}

/// Bound on |computed − exact| for every det J coefficient of an element, computed at
/// precision `prec` from an element-anchored net whose largest |coordinate| is `xmax`.
///
/// Each factor coefficient 2(P_hi − P_lo) is off by at most δ_f = ε(4·xmax + M_f) (rounding of
/// the anchored input, then of the difference); a coefficient of det J is a sum of T signed
/// triple products (T = 6 in 3D, 2 in 2D) weighted by Bernstein product weights that sum to
/// one, so input rounding moves it by at most T[(Ma+δa)(Mb+δb)(Mc+δc) − Ma·Mb·Mc], and the
/// arithmetic by at most [`JACOBIAN_ARITH_ROUNDINGS`]·ε·T·(Ma+δa)(Mb+δb)(Mc+δc).
pub fn rounding_bound(prec: Precision, dim: usize, factor_max: [f64; 3], xmax: f64) -> f64 {
    let eps = prec.epsilon();
    let [ma, mb, mc] = factor_max;
    let (mc, dc, terms) = if dim == 2 {
        (1.0, 0.0, 2.0)
    } else {
        (mc, eps * (4.0 * xmax + mc), 6.0)
    };
    let (da, db) = (eps * (4.0 * xmax + ma), eps * (4.0 * xmax + mb));
    let big = (ma + da) * (mb + db) * (mc + dc);
    JACOBIAN_SAFETY * terms * ((big - ma * mb * mc) + JACOBIAN_ARITH_ROUNDINGS * eps * big)
}

/// Run the kernel on `elements` (nets from `net`), chunked so nets and outputs fit one
/// binding and one dispatch. Returns the per-element results and each net's largest anchored
/// |coordinate|.
pub fn jacobian_check(
    ctx: &GpuContext,
    dim: usize,
    elements: &[usize],
    net: &(dyn Fn(usize) -> BezierNet + Sync),
) -> Result<Vec<(CoefBounds, f64)>, GpuError> {
    let prec = ctx.precision;
    let sz = prec.size() as u64;
    let max_e = ((ctx.max_binding() / (81 * sz)) as usize)
        .min(ctx.max_workgroups() as usize * ITEM_WORKGROUP)
        .max(1);
    let pipeline = ctx.pipeline(SOURCE, "jacobian_check");
    let mut out = Vec::with_capacity(elements.len());
    for chunk in elements.chunks(max_e) {
        let anchored: Vec<BezierNet> = chunk
            .par_iter()
            .map(|&e| {
                let net = net(e);
                let a = anchor(dim, &net);
                net.map(|p| [p[0] - a[0], p[1] - a[1], p[2] - a[2]])
            })
            .collect();
        let bytes = reals_to_bytes(
            prec,
            anchored.iter().flat_map(|n| n.iter().flatten().copied()),
        );
        let n = chunk.len();
        let params = ctx.uniform(
            "jacobian_check params",
            &Params {
                dim: dim as u32,
                n_elements: n as u32,
                _pad0: 0,
                _pad1: 0,
            },
        );
        let nets_buf = ctx.storage("nets", &bytes, false);
        let out_buf = ctx.storage_zeroed("bounds", 8 * sz * n as u64);
        let bind = ctx.bind(&pipeline, &[(0, &params), (1, &nets_buf), (2, &out_buf)]);
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            ctx.dispatch(&mut pass, &pipeline, &bind, groups(n, ITEM_WORKGROUP));
        }
        ctx.submit(enc);
        let v = bytes_to_reals(prec, &ctx.read_back(&out_buf, 8 * sz * n as u64)?);
        for (i, net) in anchored.iter().enumerate() {
            let b = &v[8 * i..8 * i + 8];
            let xmax = net.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
            out.push((
                CoefBounds {
                    min: b[0],
                    min_corner: b[1],
                    max: b[2],
                    factor_max: [b[4], b[5], b[6]],
                },
                xmax,
            ));
        }
    }
    Ok(out)
}

/// Certified det J bounds: from the GPU's coefficients where they decide (lower bound minus
/// the rounding bound > 0), else from the CPU's f64 subdivision.
pub fn certify(
    ctx: &GpuContext,
    dim: usize,
    elements: &[usize],
    net: &(dyn Fn(usize) -> BezierNet + Sync),
    max_depth: usize,
) -> Result<Vec<DetBounds>, GpuError> {
    let coefs = jacobian_check(ctx, dim, elements, net)?;
    Ok(elements
        .par_iter()
        .zip(coefs.par_iter())
        .map(|(&e, &(c, xmax))| {
            let err = rounding_bound(ctx.precision, dim, c.factor_max, xmax);
            let lower = c.min - err;
            if lower > 0.0 && lower.is_finite() {
                DetBounds {
                    lower,
                    upper: c.min_corner + err,
                }
            } else {
                det_jacobian_bounds(dim, &net(e), max_depth)
            }
        })
        .collect())
}

/// [`Certifier`] on the GPU; falls back to the CPU (and counts it) if the device fails.
pub struct GpuCertifier<'a> {
    pub ctx: &'a GpuContext,
    pub fallbacks: std::sync::atomic::AtomicUsize,
}

impl<'a> GpuCertifier<'a> {
    pub fn new(ctx: &'a GpuContext) -> Self {
        GpuCertifier {
            ctx,
            fallbacks: Default::default(),
        }
    }
}

impl Certifier for GpuCertifier<'_> {
    fn certify(
        &self,
        dim: usize,
        elements: &[usize],
        net: &(dyn Fn(usize) -> BezierNet + Sync),
        max_depth: usize,
    ) -> Vec<DetBounds> {
        match certify(self.ctx, dim, elements, net, max_depth) {
            Ok(b) => b,
            Err(_) => {
                self.fallbacks
                    .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                crate::validity::CpuCertifier.certify(dim, elements, net, max_depth)
            }
        }
    }
}
