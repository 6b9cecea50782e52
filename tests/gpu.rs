//! GPU path: naga validation of every shader (no driver needed), and cross-validation of each
//! kernel against its CPU twin, the f64 reference and independent oracles on lavapipe or a
//! hardware GPU. A missing adapter fails under `CI=true` and is a printed skip elsewhere.

use polyspline::cpu;
use polyspline::gpu::{self, AdapterChoice, GpuContext, Precision};

/// Every shader parses and validates, at both precisions.
#[test]
fn shaders_validate_with_naga() {
    for (name, src) in gpu::SHADERS {
        for prec in [Precision::F32, Precision::F64] {
            let text = gpu::shader_source(src, prec);
            assert!(text.contains("alias real"), "{name}: no `alias real`");
            let module = naga::front::wgsl::parse_str(&text)
                .unwrap_or_else(|e| panic!("{name} ({prec:?}): {}", e.emit_to_string(&text)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::FLOAT64,
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name} ({prec:?}): {e:?}"));
        }
    }
    // Every .wgsl in shaders/ is covered.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    for f in std::fs::read_dir(dir).unwrap() {
        let f = f.unwrap().file_name().into_string().unwrap();
        if f.ends_with(".wgsl") {
            assert!(
                gpu::SHADERS.iter().any(|(n, _)| *n == f),
                "{f} is not validated"
            );
        }
    }
}
