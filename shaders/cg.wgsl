// Jacobi-preconditioned CG on three right-hand sides with every scalar kept on the GPU:
// second-stage reductions that also compute α and β (finalize_alpha, finalize_beta), and the
// vector updates (update_xr: x += α p, r −= α Ap, z = D⁻¹ r; update_p: p = z + β p).
// Components that have converged (rr ≤ target²) take α = 0 and keep their iterate, so
// iterations batched past convergence change nothing and 0/0 never occurs.
// Coupled (params.coupled = 1: the fit's system K ⊗ I₃ + C across rotation seams): one
// recurrence over the three coordinates, as the CPU's solve::Coupled steps: the finalisers sum
// the three lanes of each reduction into lane 0 (rz, rr and target² live in lane 0, lanes 1
// and 2 never run) and step all three lanes by lane 0's α and β.
// CPU twin: src/exec/cpu/cg.rs.
alias real = f32;

const WG: u32 = 256u;

struct Params {
    n: u32,
    n_partials: u32,
    max_iters: u32,
    // 1: one recurrence over the three lanes (see above).
    coupled: u32,
}

struct Scalars {
    rz: vec4<real>,
    rr: vec4<real>,
    target2: vec4<real>,
    alpha: vec4<real>,
    beta: vec4<real>,
    pap: vec4<real>,
}

struct State {
    iterations: u32,
    // 1 once every component has converged or the iteration limit is reached.
    done: u32,
    // 1 + iteration of a non-positive curvature pᵀAp, or 0.
    breakdown: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> scalars: Scalars;
@group(0) @binding(2) var<storage, read_write> state: State;
@group(0) @binding(3) var<storage, read> partials: array<vec4<real>>;
@group(0) @binding(4) var<storage, read_write> x: array<vec4<real>>;
@group(0) @binding(5) var<storage, read_write> r: array<vec4<real>>;
@group(0) @binding(6) var<storage, read_write> z: array<vec4<real>>;
@group(0) @binding(7) var<storage, read_write> p: array<vec4<real>>;
@group(0) @binding(8) var<storage, read> ap: array<vec4<real>>;
@group(0) @binding(9) var<storage, read> inv_diag: array<real>;

var<workgroup> s0: array<vec4<real>, WG>;
var<workgroup> s1: array<vec4<real>, WG>;

// Sum the partial pairs of dot.wgsl into s0[0] (a·b) and s1[0] (a·a).
fn reduce_partials(l: u32) {
    var ab = vec4<real>(0.0, 0.0, 0.0, 0.0);
    var aa = vec4<real>(0.0, 0.0, 0.0, 0.0);
    for (var g = l; g < params.n_partials; g += WG) {
        ab += partials[2u * g];
        aa += partials[2u * g + 1u];
    }
    s0[l] = ab;
    s1[l] = aa;
    workgroupBarrier();
    for (var h = WG / 2u; h > 0u; h /= 2u) {
        if l < h {
            s0[l] += s0[l + h];
            s1[l] += s1[l + h];
        }
        workgroupBarrier();
    }
}

// The three lanes' sum in lane 0 (the coupled recurrence's sums), or `v` itself.
fn sums(v: vec4<real>) -> vec4<real> {
    if params.coupled != 0u {
        return vec4<real>(v.x + v.y + v.z, 0.0, 0.0, 0.0);
    }
    return v;
}

// Lane 0's step on all three lanes (coupled), or `v` itself.
fn steps(v: vec4<real>) -> vec4<real> {
    if params.coupled != 0u {
        return vec4<real>(v.x, v.x, v.x, 0.0);
    }
    return v;
}

// After dot_partial(p, Ap): α_k = rz_k / pᵀAp_k for the running components.
@compute @workgroup_size(WG)
fn finalize_alpha(@builtin(local_invocation_id) lid: vec3<u32>) {
    reduce_partials(lid.x);
    if lid.x != 0u {
        return;
    }
    let pap = sums(s0[0]);
    var alpha = vec4<real>(0.0, 0.0, 0.0, 0.0);
    var running = false;
    if state.done == 0u && state.breakdown == 0u {
        for (var k = 0u; k < 3u; k++) {
            if scalars.rr[k] > scalars.target2[k] {
                running = true;
            }
        }
        if running && state.iterations >= params.max_iters {
            running = false;
        }
        if running {
            for (var k = 0u; k < 3u; k++) {
                if scalars.rr[k] > scalars.target2[k] {
                    if pap[k] > 0.0 {
                        alpha[k] = scalars.rz[k] / pap[k];
                    } else {
                        state.breakdown = state.iterations + 1u;
                        alpha = vec4<real>(0.0, 0.0, 0.0, 0.0);
                        break;
                    }
                }
            }
            state.iterations += 1u;
        } else {
            state.done = 1u;
        }
    }
    scalars.pap = pap;
    scalars.alpha = steps(alpha);
}

@compute @workgroup_size(64)
fn update_xr(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= params.n {
        return;
    }
    let alpha = scalars.alpha;
    x[i] += alpha * p[i];
    r[i] -= alpha * ap[i];
    z[i] = inv_diag[i] * r[i];
}

// After dot_partial(r, z): β = rz_new / rz (0 when rz = 0), then rz, rr updated.
@compute @workgroup_size(WG)
fn finalize_beta(@builtin(local_invocation_id) lid: vec3<u32>) {
    reduce_partials(lid.x);
    if lid.x != 0u {
        return;
    }
    let rz_new = sums(s0[0]);
    let rr_new = sums(s1[0]);
    var beta = vec4<real>(0.0, 0.0, 0.0, 0.0);
    if state.done == 0u {
        for (var k = 0u; k < 3u; k++) {
            if scalars.rz[k] > 0.0 {
                beta[k] = rz_new[k] / scalars.rz[k];
            }
        }
        scalars.rz = rz_new;
        scalars.rr = rr_new;
    }
    scalars.beta = steps(beta);
}

@compute @workgroup_size(64)
fn update_p(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= params.n {
        return;
    }
    p[i] = z[i] + scalars.beta * p[i];
}
