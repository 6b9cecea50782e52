// y += C x for the coupling C of the fit across rotation seams (src/fit/rotated.rs): 3 × 3
// blocks on the few rows whose control points an element sees in different frames, one
// invocation per such block row. Dispatched after spmv.wgsl has written y = K x (the three
// coordinates in the first three lanes of a vec4), so y becomes (K ⊗ I₃ + C) x.
// CPU twin: src/exec/cpu/coupling.rs.
alias real = f32;

struct Params {
    // Block rows (rows of C holding blocks).
    n_rows: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// The row of x and y of each block row.
@group(0) @binding(1) var<storage, read> rows: array<u32>;
// Offsets (n_rows + 1) into cols and blocks.
@group(0) @binding(2) var<storage, read> indptr: array<u32>;
@group(0) @binding(3) var<storage, read> cols: array<u32>;
// Block k's rows p = 0, 1, 2 at 3k + p (lanes 0–2; lane 3 zero).
@group(0) @binding(4) var<storage, read> blocks: array<vec4<real>>;
@group(0) @binding(5) var<storage, read> x: array<vec4<real>>;
@group(0) @binding(6) var<storage, read_write> y: array<vec4<real>>;

@compute @workgroup_size(64)
fn coupling(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= params.n_rows {
        return;
    }
    let row = rows[i];
    var s = y[row];
    for (var k = indptr[i]; k < indptr[i + 1u]; k++) {
        let v = x[cols[k]];
        let m0 = blocks[3u * k];
        let m1 = blocks[3u * k + 1u];
        let m2 = blocks[3u * k + 2u];
        s.x += m0.x * v.x + m0.y * v.y + m0.z * v.z;
        s.y += m1.x * v.x + m1.y * v.y + m1.z * v.z;
        s.z += m2.x * v.x + m2.y * v.y + m2.z * v.z;
    }
    y[row] = s;
}
