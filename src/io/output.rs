//! Safe output files: written to a temporary file beside the target and renamed into place,
//! so a failed or interrupted write never leaves a half-written file, and never onto an input.
//!
//! Inputs: the target path, the input paths it must not replace, and a body that writes the
//! content. Output: the target, complete, or nothing at all (the target untouched).
//!
//! Invariants:
//! * the temporary is created exclusively (`O_CREAT|O_EXCL`, so a planted file or symlink at
//!   its name is never opened or followed) under an unpredictable name `.NAME.XXXXXX.tmp` in
//!   the target's directory, by the `tempfile` crate;
//! * it is flushed and `fsync`ed, then renamed over the target (a symlink at the target is
//!   replaced, not followed), and the directory is `fsync`ed;
//! * temporaries in flight are registered, so the binary's SIGINT/SIGTERM handler can remove
//!   them ([`remove_registered_temporaries`]) before it exits;
//! * [`check_outputs`] refuses, before any work, outputs that clash with an input or with each
//!   other, that are directories or other non-regular files, or whose directory is missing or
//!   not writable.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// An output file that could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error("{}: cannot write: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: refusing to overwrite the input mesh; choose another output path", path.display())]
    WouldOverwriteInput { path: PathBuf },
    #[error("{}: {what}", path.display())]
    Unsupported { path: PathBuf, what: String },
    #[error("{}: {what}", path.display())]
    Refused { path: PathBuf, what: String },
}

/// Temporaries being written (see [`remove_registered_temporaries`]).
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn registry() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    // A panic while the lock was held leaves the list itself intact.
    TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner())
}

fn unregister(path: &Path) {
    let mut list = registry();
    if let Some(i) = list.iter().position(|p| p == path) {
        list.swap_remove(i);
    }
}

/// Remove every temporary output file still being written, and return how many there were.
/// Meant for a signal handler thread (not an async-signal handler: it takes a lock) that
/// exits the process right after; the lock is kept, so no rename can start afterwards.
pub fn remove_registered_temporaries() -> usize {
    let list = registry();
    for p in list.iter() {
        let _ = std::fs::remove_file(p);
    }
    let n = list.len();
    // Keep the guard: the process is about to exit and no write may finish after this.
    std::mem::forget(list);
    n
}

