//! The WGSL kernels as naga reflects them at build time (`build.rs` parses and validates every
//! file in `shaders/` at f32 and f64, so a broken shader fails the build): each compute entry
//! point's workgroup size and the bindings it uses.
//!
//! The assertions below run at compile time and tie the shaders to what the host code assumes:
//! every file in `shaders/` is in [`super::SHADERS`]; the per-item kernels run in workgroups of
//! [`ITEM_WORKGROUP`] (the host dispatches `groups(n, ITEM_WORKGROUP)`); every binding is in
//! group 0 (the only bind group the host sets); every kernel the host compiles exists.

/// How a kernel sees one buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    Uniform,
    StorageRead,
    StorageReadWrite,
}

/// One buffer binding of a kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    pub group: u32,
    pub binding: u32,
    pub kind: BindingKind,
}

/// One compute entry point.
#[derive(Clone, Copy, Debug)]
pub struct Kernel {
    /// File name in `shaders/`.
    pub file: &'static str,
    pub entry: &'static str,
    pub workgroup_size: [u32; 3],
    /// The bindings the entry point uses (wgpu's derived layout), by group and binding.
    pub bindings: &'static [Binding],
}

include!(concat!(env!("OUT_DIR"), "/shader_reflection.rs"));

/// Invocations per workgroup of the kernels that run one invocation per item.
pub const ITEM_WORKGROUP: u32 = 64;

/// The kernels dispatched as `groups(n, ITEM_WORKGROUP)` workgroups.
const ITEM_KERNELS: [&str; 8] = [
    "assemble",
    "coupling",
    "evaluate",
    "jacobian_check",
    "local_newton",
    "spmv",
    "update_xr",
    "update_p",
];

/// The reductions: `dot_partial` over a fixed number of workgroups with a grid-strided loop,
/// the finalisers as one workgroup; their sizes are the shaders' own.
const REDUCTION_KERNELS: [&str; 3] = ["dot_partial", "finalize_alpha", "finalize_beta"];

const fn same(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// The kernel with entry point `entry` (a compile error in constant context when none has it).
pub const fn kernel(entry: &str) -> &'static Kernel {
    let mut i = 0;
    while i < KERNELS.len() {
        if same(KERNELS[i].entry, entry) {
            return &KERNELS[i];
        }
        i += 1;
    }
    panic!("no WGSL kernel has this entry point");
}

const _: () = {
    let mut i = 0;
    while i < ITEM_KERNELS.len() {
        let size = kernel(ITEM_KERNELS[i]).workgroup_size;
        assert!(
            size[0] == ITEM_WORKGROUP && size[1] == 1 && size[2] == 1,
            "a per-item kernel's @workgroup_size differs from ITEM_WORKGROUP"
        );
        i += 1;
    }
    let mut i = 0;
    while i < REDUCTION_KERNELS.len() {
        kernel(REDUCTION_KERNELS[i]);
        i += 1;
    }
    // Every entry point is one of the above, and binds in group 0 only.
    assert!(
        KERNELS.len() == ITEM_KERNELS.len() + REDUCTION_KERNELS.len(),
        "a WGSL entry point the host does not know"
    );
    let mut i = 0;
    while i < KERNELS.len() {
        let b = KERNELS[i].bindings;
        let mut j = 0;
        while j < b.len() {
            assert!(b[j].group == 0, "a kernel binds outside group 0");
            j += 1;
        }
        i += 1;
    }
    // Every file in shaders/ is compiled by the host.
    assert!(
        FILES.len() == super::SHADERS.len(),
        "shaders/ and gpu::SHADERS differ"
    );
    let mut i = 0;
    while i < FILES.len() {
        let mut found = false;
        let mut j = 0;
        while j < super::SHADERS.len() {
            found |= same(super::SHADERS[j].0, FILES[i]);
            j += 1;
        }
        assert!(found, "a file in shaders/ is missing from gpu::SHADERS");
        i += 1;
    }
};

#[cfg(test)]
mod tests {
    use super::*;

    /// The reflected layouts are what the host binds: spot checks against the binding lists
    /// in `exec/gpu/` (the full check is wgpu's own validation when a bind group is created).
    #[test]
    fn reflection_matches_the_host_bindings() {
        let k = kernel("jacobian_check");
        assert_eq!(k.file, "jacobian_check.wgsl");
        let ids: Vec<u32> = k.bindings.iter().map(|b| b.binding).collect();
        assert_eq!(ids, [0, 1, 2]);
        assert_eq!(k.bindings[0].kind, BindingKind::Uniform);
        assert_eq!(k.bindings[2].kind, BindingKind::StorageReadWrite);
        let k = kernel("dot_partial");
        assert_eq!(k.bindings.len(), 4);
        assert_eq!(k.bindings[1].kind, BindingKind::StorageRead);
        assert_eq!(kernel("update_p").bindings.len(), 4);
        let k = kernel("assemble");
        assert_eq!(k.bindings.len(), 10);
        assert_eq!(k.bindings[9].kind, BindingKind::StorageReadWrite);
    }
}
