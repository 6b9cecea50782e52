//! Opening input files without hanging or reading without bound.
//!
//! Input: a path named on the command line (a mesh, an overlay, a feature edits file).
//! Output: the file's bytes, or an [`std::io::Error`] saying why not.
//!
//! Invariants:
//! * only regular files are read: a FIFO, socket, character or block device or directory is
//!   refused at once, before any byte is read. The file is opened with `O_NONBLOCK`, so
//!   opening a FIFO that has no writer returns instead of blocking forever, and `fstat` of the
//!   open descriptor (not of the path, which could change in between) decides;
//! * at most the size `fstat` reported is read (a file growing while it is read is cut at
//!   that size), and the buffer is allocated once at that size, so reading never allocates
//!   more than the file holds.

use std::fs::{File, OpenOptions};
use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// What kind of non-regular file `meta` describes, for messages.
fn kind_name(meta: &std::fs::Metadata) -> &'static str {
    let ft = meta.file_type();
    if ft.is_dir() {
        return "a directory";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return "a FIFO";
        }
        if ft.is_char_device() {
            return "a character device";
        }
        if ft.is_block_device() {
            return "a block device";
        }
        if ft.is_socket() {
            return "a socket";
        }
    }
    "not a regular file"
}

/// Open `path` for reading if it is a regular file; never blocks on a FIFO.
pub fn open_regular(path: &Path) -> std::io::Result<(File, u64)> {
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!("{} is not a regular file", kind_name(&meta)),
        ));
    }
    Ok((file, meta.len()))
}

/// Read a whole regular file (see the module documentation).
pub fn read_regular(path: &Path) -> std::io::Result<Vec<u8>> {
    let (file, len) = open_regular(path)?;
    let cap = usize::try_from(len)
        .map_err(|_| Error::new(ErrorKind::OutOfMemory, "file too large to read"))?;
    let mut data = Vec::new();
    data.try_reserve_exact(cap).map_err(|_| {
        Error::new(
            ErrorKind::OutOfMemory,
            format!("cannot allocate {len} bytes to read the file"),
        )
    })?;
    file.take(len).read_to_end(&mut data)?;
    Ok(data)
}

/// [`read_regular`] as UTF-8 text.
pub fn read_regular_text(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_regular(path)?).map_err(|e| {
        Error::new(
            ErrorKind::InvalidData,
            format!("not UTF-8 text: {}", e.utf8_error()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_read_and_others_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        std::fs::write(&p, b"hello").unwrap();
        assert_eq!(read_regular(&p).unwrap(), b"hello");
        let e = read_regular(dir.path()).unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
        #[cfg(unix)]
        {
            let e = read_regular(Path::new("/dev/zero")).unwrap_err();
            assert!(e.to_string().contains("character device"), "{e}");
        }
    }
}