/// Whether two paths name the same file (the output need not exist yet).
fn same_file(a: &Path, b: &Path) -> bool {
    let canon = |p: &Path| -> Option<PathBuf> {
        if let Ok(c) = p.canonicalize() {
            return Some(c);
        }
        let parent = p
            .parent()
            .filter(|q| !q.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        Some(parent.canonicalize().ok()?.join(p.file_name()?))
    };
    match (canon(a), canon(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

/// The directory a file `path` goes into.
fn directory_of(path: &Path) -> &Path {
    path.parent()
        .filter(|q| !q.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
}

/// A new temporary `.NAME.XXXXXXXX.tmp` in `dir`, created exclusively.
fn create_temp(name: &std::ffi::OsStr, dir: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let prefix = format!(".{}.", name.to_string_lossy());
    let mut b = tempfile::Builder::new();
    b.prefix(&prefix).suffix(".tmp").rand_bytes(8);
    // Same mode as `File::create` (0666 less the umask), not tempfile's private 0600.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        b.permissions(std::fs::Permissions::from_mode(0o666));
    }
    b.tempfile_in(dir)
}

/// Check output paths before any work: each must be a file name in an existing, writable
/// directory, not an existing directory or special file, not one of `inputs`, and no two
/// outputs may name the same file.
pub fn check_outputs(outputs: &[&Path], inputs: &[&Path]) -> Result<(), WriteError> {
    for (i, &out) in outputs.iter().enumerate() {
        let refused = |what: String| WriteError::Refused {
            path: out.to_owned(),
            what,
        };
        if let Some(k) = inputs.iter().position(|i| same_file(i, out)) {
            let input = inputs[k];
            // The mesh itself gets the message `curve` always gave; other inputs are named.
            return Err(if k == 0 {
                WriteError::WouldOverwriteInput {
                    path: out.to_owned(),
                }
            } else {
                refused(format!(
                    "refusing to overwrite the input {}; choose another output path",
                    input.display()
                ))
            });
        }
        if let Some(other) = outputs[..i].iter().find(|o| same_file(o, out)) {
            return Err(refused(format!(
                "names the same file as the output {}; give each output its own path",
                other.display()
            )));
        }
        let Some(name) = out.file_name() else {
            return Err(refused("not a file name".into()));
        };
        match std::fs::metadata(out) {
            Ok(m) if m.is_dir() => return Err(refused("cannot write: is a directory".into())),
            Ok(m) if !m.is_file() => {
                return Err(refused(
                    "cannot write: exists and is not a regular file".into(),
                ));
            }
            _ => {}
        }
        let dir = directory_of(out);
        if !dir.is_dir() {
            return Err(refused(format!(
                "cannot write: directory {} does not exist",
                dir.display()
            )));
        }
        // A probe temporary proves the directory writable now rather than after the work.
        create_temp(name, dir).map_err(|e| {
            refused(format!(
                "cannot write: cannot create a file in {}: {e}",
                dir.display()
            ))
        })?;
    }
    Ok(())
}

/// A complete, synced temporary file waiting to be renamed over its target by
/// [`PendingFile::commit`]; dropped uncommitted, it is removed.
pub struct PendingFile {
    path: PathBuf,
    /// `None` once committed.
    temp: Option<tempfile::TempPath>,
}

impl PendingFile {
    /// The target path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The temporary holding the content until [`PendingFile::commit`] (other processes of
    /// a job write their parts of it by offset).
    pub fn temp_path(&self) -> Option<&Path> {
        self.temp.as_deref()
    }

    /// Rename the temporary over the target and sync the directory.
    pub fn commit(mut self) -> Result<(), WriteError> {
        let path = self.path.clone();
        let temp = self.temp.take().expect("a pending file is committed once");
        let temp_path = temp.to_path_buf();
        // Hold the registry lock across the rename, so a signal handler either removes the
        // temporary before it is renamed or runs after the target is complete.
        let mut list = registry();
        let result = temp.persist(&path);
        if let Some(i) = list.iter().position(|p| p == &temp_path) {
            list.swap_remove(i);
        }
        drop(list);
        result.map_err(|e| WriteError::Io {
            path: path.clone(),
            source: e.error,
        })?;
        #[cfg(unix)]
        if let Ok(dir) = File::open(directory_of(&path)) {
            let _ = dir.sync_all();
        }
        Ok(())
    }
}

impl Drop for PendingFile {
    fn drop(&mut self) {
        if let Some(temp) = self.temp.take() {
            // Remove before unregistering, so a signal in between still finds it.
            let p = temp.to_path_buf();
            drop(temp);
            unregister(&p);
        }
    }
}

/// Write the content of `path` through `body` into a new temporary beside it, flushed and
/// synced, without touching `path` yet. Refuses when `path` is one of `inputs`.
pub fn prepare(
    path: &Path,
    inputs: &[&Path],
    body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<PendingFile, WriteError> {
    if inputs.iter().any(|i| same_file(i, path)) {
        return Err(WriteError::WouldOverwriteInput {
            path: path.to_owned(),
        });
    }
    let io = |source| WriteError::Io {
        path: path.to_owned(),
        source,
    };
    let name = path.file_name().ok_or_else(|| {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a file name",
        ))
    })?;
    let dir = directory_of(path);
    let mut list = registry();
    let temp = create_temp(name, dir).map_err(io)?;
    list.push(temp.path().to_owned());
    drop(list);
    let (file, temp) = temp.into_parts();
    let pending = PendingFile {
        path: path.to_owned(),
        temp: Some(temp),
    };
    let result = (|| {
        let mut w = BufWriter::with_capacity(1 << 20, file);
        body(&mut w)?;
        let file = w.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()
    })();
    // On error `pending` is dropped here, which removes the temporary.
    result.map_err(io)?;
    Ok(pending)
}

/// Write `path` through `body`, atomically: [`prepare`] then [`PendingFile::commit`].
pub fn write_atomically(
    path: &Path,
    inputs: &[&Path],
    body: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    prepare(path, inputs, body)?.commit()
}

/// Little helpers for binary output.
pub(crate) trait WriteBin: Write {
    fn i32(&mut self, v: i32) -> std::io::Result<()> {
        self.write_all(&v.to_le_bytes())
    }
    fn u64(&mut self, v: u64) -> std::io::Result<()> {
        self.write_all(&v.to_le_bytes())
    }
    fn f64(&mut self, v: f64) -> std::io::Result<()> {
        self.write_all(&v.to_le_bytes())
    }
}

impl<W: Write> WriteBin for W {}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn a_symlink_at_a_guessable_temporary_name_is_not_followed() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.msh");
        std::fs::write(&input, b"input").unwrap();
        let out = dir.path().join("out.msh");
        // The old fixed name; every name a writer could use is covered by O_EXCL anyway.
        let planted = dir
            .path()
            .join(format!(".out.msh.{}.tmp", std::process::id()));
        std::os::unix::fs::symlink(&input, &planted).unwrap();
        write_atomically(&out, &[&input], |w| w.write_all(b"output")).unwrap();
        assert_eq!(std::fs::read(&input).unwrap(), b"input");
        assert_eq!(std::fs::read(&out).unwrap(), b"output");
        assert!(!std::fs::symlink_metadata(&out).unwrap().is_symlink());
        // Only the planted link and the two files remain: no temporary left behind.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
    }

    #[test]
    fn a_failed_body_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out.msh");
        let e = write_atomically(&out, &[], |_| Err(std::io::Error::other("boom")));
        assert!(e.is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        assert!(registry().is_empty() || !registry().iter().any(|p| p.starts_with(dir.path())));
    }

    #[test]
    fn a_failing_second_output_leaves_neither() {
        // The `curve --report` order: the mesh is complete on disk, then the report fails
        // (a full disk): the mesh's temporary goes away and neither target appears.
        let dir = tempfile::tempdir().unwrap();
        let mesh = dir.path().join("m.msh");
        let report = dir.path().join("r.json");
        let pending = prepare(&mesh, &[], |w| w.write_all(b"mesh")).unwrap();
        let full = std::io::Error::from_raw_os_error(28); // ENOSPC
        let e = prepare(&report, &[], |_| Err(full)).err().unwrap();
        assert!(e.to_string().contains("r.json"), "{e}");
        drop(pending);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn clashing_outputs_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.msh");
        std::fs::write(&input, b"input").unwrap();
        let a = dir.path().join("a.msh");
        let e = check_outputs(&[&a, &a], &[&input]).unwrap_err().to_string();
        assert!(e.contains("same file"), "{e}");
        let e = check_outputs(&[&input], &[&input]).unwrap_err().to_string();
        assert!(e.contains("input"), "{e}");
        let missing = dir.path().join("nodir/r.json");
        let e = check_outputs(&[&missing], &[&input])
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not exist"), "{e}");
        let e = check_outputs(&[dir.path()], &[&input])
            .unwrap_err()
            .to_string();
        assert!(e.contains("directory"), "{e}");
        check_outputs(&[&a, &dir.path().join("r.json")], &[&input]).unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
