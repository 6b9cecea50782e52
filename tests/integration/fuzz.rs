//! In-tree mutation fuzzing of every reader, on a fixed seed and a bounded case count, so it
//! runs in CI like any test (the `fuzz/` directory has the coverage-guided cargo-fuzz targets).
//!
//! Corpus: every fixture under `tests/data/` in a format polyspline reads. Each case applies
//! one to four random mutations (bit flips, bytes set to boundary values, ranges deleted,
//! duplicated or moved, numbers replaced by huge, negative or non-finite ones, truncation, and
//! 32/64-bit integers overwritten in binary files) and runs the reader; what it accepts goes on
//! through `LinearMesh::from_raw`, the topology and the curvability check.
//!
//! Properties asserted per case: no panic; the reader's peak heap allocation is at most
//! [`bytes_allowed`] (proportional to the file's size: nothing is allocated from a count the
//! file cannot back); every error message is one line of bounded length.
//!
//! `POLYSPLINE_FUZZ_CASES` sets the cases per fixture (default 4000), `POLYSPLINE_FUZZ_SEED` the
//! seed (default fixed); a failure prints both and the fixture, so it can be replayed.

use polyspline::io::Format;
use polyspline::mesh::{LinearMesh, MeshOptions, Topology};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Heap use of the current thread: bytes live now and the peak since the last reset.
struct Counting;

thread_local! {
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

fn note(delta: isize) {
    // `try_with`: allocations during thread teardown are not counted.
    let _ = LIVE.try_with(|l| {
        let now = l.get() + delta;
        l.set(now);
        let _ = PEAK.try_with(|p| {
            if now > p.get() {
                p.set(now)
            }
        });
    });
}

// SAFETY: every method forwards to the system allocator with the caller's arguments (so the
// caller's guarantees carry over) and only counts bytes beside it.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's guarantees for this method are those of `System`'s.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            note(layout.size() as isize);
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's guarantees for this method are those of `System`'s.
        unsafe { System.dealloc(ptr, layout) };
        note(-(layout.size() as isize));
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's guarantees for this method are those of `System`'s.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            note(layout.size() as isize);
        }
        p
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller's guarantees for this method are those of `System`'s.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            note(new_size as isize - layout.size() as isize);
        }
        p
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

/// Run `f` and return its result and the peak heap bytes it added on this thread.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.with(|l| l.get());
    PEAK.with(|p| p.set(base));
    let out = f();
    let peak = PEAK.with(|p| p.get()) - base;
    (out, peak.max(0) as usize)
}

/// Bytes per input byte a reader may allocate: every point or cell needs a few bytes of file
/// and becomes at most a few dozen bytes in memory, doubled by vector growth.
const PER_BYTE: usize = 200;

/// The constant on top, for small files: tables and one decompression state. The largest
/// allocation beyond [`PER_BYTE`] seen over the fuzz cases (printed by
/// [`every_reader_survives_mutated_fixtures`]) is about 1.8 kB; 64 KiB also holds a zlib
/// inflate state and its 32 KiB window for a file too small to pay for them.
const FLOOR: usize = 64 << 10;

/// What a reader may allocate for a file of `len` bytes.
fn bytes_allowed(len: usize) -> usize {
    PER_BYTE * len + FLOOR
}

/// xorshift64*: small, fast and the same on every platform.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const NUMBERS: [&str; 14] = [
    "0",
    "-1",
    "1000000000000",
    "4294967295",
    "4294967296",
    "2147483648",
    "18446744073709551616",
    "99999999999999999999999",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "1e154",
    "3.5",
];

const INTS: [u64; 9] = [
    0,
    1,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
    1 << 40,
    u64::MAX,
    0x7fff_ffff_ffff_ffff,
    1_000_000_000_000,
];

