//! CPU twin of `shaders/assemble.wgsl`: the fit's normal matrix summed row by row from the
//! element matrices (`fit::assembly::RowSums`), for a block of rows.

use super::Real;

/// Uniform block of `assemble.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AssembleParams {
    pub n_rows: u32,
    pub row_base: u32,
    pub local_bits: u32,
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<AssembleParams>() == 16);

/// The arrays `assemble.wgsl` reads, in its binding order (1–8).
pub struct AssembleInputs<'a, T> {
    pub indptr: &'a [u32],
    pub indices: &'a [u32],
    pub inc_start: &'a [u32],
    pub incidence: &'a [u32],
    pub elements: &'a [[u32; 2]],
    pub elem_cols: &'a [u32],
    pub mats: &'a [T],
    pub scale: &'a [T],
}

/// One invocation per row `r` of the block: zero the row, add row i of each incident
/// element's matrix at its columns' positions (found by bisection in the sorted row), in
/// element order, then scale by d_r d_j.
pub fn assemble<T: Real>(params: &AssembleParams, a: &AssembleInputs<'_, T>, data: &mut [T]) {
    let mask = (1u32 << params.local_bits) - 1;
    for r in 0..params.n_rows as usize {
        let (lo, hi) = (a.indptr[r] as usize, a.indptr[r + 1] as usize);
        for v in &mut data[lo..hi] {
            *v = T::of(0.0);
        }
        for t in a.inc_start[r] as usize..a.inc_start[r + 1] as usize {
            let packed = a.incidence[t];
            let (e, i) = ((packed >> params.local_bits) as usize, packed & mask);
            let first = a.elements[e][0];
            let m = a.elements[e + 1][0] - first;
            let row = (a.elements[e][1] + i * m) as usize;
            for j in 0..m {
                let col = a.elem_cols[(first + j) as usize];
                let (mut lo_, mut hi_) = (lo, hi);
                while lo_ < hi_ {
                    let mid = (lo_ + hi_) / 2;
                    if a.indices[mid] < col {
                        lo_ = mid + 1;
                    } else {
                        hi_ = mid;
                    }
                }
                data[lo_] += a.mats[row + j as usize];
            }
        }
        let dr = a.scale[params.row_base as usize + r];
        for k in lo..hi {
            data[k] = data[k] * (dr * a.scale[a.indices[k] as usize]);
        }
    }
}

