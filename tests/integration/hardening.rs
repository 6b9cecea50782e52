//! Hostile use outside the readers (issue 18): special files as inputs, absurd option values,
//! clashing outputs, planted temporaries, signals during a write, messages quoting hostile
//! input, and meshes `curve` cannot treat. Each case gets one bounded error line and exit 1
//! (or 128 + the signal), fast, and no file is damaged or left behind.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_polyspline"))
}

/// A fresh empty directory for one test.
fn dir(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("hardening")
        .join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Run with a deadline: a hang fails the test instead of blocking it.
fn run(cmd: &mut Command, limit: Duration) -> Output {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "still running after {limit:?}; stderr: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Expect exit 1 with one error line on stderr, quickly; return the line.
fn fails(cmd: &mut Command) -> String {
    let out = run(cmd, Duration::from_secs(20));
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "one line: {stderr:?}");
    assert!(stderr.starts_with("polyspline: error: "), "{stderr}");
    assert!(stderr.len() < 2200, "bounded: {} bytes", stderr.len());
    stderr
}

fn files_in(d: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Two unit squares side by side (SU2, 2D).
const TWO_QUADS: &str = "NDIME= 2\nNELEM= 2\n9 0 1 4 3 0\n9 1 2 5 4 1\nNPOIN= 6\n0 0 0\n1 0 1\n2 0 2\n0 1 3\n1 1 4\n2 1 5\nNMARK= 0\n";

fn two_quads(d: &Path) -> PathBuf {
    let p = d.join("in.su2");
    std::fs::write(&p, TWO_QUADS).unwrap();
    p
}

#[cfg(unix)]
#[test]
fn special_files_are_refused_at_once() {
    let d = dir("special");
    let fifo = d.join("f.msh");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let e = fails(bin().arg("info").arg(&fifo));
    assert!(e.contains("FIFO") && e.contains("f.msh"), "{e}");
    let e = fails(bin().arg("info").arg("/dev/zero"));
    assert!(e.contains("character device"), "{e}");
    let e = fails(bin().arg("info").arg("/dev/urandom"));
    assert!(e.contains("character device"), "{e}");
    let e = fails(bin().arg("info").arg(&d));
    assert!(e.contains("directory"), "{e}");
    let input = two_quads(&d);
    let e = fails(
        bin()
            .arg("info")
            .arg(&input)
            .args(["--feature-edits", "/dev/zero"]),
    );
    assert!(e.contains("character device"), "{e}");
    let e = fails(
        bin()
            .arg("curve")
            .arg(&input)
            .arg("-o")
            .arg(d.join("o.msh"))
            .arg("--feature-edits")
            .arg(&fifo),
    );
    assert!(e.contains("FIFO"), "{e}");
}

#[test]
fn generate_refuses_element_counts_out_of_range() {
    let d = dir("generate");
    for n in ["0", "100000000", "1000000000000"] {
        let e = fails(
            bin()
                .args(["generate", "torus", "--elements", n, "-o"])
                .arg(d.join("t.msh")),
        );
        assert!(e.contains("--elements") && e.contains(n), "{e}");
    }
    assert!(files_in(&d).is_empty());
}

/// `--demote-uncertified` redoes the least-squares spline pass: where the job has none it is
/// refused in one line, before any output is written.
#[test]
fn demote_uncertified_is_refused_where_no_fit_runs() {
    let d = dir("demote");
    let input = two_quads(&d);
    for extra in [
        &["--straight"][..],
        &["--fit", "none"],
        &["--fit", "energy"],
        &["--method", "elastic"],
    ] {
        let e = fails(
            bin()
                .arg("curve")
                .arg(&input)
                .arg("-o")
                .arg(d.join("out.msh"))
                .arg("--demote-uncertified")
                .args(extra),
        );
        assert!(e.contains("--demote-uncertified"), "{extra:?}: {e}");
    }
    assert!(!d.join("out.msh").exists());
}

/// An option given where the job cannot use it is refused in one line naming it (and no file
/// is written), never ignored: every group of the table in `cli::curve`, and the same options
/// where they do apply run.
#[test]
fn options_that_cannot_apply_are_refused_by_name() {
    let d = dir("inapplicable");
    let input = two_quads(&d);
    let refused: &[(&[&str], &str, &[&str])] = &[
        (
            &["--straight", "--snap-boundary"],
            "msh",
            &["--snap-boundary"],
        ),
        (
            &["--straight", "--knot-intervals", "graded"],
            "msh",
            &["--knot-intervals"],
        ),
        (
            &["--straight", "--feature-angle", "20"],
            "msh",
            &["--feature-angle"],
        ),
        (
            &["--straight", "--max-bisections", "3"],
            "msh",
            &["--max-bisections"],
        ),
        (&["--straight", "--w-corner", "5"], "msh", &["--w-corner"]),
        (
            &["--fit", "none", "--w-corner", "5", "--fit-solver", "cg"],
            "msh",
            &["--w-corner", "--fit-solver"],
        ),
        (&["--fit", "none", "--cg-tol", "1e-8"], "msh", &["--cg-tol"]),
        (
            &["--fit-solver", "cholesky", "--cg-preconditioner", "jacobi"],
            "msh",
            &["--cg-preconditioner"],
        ),
        (
            &["--fit", "position", "--kink-angle", "20"],
            "msh",
            &["--kink-angle"],
        ),
        (
            &["--knot-intervals", "uniform", "--knot-max-ratio", "3"],
            "msh",
            &["--knot-max-ratio"],
        ),
        (
            &["--young", "3", "--poisson", "0.3"],
            "msh",
            &["--young", "--poisson"],
        ),
        (
            &[
                "--method",
                "elastic",
                "--elastic-solver",
                "cholesky",
                "--elastic-preconditioner",
                "jacobi",
            ],
            "msh",
            &["--elastic-preconditioner"],
        ),
        (&["--energy-weight", "2"], "msh", &["--energy-weight"]),
        (
            &["--fit", "energy", "--energy-sweep-tol", "0.1"],
            "msh",
            &["--energy-sweep-tol"],
        ),
        (
            &["--backend", "cpu", "--precision", "f32"],
            "msh",
            &["--precision"],
        ),
        (
            &["--binary", "--msh-version", "2.2"],
            "vtu",
            &["--binary", "--msh-version"],
        ),
        (&["--volume-name", "v"], "vtu", &["--volume-name"]),
        (&["--vtu-encoding", "ascii"], "msh", &["--vtu-encoding"]),
    ];
    for (extra, ext, names) in refused {
        let out = d.join(format!("out.{ext}"));
        let e = fails(
            bin()
                .arg("curve")
                .arg(&input)
                .arg("-o")
                .arg(&out)
                .args(*extra),
        );
        assert!(e.contains("not apply to this job"), "{extra:?}: {e}");
        for n in *names {
            assert!(e.contains(n), "{extra:?}: {e} names no {n}");
        }
        assert!(!out.exists(), "{extra:?}: wrote {}", out.display());
    }
    // `generate` too: binary is an MSH option.
    let out = d.join("g.vtu");
    let e = fails(
        bin()
            .args(["generate", "disc", "--elements", "50", "--binary", "-o"])
            .arg(&out),
    );
    assert!(e.contains("--binary"), "{e}");
    assert!(!out.exists());
    // Where they apply, the same options run.
    let applies: &[(&[&str], &str)] = &[
        (
            &[
                "--method",
                "elastic",
                "--young",
                "3",
                "--snap-boundary",
                "--w-corner",
                "4",
            ],
            "msh",
        ),
        (
            &[
                "--fit",
                "energy",
                "--energy-solver",
                "colored",
                "--energy-sweep-tol",
                "0.1",
            ],
            "msh",
        ),
        (
            &[
                "--method",
                "elastic",
                "--fit-solver",
                "cholesky",
                "--cg-tol",
                "1e-7",
            ],
            "msh",
        ),
        (
            &[
                "--knot-intervals",
                "graded",
                "--knot-max-ratio",
                "3",
                "--kink-angle",
                "20",
            ],
            "msh",
        ),
        (
            &["--binary", "--msh-version", "2.2", "--volume-name", "v"],
            "msh",
        ),
        (&["--vtu-encoding", "ascii"], "vtu"),
        (&["--straight", "--order", "3"], "msh"),
    ];
    for (extra, ext) in applies {
        let out = d.join(format!("ok.{ext}"));
        let o = run(
            bin()
                .arg("curve")
                .arg("-q")
                .arg(&input)
                .arg("-o")
                .arg(&out)
                .args(*extra),
            Duration::from_secs(20),
        );
        assert!(
            o.status.success(),
            "{extra:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(out.exists(), "{extra:?}");
    }
}

#[test]
fn outputs_are_checked_before_any_work() {
    let d = dir("outputs");
    let input = two_quads(&d);
    let before = std::fs::read(&input).unwrap();
    // Mesh and report on one file.
    let e = fails(
        bin()
            .arg("curve")
            .arg(&input)
            .arg("-o")
            .arg(d.join("r.msh"))
            .arg("--report")
            .arg(d.join("r.msh")),
    );
    assert!(e.contains("same file"), "{e}");
    // A report in a missing directory.
    let e = fails(
        bin()
            .arg("curve")
            .arg(&input)
            .arg("-o")
            .arg(d.join("m.msh"))
            .arg("--report")
            .arg(d.join("nodir/r.json")),
    );
    assert!(e.contains("does not exist"), "{e}");
    // The report onto the input.
    let e = fails(
        bin()
            .arg("curve")
            .arg(&input)
            .arg("-o")
            .arg(d.join("m.msh"))
            .arg("--report")
            .arg(&input),
    );
    assert!(e.contains("input"), "{e}");
    // A directory as the output; an SVG onto an overlay.
    let e = fails(bin().arg("curve").arg(&input).arg("-o").arg(&d));
    assert!(e.contains("format") || e.contains("directory"), "{e}");
    let e = fails(
        bin()
            .arg("plot")
            .arg(&input)
            .arg("--overlay")
            .arg(d.join("in.su2"))
            .arg("-o")
            .arg(&input),
    );
    assert!(e.contains("input"), "{e}");
    assert_eq!(std::fs::read(&input).unwrap(), before);
    assert_eq!(files_in(&d), ["in.su2"], "nothing written");
    // The valid twin writes both.
    let out = run(
        bin()
            .arg("curve")
            .arg(&input)
            .arg("-q")
            .arg("-o")
            .arg(d.join("m.msh"))
            .arg("--report")
            .arg(d.join("r.json")),
        Duration::from_secs(60),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(files_in(&d), ["in.su2", "m.msh", "r.json"]);
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("r.json")).unwrap()).unwrap();
    assert_eq!(report["elements"], 2);
}

#[cfg(unix)]
#[test]
fn a_signal_during_the_write_leaves_no_temporary() {
    let d = dir("signal");
    let mut interrupted = 0;
    for (sig, code) in [(libc::SIGTERM, 143), (libc::SIGINT, 130)] {
        let out = d.join("big.msh");
        // Large enough that the write takes a noticeable time.
        let mut child = bin()
            .args(["generate", "torus", "--elements", "400000", "-o"])
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        let mut signalled = false;
        while start.elapsed() < Duration::from_secs(120) {
            if child.try_wait().unwrap().is_some() {
                break;
            }
            // A temporary with data in it: the write is under way (not the probe of the
            // output check, which is empty and gone at once).
            let writing = files_in(&d).iter().any(|f| {
                f.ends_with(".tmp") && std::fs::metadata(d.join(f)).is_ok_and(|m| m.len() > 1 << 20)
            });
            if writing {
                // SAFETY: a plain kill(2) of our own child.
                unsafe { libc::kill(child.id() as i32, sig) };
                signalled = true;
                break;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        let status = child.wait().unwrap();
        assert!(signalled, "the temporary never appeared");
        let mut stderr = String::new();
        std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut stderr).unwrap();
        if status.success() {
            // The write won the race; nothing to learn from this round.
            std::fs::remove_file(&out).unwrap();
            continue;
        }
        assert_eq!(status.code(), Some(code), "{stderr}");
        assert!(stderr.contains("interrupted"), "{stderr}");
        assert!(files_in(&d).is_empty(), "left behind: {:?}", files_in(&d));
        interrupted += 1;
    }
    assert!(interrupted > 0, "every write finished before the signal");
}

#[test]
fn messages_are_one_bounded_line() {
    let d = dir("messages");
    // A newline inside an XML tag name.
    let vtu = d.join("nl.vtu");
    std::fs::write(
        &vtu,
        "<VTKFile type=\"UnstructuredGrid\"><UnstructuredGrid><Piece NumberOfPoints=\"1\" NumberOfCells=\"0\"></Points\n<Cells></Piece></UnstructuredGrid></VTKFile>",
    )
    .unwrap();
    fails(bin().arg("info").arg(&vtu));
    // A 1 MB token and control bytes where a count belongs.
    let big = d.join("big.su2");
    let token = "7".repeat(1 << 20);
    std::fs::write(
        &big,
        TWO_QUADS.replace("NELEM= 2", &format!("NELEM= x{token}")),
    )
    .unwrap();
    let e = fails(bin().arg("info").arg(&big));
    assert!(e.len() < 1000, "{} bytes", e.len());
    let ctl = d.join("ctl.su2");
    std::fs::write(&ctl, TWO_QUADS.replace("NELEM= 2", "NELEM= \x1b[2J\x07")).unwrap();
    let e = fails(bin().arg("info").arg(&ctl));
    assert!(!e.contains('\x1b') && !e.contains('\x07'), "{e:?}");
    let input = two_quads(&d);
    let e = fails(
        bin()
            .arg("curve")
            .arg(&input)
            .arg("-o")
            .arg(d.join("o.msh"))
            .args(["--order", "1", "--subdivide", "0"]),
    );
    assert!(e.contains("--subdivide 0"), "{e}");
    let e = fails(
        bin()
            .arg("curve")
            .arg(&input)
            .arg("-o")
            .arg(d.join("o.msh"))
            .args(["--w-corner", "1e308"]),
    );
    assert!(e.contains("--w-corner"), "{e}");
    // Scaled by 1e154: out of range, not "degenerate".
    let scaled = d.join("scaled.su2");
    let mut text = String::new();
    for line in TWO_QUADS.lines() {
        let w: Vec<&str> = line.split(' ').collect();
        if w.len() == 3 && !line.contains('=') {
            text.push_str(&format!("{}e154 {}e154 {}\n", w[0], w[1], w[2]));
        } else {
            text.push_str(line);
            text.push('\n');
        }
    }
    std::fs::write(&scaled, text).unwrap();
    let e = fails(bin().arg("info").arg(&scaled));
    assert!(
        e.contains("out of range") && !e.contains("degenerate"),
        "{e}"
    );
    assert_eq!(files_in(&d).len(), 5, "nothing written: {:?}", files_in(&d));
}

#[test]
fn numeric_options_are_validated() {
    let d = dir("options");
    let input = two_quads(&d);
    let o = d.join("o.msh");
    for args in [
        &["--feature-angle", "nan"][..],
        &["--cg-tol", "nan"],
        &["--min-det-fraction", "nan"],
        &["--kink-angle", "inf"],
        &["--cg-tol=-1"],
    ] {
        let e = fails(bin().arg("curve").arg(&input).arg("-o").arg(&o).args(args));
        let option = args[0].split('=').next().unwrap();
        assert!(e.contains(option), "{args:?}: {e}");
    }
    let e = fails(
        bin()
            .arg("info")
            .arg(&input)
            .args(["--feature-angle", "nan"]),
    );
    assert!(e.contains("--feature-angle"), "{e}");
    let e = fails(
        bin()
            .arg("plot")
            .arg(&input)
            .arg("-o")
            .arg(d.join("p.svg"))
            .args(["--width", "nan"]),
    );
    assert!(e.contains("--width"), "{e}");
    let e = fails(bin().arg("compare").arg(&input).args(["--order", "0"]));
    assert!(e.contains("--order"), "{e}");
    let e = fails(bin().arg("compare").arg(&input).args(["--cg-tol", "nan"]));
    assert!(e.contains("--cg-tol"), "{e}");
    assert_eq!(files_in(&d), ["in.su2"]);
}

/// `curve` refuses what `info` lists as not a manifold mesh, naming the elements.
#[test]
fn curve_refuses_non_manifold_meshes() {
    let d = dir("topology");
    let su2 = |name: &str, dim: usize, elems: &[&str], points: &[&str]| -> PathBuf {
        let mut t = format!("NDIME= {dim}\nNELEM= {}\n", elems.len());
        for (i, e) in elems.iter().enumerate() {
            t.push_str(&format!("{e} {i}\n"));
        }
        t.push_str(&format!("NPOIN= {}\n", points.len()));
        for (i, p) in points.iter().enumerate() {
            t.push_str(&format!("{p} {i}\n"));
        }
        t.push_str("NMARK= 0\n");
        let p = d.join(name);
        std::fs::write(&p, t).unwrap();
        p
    };
    let square = ["0 0", "1 0", "2 0", "0 1", "1 1", "2 1"];
    let cases = [
        (
            su2(
                "duplicate.su2",
                2,
                &["9 0 1 4 3", "9 1 2 5 4", "9 1 2 5 4"],
                &square,
            ),
            "duplicated",
        ),
        (
            su2("doubled.su2", 2, &["9 0 1 4 3", "9 0 3 4 1"], &square),
            "duplicated",
        ),
        (
            su2(
                "bowtie.su2",
                2,
                &["9 0 1 4 3", "9 4 5 7 6"],
                &["0 0", "1 0", "0 0", "0 1", "1 1", "2 1", "1 2", "2 2"],
            ),
            "non-manifold",
        ),
        (
            su2(
                "three_hexes.su2",
                3,
                &[
                    "12 0 1 2 3 4 5 6 7",
                    "12 4 5 6 7 8 9 10 11",
                    "12 4 5 6 7 12 13 14 15",
                ],
                &[
                    "0 0 0",
                    "1 0 0",
                    "1 1 0",
                    "0 1 0",
                    "0 0 1",
                    "1 0 1",
                    "1 1 1",
                    "0 1 1",
                    "0 0 2",
                    "1 0 2",
                    "1 1 2",
                    "0 1 2",
                    "0.2 0 2.5",
                    "1.2 0 2.5",
                    "1.2 1 2.5",
                    "0.2 1 2.5",
                ],
            ),
            "shared by more than two",
        ),
    ];
    for (path, what) in cases {
        // `info` lists the mesh, `curve` refuses it.
        let out = run(bin().arg("info").arg(&path), Duration::from_secs(20));
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let listed = String::from_utf8_lossy(&out.stdout);
        let row = if what == "duplicated" {
            "duplicate elements"
        } else {
            "non-manifold"
        };
        assert!(
            listed
                .lines()
                .any(|l| l.starts_with(row) && !l.contains("none")),
            "{}: info must list it: {listed}",
            path.display()
        );
        let e = fails(
            bin()
                .arg("curve")
                .arg(&path)
                .arg("-q")
                .arg("-o")
                .arg(d.join("o.msh")),
        );
        assert!(
            e.contains(what) && e.contains("element"),
            "{}: {e}",
            path.display()
        );
    }
    assert!(!d.join("o.msh").exists());
}