fn mutate(data: &mut Vec<u8>, rng: &mut Rng) {
    let n = data.len();
    if n == 0 {
        data.extend_from_slice(b"0");
        return;
    }
    match rng.below(10) {
        0 => {
            let i = rng.below(n);
            data[i] ^= 1 << rng.below(8);
        }
        1 => {
            let i = rng.below(n);
            data[i] = [0u8, 0xff, b'\n', b' ', b'-', b'9', b'"', b'<', b'$', 0x7f][rng.below(10)];
        }
        2 => {
            let i = rng.below(n);
            let len = 1 + rng.below((n - i).min(64));
            data.drain(i..i + len);
        }
        3 => {
            let i = rng.below(n);
            let len = 1 + rng.below((n - i).min(256));
            let chunk = data[i..i + len].to_vec();
            let at = rng.below(n);
            data.splice(at..at, chunk);
        }
        4 => data.truncate(rng.below(n)),
        5 | 6 => {
            // Replace a run of digits (a count, an index, a coordinate) with a hostile number.
            let start = rng.below(n);
            if let Some(off) = data[start..].iter().position(|b| b.is_ascii_digit()) {
                let i = start + off;
                let mut j = i;
                while j < n && (data[j].is_ascii_digit() || data[j] == b'.') {
                    j += 1;
                }
                let num = NUMBERS[rng.below(NUMBERS.len())].as_bytes();
                data.splice(i..j, num.iter().copied());
            } else {
                data[start] ^= 0x20;
            }
        }
        7 | 8 => {
            // A binary count or offset: overwrite 4 or 8 aligned bytes with a boundary value.
            let width = if rng.below(2) == 0 { 4 } else { 8 };
            if n >= width {
                let i = rng.below(n - width + 1) & !(width - 1);
                let v = INTS[rng.below(INTS.len())];
                let bytes = if rng.below(2) == 0 {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                };
                let src = if rng.below(2) == 0 {
                    &bytes[..width]
                } else {
                    &bytes[8 - width..]
                };
                data[i..i + width].copy_from_slice(src);
            }
        }
        _ => {
            // A long token or line: readers must not echo it whole.
            let at = rng.below(n);
            let fill = vec![b"ax\n"[rng.below(3)]; 1 + rng.below(5000)];
            data.splice(at..at, fill);
        }
    }
}

fn corpus() -> Vec<(PathBuf, Format, Vec<u8>)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let mut out = Vec::new();
    let mut dirs: Vec<_> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    dirs.sort();
    for dir in dirs.iter().filter(|d| d.is_dir()) {
        let mut files: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        files.sort();
        // Sub-folders (e.g. the malformed CGNS fixtures) hold deliberately broken files of
        // their own tests, not seeds.
        for f in files.into_iter().filter(|f| f.is_file()) {
            let data = std::fs::read(&f).unwrap();
            if let Some(format) = Format::detect(&f, &data[..data.len().min(64)]) {
                out.push((f, format, data));
            }
        }
    }
    out
}

fn check_message(msg: &str, context: &str) {
    assert!(
        !msg.contains('\n') && !msg.contains('\r'),
        "{context}: message of several lines: {msg:?}"
    );
    assert!(
        msg.chars().count() <= polyspline::mesh::raw::MAX_MESSAGE_CHARS + 40,
        "{context}: message of {} characters",
        msg.chars().count()
    );
}

/// Run one input through a reader and the checks after it; returns whether it was accepted
/// and the reader's peak heap allocation.
fn run_case(format: Format, data: &[u8], context: &str) -> (bool, usize) {
    let t = Instant::now();
    let (parsed, peak) = peak_of(|| format.parse(data));
    assert!(
        peak <= bytes_allowed(data.len()),
        "{context}: the reader allocated {peak} bytes for a file of {} bytes",
        data.len()
    );
    let accepted = match parsed {
        Err(e) => {
            check_message(&e.message, context);
            false
        }
        Ok(raw) => match LinearMesh::from_raw(raw, &MeshOptions::default()) {
            Err(e) => {
                check_message(&e.message, context);
                false
            }
            Ok(mesh) => {
                let topo = Topology::build(&mesh);
                if let Err(e) = polyspline::mesh::manifold::check_curvable(&mesh, &topo) {
                    assert!(!e.contains('\n'), "{context}: {e:?}");
                }
                true
            }
        },
    };
    assert!(
        t.elapsed() < Duration::from_secs(10),
        "{context}: took {:?}",
        t.elapsed()
    );
    (accepted, peak)
}

