//! CPU twin of `shaders/jacobian_check.wgsl`.

use super::{Real, Vec4};

/// Uniform block of `jacobian_check.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Params {
    pub dim: u32,
    pub n_elements: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 16);

type U3 = [usize; 3];

fn idx(i: usize, j: usize, k: usize, deg: U3) -> usize {
    i + (deg[0] + 1) * (j + (deg[1] + 1) * k)
}

fn count(deg: U3) -> usize {
    (deg[0] + 1) * (deg[1] + 1) * (deg[2] + 1)
}

fn unpack(o: usize, deg: U3) -> U3 {
    let i = o % (deg[0] + 1);
    let j = (o / (deg[0] + 1)) % (deg[1] + 1);
    let k = o / ((deg[0] + 1) * (deg[1] + 1));
    [i, j, k]
}

fn add3(a: U3, b: U3) -> U3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// C(n, k) at 7n + k.
fn binom<T: Real>(n: usize, k: usize) -> T {
    const B: [[f64; 7]; 7] = [
        [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [1.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        [1.0, 3.0, 3.0, 1.0, 0.0, 0.0, 0.0],
        [1.0, 4.0, 6.0, 4.0, 1.0, 0.0, 0.0],
        [1.0, 5.0, 10.0, 10.0, 5.0, 1.0, 0.0],
        [1.0, 6.0, 15.0, 20.0, 15.0, 6.0, 1.0],
    ];
    T::of(B[n][k])
}

fn weight<T: Real>(m: usize, n: usize, i: usize, j: usize) -> T {
    binom::<T>(m, i) * binom::<T>(n, j) / binom::<T>(m + n, i + j)
}

/// The shader's private arrays.
struct Private<T> {
    pa: [T; 54],
    pb: [T; 54],
    pc: [T; 54],
    cross: [T; 80],
    det: [T; 216],
}

fn net<T: Real>(nets: &[T], e: usize, q: U3, c: usize) -> T {
    nets[e * 81 + (q[0] + 3 * q[1] + 9 * q[2]) * 3 + c]
}

fn partial<T: Real>(nets: &[T], e: usize, d: usize, c: usize, q: U3) -> T {
    let mut hi = q;
    hi[d] += 1;
    T::of(2.0) * (net(nets, e, hi, c) - net(nets, e, q, c))
}

fn mul_ab<T: Real>(m: &mut Private<T>, ca: usize, cb: usize, da: U3, db: U3, s: T) {
    let dout = add3(da, db);
    for ia in 0..count(da) {
        let qa = unpack(ia, da);
        let a = s * m.pa[18 * ca + ia];
        for ib in 0..count(db) {
            let qb = unpack(ib, db);
            let w = weight::<T>(da[0], db[0], qa[0], qb[0])
                * weight::<T>(da[1], db[1], qa[1], qb[1])
                * weight::<T>(da[2], db[2], qa[2], qb[2]);
            let o = idx(qa[0] + qb[0], qa[1] + qb[1], qa[2] + qb[2], dout);
            m.cross[o] += a * m.pb[18 * cb + ib] * w;
        }
    }
}

fn mul_c<T: Real>(m: &mut Private<T>, cc: usize, dc: U3, dx: U3) {
    let dout = add3(dc, dx);
    for ic in 0..count(dc) {
        let qc = unpack(ic, dc);
        let a = m.pc[18 * cc + ic];
        for ix in 0..count(dx) {
            let qx = unpack(ix, dx);
            let w = weight::<T>(dc[0], dx[0], qc[0], qx[0])
                * weight::<T>(dc[1], dx[1], qc[1], qx[1])
                * weight::<T>(dc[2], dx[2], qc[2], qx[2]);
            let o = idx(qc[0] + qx[0], qc[1] + qx[1], qc[2] + qx[2], dout);
            m.det[o] += a * m.cross[ix] * w;
        }
    }
}

/// One invocation per element `e`, as in the shader: `bounds[2e]` = (min coefficient, min
/// corner coefficient, max coefficient, 0), `bounds[2e+1]` = (max |A|, max |B|, max |C|, 0).
pub fn jacobian_check<T: Real>(params: &Params, nets: &[T], bounds: &mut [Vec4<T>]) {
    let zero = T::of(0.0);
    for e in 0..params.n_elements as usize {
        let three = params.dim == 3;
        let mut m = Private {
            pa: [zero; 54],
            pb: [zero; 54],
            pc: [zero; 54],
            cross: [zero; 80],
            det: [zero; 216],
        };
        let (mut da, mut db, mut dc, mut dir) = ([1, 2, 0], [2, 1, 0], [0, 0, 0], [0, 1, 0]);
        if three {
            da = [2, 1, 2];
            db = [2, 2, 1];
            dc = [1, 2, 2];
            dir = [1, 2, 0];
        }
        let (mut ma, mut mb, mut mc) = (zero, zero, zero);
        for c in 0..3 {
            for o in 0..18 {
                if o < count(da) {
                    m.pa[18 * c + o] = partial(nets, e, dir[0], c, unpack(o, da));
                    ma = ma.max(m.pa[18 * c + o].abs());
                }
                if o < count(db) {
                    m.pb[18 * c + o] = partial(nets, e, dir[1], c, unpack(o, db));
                    mb = mb.max(m.pb[18 * c + o].abs());
                }
                if three && o < count(dc) {
                    m.pc[18 * c + o] = partial(nets, e, dir[2], c, unpack(o, dc));
                    mc = mc.max(m.pc[18 * c + o].abs());
                }
            }
        }
        let mut dd = add3(da, db);
        if three {
            dd = add3(dc, add3(da, db));
            for c in 0..3 {
                m.cross = [zero; 80];
                let a = (c + 1) % 3;
                let b = (c + 2) % 3;
                mul_ab(&mut m, a, b, da, db, T::of(1.0));
                mul_ab(&mut m, b, a, da, db, T::of(-1.0));
                mul_c(&mut m, c, dc, add3(da, db));
            }
        } else {
            mul_ab(&mut m, 0, 1, da, db, T::of(1.0));
            mul_ab(&mut m, 1, 0, da, db, T::of(-1.0));
            for o in 0..count(dd) {
                m.det[o] = m.cross[o];
            }
        }
        let mut lo = m.det[0];
        let mut hi = m.det[0];
        for o in 1..count(dd) {
            lo = lo.min(m.det[o]);
            hi = hi.max(m.det[o]);
        }
        let mut corner = m.det[0];
        for k in 0..2 {
            for j in 0..2 {
                for i in 0..2 {
                    corner = corner.min(m.det[idx(i * dd[0], j * dd[1], k * dd[2], dd)]);
                }
            }
        }
        bounds[2 * e] = [lo, corner, hi, zero];
        bounds[2 * e + 1] = [ma, mb, mc, zero];
    }
}
