// y = A x for a block of rows of a CSR matrix, on three right-hand sides at once (x, y, z in
// the first three lanes of a vec4). CPU twin: src/exec/cpu/spmv.rs.
alias real = f32;

struct Params {
    n_rows: u32,
    // First row of this block in x and y.
    row_base: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Block-local row pointers (n_rows + 1), into this block's indices and data.
@group(0) @binding(1) var<storage, read> indptr: array<u32>;
@group(0) @binding(2) var<storage, read> indices: array<u32>;
@group(0) @binding(3) var<storage, read> data: array<real>;
@group(0) @binding(4) var<storage, read> x: array<vec4<real>>;
@group(0) @binding(5) var<storage, read_write> y: array<vec4<real>>;

@compute @workgroup_size(64)
fn spmv(@builtin(global_invocation_id) gid: vec3<u32>) {
    let r = gid.x;
    if r >= params.n_rows {
        return;
    }
    var s = vec4<real>(0.0, 0.0, 0.0, 0.0);
    for (var k = indptr[r]; k < indptr[r + 1u]; k++) {
        s += data[k] * x[indices[k]];
    }
    y[params.row_base + r] = s;
}