#[test]
fn every_reader_survives_mutated_fixtures() {
    let cases: usize = std::env::var("POLYSPLINE_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4000);
    let seed: u64 = std::env::var("POLYSPLINE_FUZZ_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0x5eed_2026);
    let corpus = corpus();
    let formats: std::collections::BTreeSet<String> =
        corpus.iter().map(|(_, f, _)| format!("{f:?}")).collect();
    assert_eq!(formats.len(), 10, "fixtures of every format: {formats:?}");
    let start = Instant::now();
    let (mut total, mut accepted) = (0usize, 0usize);
    // Largest peak allocation per byte of input, over the cases of at least 1 kB.
    let mut ratio: f64 = 0.0;
    // Largest allocation beyond PER_BYTE per input byte (what FLOOR must cover).
    let mut floor = 0usize;
    for (k, (path, format, original)) in corpus.iter().enumerate() {
        // Some fixtures are meant to be refused (tetrahedra, high-order cells); all must run.
        run_case(*format, original, &path.display().to_string());
        let mut rng = Rng(seed ^ (k as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15));
        for case in 0..cases {
            let mut data = original.clone();
            for _ in 0..1 + rng.below(4) {
                mutate(&mut data, &mut rng);
            }
            let context = format!(
                "{} case {case} (POLYSPLINE_FUZZ_SEED={seed})",
                path.display()
            );
            let result = std::panic::catch_unwind(|| run_case(*format, &data, &context));
            match result {
                Ok((a, peak)) => {
                    accepted += a as usize;
                    floor = floor.max(peak.saturating_sub(PER_BYTE * data.len()));
                    if data.len() >= 1024 {
                        ratio = ratio.max(peak as f64 / data.len() as f64);
                    }
                }
                Err(_) => {
                    let dump = std::env::temp_dir().join("polyspline-fuzz-failure");
                    let _ = std::fs::write(&dump, &data);
                    panic!("{context}: panicked; input saved to {}", dump.display());
                }
            }
            total += 1;
        }
    }
    eprintln!(
        "fuzz: {total} mutated cases over {} fixtures of {} formats, {accepted} accepted, peak reader allocation at most {ratio:.1} bytes per input byte, at most {floor} bytes beyond {PER_BYTE} per byte (floor {FLOOR}), {:.1} s",
        corpus.len(),
        formats.len(),
        start.elapsed().as_secs_f64()
    );
}

/// A tiny file claiming 10^12 nodes (or cells) fails at once, naming the count, without
/// allocating for it.
#[test]
fn huge_counts_in_tiny_files_fail_fast() {
    let cases: [(&str, Format, &str); 8] = [
        (
            "gmsh 2.2",
            Format::Gmsh,
            "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1000000000000\n1 0 0 0\n$EndNodes\n",
        ),
        (
            "gmsh 4.1",
            Format::Gmsh,
            "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 1000000000000 1 1000000000000\n2 1 0 1000000000000\n1\n0 0 0\n$EndNodes\n",
        ),
        (
            "medit",
            Format::Medit,
            "MeshVersionFormatted 2\nDimension 3\nVertices\n1000000000000\n0 0 0 0\nEnd\n",
        ),
        (
            "mfem",
            Format::Mfem,
            "MFEM mesh v1.0\n\ndimension\n2\n\nelements\n1000000000000\n1 3 0 1 2 3\n",
        ),
        (
            "vtk",
            Format::Vtk,
            "# vtk DataFile Version 4.2\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 1000000000000 double\n0 0 0\n",
        ),
        (
            "vtu",
            Format::Vtu,
            "<VTKFile type=\"UnstructuredGrid\"><UnstructuredGrid><Piece NumberOfPoints=\"1000000000000\" NumberOfCells=\"1000000000000\"><Points><DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">0 0 0</DataArray></Points></Piece></UnstructuredGrid></VTKFile>",
        ),
        (
            "su2",
            Format::Su2,
            "NDIME= 2\nNPOIN= 1000000000000\n0 0 0\n",
        ),
        (
            "abaqus",
            Format::Abaqus,
            "*NODE\n1000000000000, 0, 0\n*ELEMENT, TYPE=CPS4\n1, 1000000000000, 2, 3, 4\n",
        ),
    ];
    for (name, format, text) in cases {
        let t = Instant::now();
        let (result, peak) = peak_of(|| format.parse(text.as_bytes()));
        let elapsed = t.elapsed();
        let accepted_then =
            result.and_then(|raw| LinearMesh::from_raw(raw, &MeshOptions::default()).map(|_| ()));
        let e = accepted_then.expect_err(name);
        assert!(peak < 1 << 20, "{name}: allocated {peak} bytes");
        assert!(elapsed < Duration::from_millis(500), "{name}: {elapsed:?}");
        check_message(&e.message, name);
    }
    // Exodus: a netCDF dimension of 2^31 - 1 nodes in the two-hex fixture.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/exodus/two_hex_classic.exo");
    let data = std::fs::read(&path).unwrap();
    let name = b"num_nodes";
    let at = data
        .windows(name.len())
        .position(|w| w == name)
        .expect("num_nodes dimension");
    // Name is padded to 4 bytes, then the 32-bit big-endian length.
    let len_at = at + name.len().div_ceil(4) * 4;
    let mut bad = data.clone();
    bad[len_at..len_at + 4].copy_from_slice(&0x7fff_ffffu32.to_be_bytes());
    let (result, peak) = peak_of(|| Format::Exodus.parse(&bad));
    assert!(result.is_err(), "exodus with 2^31 - 1 nodes accepted");
    assert!(
        peak < bytes_allowed(bad.len()),
        "exodus: allocated {peak} bytes"
    );
}

/// A zlib bomb in a VTU file (64 MiB of zeros in 65 kB) is refused; what it costs is bounded by
/// deflate's largest expansion (1032:1), not by what the header claims.
#[test]
fn a_zlib_bomb_costs_at_most_the_deflate_ratio() {
    use std::io::Write;
    let raw = vec![0u8; 64 << 20];
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&raw).unwrap();
    let comp = z.finish().unwrap();
    let mut data = br#"<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian" header_type="UInt32" compressor="vtkZLibDataCompressor">
<UnstructuredGrid><Piece NumberOfPoints="1" NumberOfCells="1"><Points>
<DataArray type="Float64" NumberOfComponents="3" format="appended" offset="0"/></Points>
<Cells><DataArray type="Int64" Name="connectivity" format="ascii">0 0 0 0</DataArray>
<DataArray type="Int64" Name="offsets" format="ascii">4</DataArray>
<DataArray type="UInt8" Name="types" format="ascii">9</DataArray></Cells>
</Piece></UnstructuredGrid><AppendedData encoding="raw">_"#
        .to_vec();
    for w in [1u32, raw.len() as u32, raw.len() as u32, comp.len() as u32] {
        data.extend_from_slice(&w.to_le_bytes());
    }
    data.extend_from_slice(&comp);
    data.extend_from_slice(b"</AppendedData></VTKFile>");
    drop(raw);
    let (result, peak) = peak_of(|| Format::Vtu.parse(&data));
    let e = result.expect_err("a bomb is not a mesh");
    check_message(&e.message, "zlib bomb");
    assert!(
        // The decompressed bytes and the values decoded from them: twice deflate's ratio.
        peak <= 2 * 1040 * data.len() + FLOOR,
        "allocated {peak} bytes for {} bytes",
        data.len()
    );
}
