//! CPU twin of `shaders/local_newton.wgsl`: value, gradient and Hessian of each coloured-solver
//! local problem at the current position.

use super::Real;

/// Uniform block of `local_newton.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Params {
    pub dim: u32,
    pub n_problems: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}
const _: () = assert!(std::mem::size_of::<Params>() == 16);

type M3<T> = [[T; 3]; 3];

fn det<T: Real>(m: &M3<T>) -> T {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

fn cross<T: Real>(a: [T; 3], b: [T; 3]) -> [T; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn col<T: Real>(m: &M3<T>, j: usize) -> [T; 3] {
    [m[0][j], m[1][j], m[2][j]]
}

/// As the shader: rows of the inverse are the cross products of the columns, over det.
fn inverse<T: Real>(m: &M3<T>) -> M3<T> {
    let s = T::of(1.0) / det(m);
    let r0 = cross(col(m, 1), col(m, 2));
    let r1 = cross(col(m, 2), col(m, 0));
    let r2 = cross(col(m, 0), col(m, 1));
    [r0, r1, r2].map(|r| r.map(|x| x * s))
}

fn mul<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut r = [[T::of(0.0); 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    r
}

fn tr<T: Real>(a: &M3<T>) -> M3<T> {
    let mut r = *a;
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[j][i];
        }
    }
    r
}

fn norm2<T: Real>(m: &M3<T>) -> T {
    let mut s = T::of(0.0);
    for r in m {
        for x in r {
            s += *x * *x;
        }
    }
    s
}

fn apply<T: Real>(m: &M3<T>, v: [T; 3]) -> [T; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// One invocation per problem `p`, as in the shader.
pub fn local_newton<T: Real>(
    params: &Params,
    coefs: &[T],
    ranges: &[[u32; 2]],
    points: &[T],
    out: &mut [T],
) {
    let d = params.dim as usize;
    let dr = T::of(d as f64);
    for p in 0..params.n_problems as usize {
        let kii = coefs[4 * p];
        let b = [coefs[4 * p + 1], coefs[4 * p + 2], coefs[4 * p + 3]];
        let mut value = T::of(0.0);
        let mut g = [T::of(0.0); 3];
        let mut h = [[T::of(0.0); 3]; 3];
        for i in 0..d {
            g[i] = T::of(2.0) * b[i];
            h[i][i] = T::of(2.0) * kii;
        }
        let mut bad = false;
        let [first, count] = ranges[p];
        for k in 0..count as usize {
            let o = 13 * (first as usize + k);
            let w = points[o];
            let m = [
                [points[o + 1], points[o + 2], points[o + 3]],
                [points[o + 4], points[o + 5], points[o + 6]],
                [points[o + 7], points[o + 8], points[o + 9]],
            ];
            let psi = [points[o + 10], points[o + 11], points[o + 12]];
            if !(det(&m) > T::of(0.0)) {
                bad = true;
                break;
            }
            let a = inverse(&m);
            let at = tr(&a);
            value += w * (norm2(&m) + norm2(&a) - T::of(6.0)) / (T::of(2.0) * dr);
            let t = mul(&mul(&at, &a), &at);
            let mut mt = m;
            for i in 0..3 {
                for j in 0..3 {
                    mt[i][j] = m[i][j] - t[i][j];
                }
            }
            let gm = apply(&mt, psi);
            for i in 0..d {
                g[i] += w * gm[i] / dr;
            }
            for c in 0..d {
                let mut dm = [[T::of(0.0); 3]; 3];
                dm[c] = psi;
                let da = mul(&mul(&a, &dm), &a).map(|r| r.map(|x| -x));
                let dat = tr(&da);
                let t1 = mul(&mul(&dat, &a), &at);
                let t2 = mul(&mul(&at, &da), &at);
                let t3 = mul(&mul(&at, &a), &dat);
                let mut dg = dm;
                for i in 0..3 {
                    for j in 0..3 {
                        dg[i][j] = dm[i][j] - (t1[i][j] + t2[i][j] + t3[i][j]);
                    }
                }
                let colv = apply(&dg, psi);
                for i in 0..d {
                    h[i][c] += w * colv[i] / dr;
                }
            }
        }
        let r = 13 * p;
        out[r] = if bad { T::of(-1.0) } else { value };
        for i in 0..3 {
            out[r + 1 + i] = g[i];
            for c in 0..3 {
                out[r + 4 + 3 * i + c] = h[i][c];
            }
        }
    }
}
