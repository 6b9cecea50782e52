//! The library's floors hold (`scripts/check_floors.py`, which has the floor table): no import
//! cycle between top-level modules, no import pointing up a floor, and every top-level module
//! of `src/lib.rs` on a floor, no clap in the library, and no printing or exiting in it (the
//! binary prints and sets the status). Imports are read from the sources (`use` trees, paths in code
//! and in doc links), so the test needs only Python's standard library.

use crate::common::{python, python_path, skip};

#[test]
fn no_import_cycle_and_no_import_up_a_floor() {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/check_floors.py");
    let out = match python().arg(script).output() {
        Ok(out) => out,
        Err(e) => {
            let why = format!("cannot run {}: {e}", python_path().display());
            return skip("floors::no_import_cycle_and_no_import_up_a_floor", &why);
        }
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "the floors do not hold:\n{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("floors hold"), "{stdout}");
}
