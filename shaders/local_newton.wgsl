// Local Newton data of the coloured energy solver (src/energy/colored.rs): for each control
// point's local problem, the energy's value, gradient and Hessian at the current position.
// CPU twin: src/exec/cpu/local_newton.rs (same loops, same binding order).
//
// Problem p: L(v) = kii |v|^2 + 2 b.v + sum_q w_q f(M_q + v psi_q^T), f the symmetric Dirichlet
// density (|M|^2 + |M^-1|^2 - 6) / (2d) (2D: M embedded with M_33 = 1), evaluated at v = 0.
alias real = f32;

struct Params {
    dim: u32,
    n_problems: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// 4 scalars per problem: kii, b.x, b.y, b.z.
@group(0) @binding(1) var<storage, read> coefs: array<real>;
// (first point, number of points) per problem.
@group(0) @binding(2) var<storage, read> ranges: array<vec2<u32>>;
// 13 scalars per point: w, M row-major (9), psi (3).
@group(0) @binding(3) var<storage, read> points: array<real>;
// 13 scalars per problem: value (or -1 when some det M <= 0), gradient (3), Hessian row-major (9).
@group(0) @binding(4) var<storage, read_write> out: array<real>;

fn inverse3(m: mat3x3<real>) -> mat3x3<real> {
    let det = determinant(m);
    // Columns of the adjugate transposed, i.e. rows of the inverse via cross products.
    let c0 = cross(m[1], m[2]);
    let c1 = cross(m[2], m[0]);
    let c2 = cross(m[0], m[1]);
    return transpose(mat3x3<real>(c0, c1, c2)) * (1.0 / det);
}

fn norm2(m: mat3x3<real>) -> real {
    return dot(m[0], m[0]) + dot(m[1], m[1]) + dot(m[2], m[2]);
}

@compute @workgroup_size(64)
fn local_newton(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = gid.x;
    if p >= params.n_problems {
        return;
    }
    let d = params.dim;
    let dr = real(d);
    let kii = coefs[4u * p];
    let b = vec3<real>(coefs[4u * p + 1u], coefs[4u * p + 2u], coefs[4u * p + 3u]);
    var value: real = 0.0;
    var g = vec3<real>(0.0, 0.0, 0.0);
    // Hessian columns.
    var h = mat3x3<real>(vec3<real>(0.0, 0.0, 0.0), vec3<real>(0.0, 0.0, 0.0), vec3<real>(0.0, 0.0, 0.0));
    for (var i = 0u; i < d; i++) {
        g[i] = 2.0 * b[i];
        h[i][i] = 2.0 * kii;
    }
    var bad = false;
    let first = ranges[p].x;
    let count = ranges[p].y;
    for (var k = 0u; k < count; k++) {
        let o = 13u * (first + k);
        let w = points[o];
        // WGSL matrices are column-major: column j holds M[.][j].
        let m = mat3x3<real>(
            vec3<real>(points[o + 1u], points[o + 4u], points[o + 7u]),
            vec3<real>(points[o + 2u], points[o + 5u], points[o + 8u]),
            vec3<real>(points[o + 3u], points[o + 6u], points[o + 9u]),
        );
        let psi = vec3<real>(points[o + 10u], points[o + 11u], points[o + 12u]);
        if !(determinant(m) > 0.0) {
            bad = true;
            break;
        }
        let a = inverse3(m);
        let at = transpose(a);
        value += w * (norm2(m) + norm2(a) - 6.0) / (2.0 * dr);
        // dL/dv = w (M - A^T A A^T) psi / d.
        let t = at * a * at;
        let gm = (m - t) * psi;
        for (var i = 0u; i < d; i++) {
            g[i] += w * gm[i] / dr;
        }
        // d/dv_c with dM = e_c psi^T: dG = (dM - dT) / d, dA = -A dM A.
        for (var c = 0u; c < d; c++) {
            var dm = mat3x3<real>(vec3<real>(0.0, 0.0, 0.0), vec3<real>(0.0, 0.0, 0.0), vec3<real>(0.0, 0.0, 0.0));
            for (var j = 0u; j < 3u; j++) {
                dm[j][c] = psi[j];
            }
            let da = (a * dm * a) * -1.0;
            let dat = transpose(da);
            let dt = dat * a * at + at * da * at + at * a * dat;
            let col = (dm - dt) * psi;
            for (var i = 0u; i < d; i++) {
                h[c][i] += w * col[i] / dr;
            }
        }
    }
    let r = 13u * p;
    if bad {
        out[r] = -1.0;
    } else {
        out[r] = value;
    }
    for (var i = 0u; i < 3u; i++) {
        out[r + 1u + i] = g[i];
        for (var c = 0u; c < 3u; c++) {
            out[r + 4u + 3u * i + c] = h[c][i];
        }
    }
}
