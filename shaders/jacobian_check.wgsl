// Bernstein coefficients of det J of tensor-product quadratic Bézier elements, reduced per
// element to (min coefficient, min corner coefficient, max coefficient) and the magnitudes of
// the partial-derivative coefficients (for the host's rounding-error bound). This is the first
// level of the certificate: min coefficient > 0 ⇒ det J > 0 on the whole element; the host
// finishes inconclusive elements on the CPU by subdivision.
// CPU twin: src/exec/cpu/jacobian_check.rs (same loops, same binding order).
alias real = f32;

struct Params {
    dim: u32,
    n_elements: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// 81 scalars per element (element-anchored control points 9z + 3y + x, then x, y, z).
@group(0) @binding(1) var<storage, read> nets: array<real>;
// Two per element: (min coefficient, min corner coefficient, max coefficient, 0) and
// (max |A|, max |B|, max |C|, 0) over the coefficients of the three partial-derivative factors.
@group(0) @binding(2) var<storage, read_write> bounds: array<vec4<real>>;

// C(n, k) at 7n + k.
var<private> BINOM: array<real, 49> = array<real, 49>(
    1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    1.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0,
    1.0, 3.0, 3.0, 1.0, 0.0, 0.0, 0.0,
    1.0, 4.0, 6.0, 4.0, 1.0, 0.0, 0.0,
    1.0, 5.0, 10.0, 10.0, 5.0, 1.0, 0.0,
    1.0, 6.0, 15.0, 20.0, 15.0, 6.0, 1.0,
);

// Partial-derivative factors, 18 coefficients per component c at 18c: in 3D A = ∂x/∂v,
// B = ∂x/∂w, C = ∂x/∂u; in 2D A = ∂x/∂u, B = ∂x/∂v.
var<private> pa: array<real, 54>;
var<private> pb: array<real, 54>;
var<private> pc: array<real, 54>;
// One component of A × B (degree ≤ (4, 3, 3)); det J (degree ≤ (5, 5, 5)).
var<private> cross: array<real, 80>;
var<private> det: array<real, 216>;

fn idx(i: u32, j: u32, k: u32, deg: vec3<u32>) -> u32 {
    return i + (deg.x + 1u) * (j + (deg.y + 1u) * k);
}

fn count(deg: vec3<u32>) -> u32 {
    return (deg.x + 1u) * (deg.y + 1u) * (deg.z + 1u);
}

fn unpack(o: u32, deg: vec3<u32>) -> vec3<u32> {
    let i = o % (deg.x + 1u);
    let j = (o / (deg.x + 1u)) % (deg.y + 1u);
    let k = o / ((deg.x + 1u) * (deg.y + 1u));
    return vec3<u32>(i, j, k);
}

// Bernstein product weight C(m, i) C(n, j) / C(m + n, i + j).
fn weight(m: u32, n: u32, i: u32, j: u32) -> real {
    return BINOM[7u * m + i] * BINOM[7u * n + j] / BINOM[7u * (m + n) + i + j];
}

fn net(e: u32, q: vec3<u32>, c: u32) -> real {
    return nets[e * 81u + (q.x + 3u * q.y + 9u * q.z) * 3u + c];
}

// Coefficient (i, j, k) of ∂x_c/∂t_d: 2 (P[q + e_d] − P[q]).
fn partial(e: u32, d: u32, c: u32, q: vec3<u32>) -> real {
    var hi = q;
    hi[d] += 1u;
    return 2.0 * (net(e, hi, c) - net(e, q, c));
}

// cross += s · A_ca · B_cb.
fn mul_ab(ca: u32, cb: u32, da: vec3<u32>, db: vec3<u32>, s: real) {
    let dout = da + db;
    for (var ia = 0u; ia < count(da); ia++) {
        let qa = unpack(ia, da);
        let a = s * pa[18u * ca + ia];
        for (var ib = 0u; ib < count(db); ib++) {
            let qb = unpack(ib, db);
            let w = weight(da.x, db.x, qa.x, qb.x) * weight(da.y, db.y, qa.y, qb.y)
                * weight(da.z, db.z, qa.z, qb.z);
            let o = idx(qa.x + qb.x, qa.y + qb.y, qa.z + qb.z, dout);
            cross[o] += a * pb[18u * cb + ib] * w;
        }
    }
}

// det += C_cc · cross.
fn mul_c(cc: u32, dc: vec3<u32>, dx: vec3<u32>) {
    let dout = dc + dx;
    for (var ic = 0u; ic < count(dc); ic++) {
        let qc = unpack(ic, dc);
        let a = pc[18u * cc + ic];
        for (var ix = 0u; ix < count(dx); ix++) {
            let qx = unpack(ix, dx);
            let w = weight(dc.x, dx.x, qc.x, qx.x) * weight(dc.y, dx.y, qc.y, qx.y)
                * weight(dc.z, dx.z, qc.z, qx.z);
            let o = idx(qc.x + qx.x, qc.y + qx.y, qc.z + qx.z, dout);
            det[o] += a * cross[ix] * w;
        }
    }
}

@compute @workgroup_size(64)
fn jacobian_check(@builtin(global_invocation_id) gid: vec3<u32>) {
    let e = gid.x;
    if e >= params.n_elements {
        return;
    }
    let three = params.dim == 3u;
    // Degrees of the factors and which direction each differentiates.
    var da = vec3<u32>(1u, 2u, 0u);
    var db = vec3<u32>(2u, 1u, 0u);
    var dc = vec3<u32>(0u, 0u, 0u);
    var dir = vec3<u32>(0u, 1u, 0u);
    if three {
        da = vec3<u32>(2u, 1u, 2u);
        db = vec3<u32>(2u, 2u, 1u);
        dc = vec3<u32>(1u, 2u, 2u);
        dir = vec3<u32>(1u, 2u, 0u);
    }
    var ma: real = 0.0;
    var mb: real = 0.0;
    var mc: real = 0.0;
    for (var c = 0u; c < 3u; c++) {
        for (var o = 0u; o < 18u; o++) {
            pa[18u * c + o] = 0.0;
            pb[18u * c + o] = 0.0;
            pc[18u * c + o] = 0.0;
            if o < count(da) {
                pa[18u * c + o] = partial(e, dir.x, c, unpack(o, da));
                ma = max(ma, abs(pa[18u * c + o]));
            }
            if o < count(db) {
                pb[18u * c + o] = partial(e, dir.y, c, unpack(o, db));
                mb = max(mb, abs(pb[18u * c + o]));
            }
            if three && o < count(dc) {
                pc[18u * c + o] = partial(e, dir.z, c, unpack(o, dc));
                mc = max(mc, abs(pc[18u * c + o]));
            }
        }
    }
    var dd = da + db;
    for (var o = 0u; o < 216u; o++) {
        det[o] = 0.0;
    }
    if three {
        dd = dc + da + db;
        for (var c = 0u; c < 3u; c++) {
            for (var o = 0u; o < 80u; o++) {
                cross[o] = 0.0;
            }
            let a = (c + 1u) % 3u;
            let b = (c + 2u) % 3u;
            mul_ab(a, b, da, db, 1.0);
            mul_ab(b, a, da, db, -1.0);
            mul_c(c, dc, da + db);
        }
    } else {
        for (var o = 0u; o < 80u; o++) {
            cross[o] = 0.0;
        }
        mul_ab(0u, 1u, da, db, 1.0);
        mul_ab(1u, 0u, da, db, -1.0);
        for (var o = 0u; o < count(dd); o++) {
            det[o] = cross[o];
        }
    }
    var lo = det[0];
    var hi = det[0];
    for (var o = 1u; o < count(dd); o++) {
        lo = min(lo, det[o]);
        hi = max(hi, det[o]);
    }
    var corner = det[0];
    for (var k = 0u; k < 2u; k++) {
        for (var j = 0u; j < 2u; j++) {
            for (var i = 0u; i < 2u; i++) {
                corner = min(corner, det[idx(i * dd.x, j * dd.y, k * dd.z, dd)]);
            }
        }
    }
    bounds[2u * e] = vec4<real>(lo, corner, hi, 0.0);
    bounds[2u * e + 1u] = vec4<real>(ma, mb, mc, 0.0);
}
