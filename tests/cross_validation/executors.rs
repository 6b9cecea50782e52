//! The executors a cross-validation test runs its one body on (the CPU reference and the GPU
//! on one device), and the dump of every executor's output when they disagree.
//!
//! A comparing test computes its result with the same code for each executor, through the
//! library's `Executor` seam, then checks the GPU's against the CPU's. On a failed check the
//! assertion message names the files both outputs were written to, under
//! `target/tmp/cross_validation/<test>/`, so the two can be diffed or opened in Gmsh.

use polyspline::exec::gpu::GpuContext;
use polyspline::exec::{CpuExecutor, Executor, GpuExecutor};
use polyspline::io::gmsh_write::{MshVersion, write_msh};
use polyspline::mesh::HighOrderMesh;
use std::fmt::Debug;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The CPU reference first, then the GPU on `ctx`.
pub fn cpu_and_gpu(ctx: &GpuContext) -> [Box<dyn Executor + '_>; 2] {
    [Box::new(CpuExecutor), Box::new(GpuExecutor::new(ctx))]
}

/// Run `body` once per executor: the outputs in the order of `executors`.
pub fn on_each<'a, T, const N: usize>(
    executors: &'a [Box<dyn Executor + 'a>; N],
    mut body: impl FnMut(&'a dyn Executor) -> T,
) -> [T; N] {
    executors.each_ref().map(|x| body(x.as_ref()))
}

/// An output that can be written for inspection.
pub trait Dump {
    /// The file extension of the dump.
    fn extension(&self) -> &'static str;
    fn dump(&self, w: &mut dyn Write) -> std::io::Result<()>;
}

/// High-order meshes as Gmsh files, which Gmsh opens side by side.
impl Dump for HighOrderMesh {
    fn extension(&self) -> &'static str {
        "msh"
    }
    fn dump(&self, w: &mut dyn Write) -> std::io::Result<()> {
        let mut buf = Vec::new();
        write_msh(self, MshVersion::V41, false, &mut buf)?;
        w.write_all(&buf)
    }
}

/// Point and solution vectors: one row per line, shortest round-trip decimals.
impl Dump for Vec<[f64; 3]> {
    fn extension(&self) -> &'static str {
        "txt"
    }
    fn dump(&self, w: &mut dyn Write) -> std::io::Result<()> {
        for (i, v) in self.iter().enumerate() {
            writeln!(w, "{i} {:?} {:?} {:?}", v[0], v[1], v[2])?;
        }
        Ok(())
    }
}

/// Anything else by its `Debug` form (solver reports and the like).
pub struct Debugged<T>(pub T);

impl<T: Debug> Dump for Debugged<T> {
    fn extension(&self) -> &'static str {
        "txt"
    }
    fn dump(&self, w: &mut dyn Write) -> std::io::Result<()> {
        writeln!(w, "{:#?}", self.0)
    }
}

/// A case name as a file name: mesh paths and option lists flattened.
fn file_stem(case: &str) -> String {
    case.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn dump_dir(test: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("cross_validation")
        .join(test);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Write each executor's output of `case` to `target/tmp/cross_validation/<test>/` and return
/// the paths as one line for the assertion message. `outputs` pairs an executor's name with
/// its output. Called from assertion messages, so only when a check fails.
pub fn dump(test: &str, case: &str, outputs: &[(&str, &dyn Dump)]) -> String {
    let dir = dump_dir(test);
    let paths: Vec<String> = outputs
        .iter()
        .map(|(name, out)| {
            let path = dir.join(format!("{}.{name}.{}", file_stem(case), out.extension()));
            let written = std::fs::File::create(&path)
                .map(std::io::BufWriter::new)
                .and_then(|mut f| {
                    out.dump(&mut f)?;
                    f.flush()
                });
            match written {
                Ok(()) => path.display().to_string(),
                Err(e) => format!("{} (not written: {e})", path.display()),
            }
        })
        .collect();
    format!("outputs: {}", paths.join(" and "))
}

/// Where a test that writes files (the `curve` job) puts each executor's output of `case`.
pub fn output_path(test: &str, case: &str, executor: &str, extension: &str) -> PathBuf {
    dump_dir(test).join(format!("{}.{executor}.{extension}", file_stem(case)))
}
