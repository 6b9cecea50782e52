// First stage of the dot products a·b and a·a on three right-hand sides: each workgroup
// reduces a grid-strided share of the rows to one pair of partial sums. The second stage is in
// cg.wgsl (finalize_alpha, finalize_beta). CPU twin: src/exec/cpu/dot.rs.
alias real = f32;

const WG: u32 = 256u;

struct Params {
    n: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> a: array<vec4<real>>;
@group(0) @binding(2) var<storage, read> b: array<vec4<real>>;
// Per workgroup g: partials[2g] = Σ a·b, partials[2g + 1] = Σ a·a (componentwise).
@group(0) @binding(3) var<storage, read_write> partials: array<vec4<real>>;

var<workgroup> sab: array<vec4<real>, WG>;
var<workgroup> saa: array<vec4<real>, WG>;

@compute @workgroup_size(WG)
fn dot_partial(
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    var ab = vec4<real>(0.0, 0.0, 0.0, 0.0);
    var aa = vec4<real>(0.0, 0.0, 0.0, 0.0);
    let stride = nwg.x * WG;
    for (var i = wid.x * WG + lid.x; i < params.n; i += stride) {
        let x = a[i];
        ab += x * b[i];
        aa += x * x;
    }
    sab[lid.x] = ab;
    saa[lid.x] = aa;
    workgroupBarrier();
    for (var h = WG / 2u; h > 0u; h /= 2u) {
        if lid.x < h {
            sab[lid.x] += sab[lid.x + h];
            saa[lid.x] += saa[lid.x + h];
        }
        workgroupBarrier();
    }
    if lid.x == 0u {
        partials[2u * wid.x] = sab[0];
        partials[2u * wid.x + 1u] = saa[0];
    }
}
