// Evaluate tensor-product quadratic Bézier elements at parameters: points and parametric
// derivatives. CPU twin: src/exec/cpu/evaluate.rs (same loops, same binding order).
//
// Nets are element-anchored (the host subtracts an anchor point in f64 before upload and adds
// it back to the points), so rounding scales with the element size.
alias real = f32;

struct Params {
    dim: u32,
    n_queries: u32,
    with_derivs: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// 81 scalars per element: control point 9z + 3y + x, then x, y, z.
@group(0) @binding(1) var<storage, read> nets: array<real>;
// Parameters (u, v, w, unused).
@group(0) @binding(2) var<storage, read> xi: array<vec4<real>>;
// (element in this chunk, parameter index).
@group(0) @binding(3) var<storage, read> queries: array<vec2<u32>>;
// 3 scalars per query.
@group(0) @binding(4) var<storage, read_write> points: array<real>;
// 9 scalars per query: d/du (x, y, z), d/dv, d/dw; written when with_derivs != 0.
@group(0) @binding(5) var<storage, read_write> derivs: array<real>;

fn bernstein2(t: real) -> vec3<real> {
    let s = 1.0 - t;
    return vec3<real>(s * s, 2.0 * s * t, t * t);
}

fn bernstein2_derivative(t: real) -> vec3<real> {
    return vec3<real>(-2.0 * (1.0 - t), 2.0 - 4.0 * t, 2.0 * t);
}

@compute @workgroup_size(64)
fn evaluate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let q = gid.x;
    if q >= params.n_queries {
        return;
    }
    let e = queries[q].x;
    let t = xi[queries[q].y];
    let bu = bernstein2(t.x);
    let bv = bernstein2(t.y);
    let du = bernstein2_derivative(t.x);
    let dv = bernstein2_derivative(t.y);
    var bw = vec3<real>(1.0, 0.0, 0.0);
    var dw = vec3<real>(0.0, 0.0, 0.0);
    var nz = 1u;
    if params.dim == 3u {
        bw = bernstein2(t.z);
        dw = bernstein2_derivative(t.z);
        nz = 3u;
    }
    var x = vec3<real>(0.0, 0.0, 0.0);
    var xu = vec3<real>(0.0, 0.0, 0.0);
    var xv = vec3<real>(0.0, 0.0, 0.0);
    var xw = vec3<real>(0.0, 0.0, 0.0);
    for (var c = 0u; c < nz; c++) {
        for (var b = 0u; b < 3u; b++) {
            for (var a = 0u; a < 3u; a++) {
                let o = e * 81u + (9u * c + 3u * b + a) * 3u;
                let p = vec3<real>(nets[o], nets[o + 1u], nets[o + 2u]);
                x += (bu[a] * bv[b] * bw[c]) * p;
                xu += (du[a] * bv[b] * bw[c]) * p;
                xv += (bu[a] * dv[b] * bw[c]) * p;
                xw += (bu[a] * bv[b] * dw[c]) * p;
            }
        }
    }
    points[3u * q] = x.x;
    points[3u * q + 1u] = x.y;
    points[3u * q + 2u] = x.z;
    if params.with_derivs != 0u {
        let o = 9u * q;
        derivs[o] = xu.x;
        derivs[o + 1u] = xu.y;
        derivs[o + 2u] = xu.z;
        derivs[o + 3u] = xv.x;
        derivs[o + 4u] = xv.y;
        derivs[o + 5u] = xv.z;
        derivs[o + 6u] = xw.x;
        derivs[o + 7u] = xw.y;
        derivs[o + 8u] = xw.z;
    }
}