/// The twin over every row of an unsummed matrix as one block
/// ([`crate::fit::NormalMatrix::unsummed`]), with every element-matrix entry and scale factor
/// passed through `f` first (the identity for K; `f64::abs` gives each entry's sum of term
/// magnitudes, for rounding bounds). `None` for a matrix whose values are summed.
pub fn assemble_all<T: Real>(
    k: &crate::fit::NormalMatrix,
    f: impl Fn(f64) -> f64,
) -> Option<Vec<T>> {
    let (sums, scale) = k.unsummed()?;
    let n = k.n();
    let tables = sums.tables().expect("32-bit indices");
    let (inc_start, incidence) = sums.incidence(0..n, tables.local_bits);
    let indptr: Vec<u32> = k.indptr().iter().map(|&o| o as u32).collect();
    let mats: Vec<T> = tables.mats.iter().map(|&v| T::of(f(v))).collect();
    let scale: Vec<T> = (0..n)
        .map(|r| T::of(f(scale.map_or(1.0, |d| d[r]))))
        .collect();
    let inputs = AssembleInputs {
        indptr: &indptr,
        indices: k.indices(),
        inc_start: &inc_start,
        incidence: &incidence,
        elements: &tables.elements,
        elem_cols: tables.elem_cols,
        mats: &mats,
        scale: &scale,
    };
    let params = AssembleParams {
        n_rows: n as u32,
        row_base: 0,
        local_bits: tables.local_bits,
        _pad: 0,
    };
    let mut data = vec![T::of(0.0); k.indices().len()];
    assemble(&params, &inputs, &mut data);
    Some(data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::assembly::{assemble_deferred, assemble_matrix};
    use crate::fit::{ElementBlocks, FitSpace, FitWeights, NormalMatrix};
    use crate::mesh::Topology;
    use crate::mesh::generate::{Kind, generate};
    use crate::solve::LinOp;
    use crate::spline::SplineSpace;

    fn bits(v: &[f64]) -> Vec<u64> {
        v.iter().map(|v| v.to_bits()).collect()
    }

    /// A cylinder's spline space: uniform knots (shared matrices, and Q2 elements with
    /// constrained nodes, matrices of their own) or graded knots (every element its own).
    fn space(m: &crate::mesh::LinearMesh, t: &Topology, graded: bool) -> SplineSpace {
        if !graded {
            return SplineSpace::build(m, t);
        }
        let weights: Vec<_> = (0..m.n_elements())
            .map(|e| {
                let f = |k: usize| 0.3 + 0.4 * (((e * 7 + k * 3) % 11) as f64 / 10.0);
                [[f(0), f(1)], [f(2), f(3)], [f(4), f(5)]]
            })
            .collect();
        SplineSpace::build_with_knots(m, t, &[], Some(&weights))
    }

    /// The twin sums K with the bits of the host assembly in f64, scaled or not; the
    /// unsummed matrix's diagonal, product and host sums are the assembled matrix's to the
    /// bit; in f32 every entry is within [`crate::exec::gpu::assemble::ASSEMBLE_TOL_F32`] of
    /// its sum of term magnitudes.
    #[test]
    fn twin_sums_the_host_assembly() {
        let m = generate(Kind::Cylinder, 1500);
        let t = Topology::build(&m);
        for (name, graded) in [("uniform", false), ("graded", true)] {
            let s = space(&m, &t, graded);
            let ids = &mut Vec::new();
            let own = (0..s.n_elements())
                .filter(|&e| {
                    s.element_pattern(e, ids).is_none() && s.element_factors(e, ids).is_none()
                })
                .count();
            assert!(own > 0, "{name}: no element with a matrix of its own");
            let blocks = ElementBlocks::new(&s, &m, &t, &FitWeights::position());
            let n = s.control_points.len();
            let d: Vec<f64> = (0..n).map(|i| [1.0, 0.5, 0.25][i % 3]).collect();
            for scale in [None, Some(&d)] {
                let mut host = assemble_matrix(&s, &blocks);
                let mut k = assemble_deferred(&s, &blocks);
                if let Some(d) = scale {
                    host.scale_symmetric(d);
                    k.scale_symmetric(d);
                }
                assert_eq!(k.indptr(), host.indptr());
                assert_eq!(k.indices(), host.indices());
                let twin: Vec<f64> = assemble_all(&k, |v| v).expect("unsummed");
                assert!(bits(&twin) == bits(host.data()), "{name}: twin differs");
                assert_eq!(bits(&k.diagonal()), bits(&host.diagonal()), "{name}");
                let x: Vec<[f64; 3]> = (0..n)
                    .map(|i| [i as f64, 1.0, -(i as f64).sqrt()])
                    .collect();
                let (mut y0, mut y1) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
                host.apply(&x, &mut y0);
                k.apply(&x, &mut y1);
                let flat = |y: &[[f64; 3]]| bits(&y.concat());
                assert!(flat(&y0) == flat(&y1), "{name}: product differs");
                let f32s: Vec<f32> = assemble_all(&k, |v| v).expect("unsummed");
                let mags: Vec<f64> = assemble_all(&k, f64::abs).expect("unsummed");
                let tol = crate::exec::gpu::assemble::ASSEMBLE_TOL_F32;
                for ((a, b), m) in f32s.iter().zip(host.data()).zip(&mags) {
                    assert!((*a as f64 - b).abs() <= tol * m, "{name}: {a} against {b}");
                }
                assert!(
                    bits(k.data()) == bits(host.data()),
                    "{name}: host sums differ"
                );
                let _: &NormalMatrix = &k;
            }
        }
    }
}
