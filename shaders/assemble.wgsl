// The fit's normal matrix K = Σ_e E_eᵀ G_e E_e summed row by row, for a block of rows of its
// CSR form, without atomics: row c gathers row i of each incident element's m × m matrix
// (element e, local index i), summed into the row's values in element order, then scales the
// row by d_c d_j. CPU twin: src/exec/cpu/assemble.rs.
alias real = f32;

struct Params {
    n_rows: u32,
    // First row of this block.
    row_base: u32,
    // Bits of the local index in an incidence entry (element << local_bits | local).
    local_bits: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Block-local row pointers (n_rows + 1), into this block's indices and data.
@group(0) @binding(1) var<storage, read> indptr: array<u32>;
// The rows' columns, sorted within each row.
@group(0) @binding(2) var<storage, read> indices: array<u32>;
// Block-local offsets (n_rows + 1) into `incidence`.
@group(0) @binding(3) var<storage, read> inc_start: array<u32>;
// Per row its elements in element order, packed element << local_bits | local index.
@group(0) @binding(4) var<storage, read> incidence: array<u32>;
// Per element and one past the last: its first column in elem_cols, its matrix's offset in mats.
@group(0) @binding(5) var<storage, read> elements: array<vec2<u32>>;
@group(0) @binding(6) var<storage, read> elem_cols: array<u32>;
// The element matrices, m × m row-major over the element's columns.
@group(0) @binding(7) var<storage, read> mats: array<real>;
// The symmetric scaling d (1 where none), one per row of K.
@group(0) @binding(8) var<storage, read> scale: array<real>;
@group(0) @binding(9) var<storage, read_write> data: array<real>;

@compute @workgroup_size(64)
fn assemble(@builtin(global_invocation_id) gid: vec3<u32>) {
    let r = gid.x;
    if r >= params.n_rows {
        return;
    }
    let lo = indptr[r];
    let hi = indptr[r + 1u];
    for (var k = lo; k < hi; k++) {
        data[k] = real(0.0);
    }
    let mask = (1u << params.local_bits) - 1u;
    for (var t = inc_start[r]; t < inc_start[r + 1u]; t++) {
        let packed = incidence[t];
        let e = packed >> params.local_bits;
        let i = packed & mask;
        let first = elements[e].x;
        let m = elements[e + 1u].x - first;
        let row = elements[e].y + i * m;
        for (var j = 0u; j < m; j++) {
            let col = elem_cols[first + j];
            // The column's position in the row: the first stored column not below it.
            var a = lo;
            var b = hi;
            while a < b {
                let mid = (a + b) / 2u;
                if indices[mid] < col {
                    a = mid + 1u;
                } else {
                    b = mid;
                }
            }
            data[a] += mats[row + j];
        }
    }
    let dr = scale[params.row_base + r];
    for (var k = lo; k < hi; k++) {
        data[k] = data[k] * (dr * scale[indices[k]]);
    }
}
