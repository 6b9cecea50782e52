#!/usr/bin/env python3
"""Scale guard: `polyspline curve` from 10k to 100k hexes (1M with --large) against a fixed
baseline build and Gmsh's straight-sided elevation of the same meshes, in one run.

usage: python3 scripts/bench_scale.py [--sizes 10000,50000,100000] [--large] [--runs 3]
                                      [--baseline COMMIT | --no-baseline] [--baseline-dir DIR]
                                      [--no-gmsh] [--python PY] [--order P] [--ascii]
                                      [--max-wall-ratio R] [--max-cpu-ratio R]
                                      [--max-rss-ratio R] [--timeout S]

Builds nothing for this checkout: run `cargo build --release` first. The baseline (default
DEFAULT_BASELINE, the commit of the 1M figures in BENCHMARKS.md) is built on first use in its
own worktree and target directory (DIR, default /tmp/polyspline-baseline-COMMIT, seeded with a
copy of this checkout's target/; see scripts/bench_real.py) and reused afterwards. Meshes are
generated into a temporary directory (`generate cylinder --elements N --binary`). For every
size, each of the three programs runs N times, interleaved (the starting program rotates per
round) so that all see the same background load: this checkout's `curve --order P --binary`,
the baseline's, and Gmsh's Python API (read + `setOrder(P)` + binary MSH write; Python from
--python, else $POLYSPLINE_PYTHON, else python3). Wall time, CPU time and peak RSS are those of
each child process (os.wait4); fit seconds and CG iterations come from the JSON report.

Prints a Markdown table of medians and the ratios current / baseline and current / Gmsh (wall,
CPU = user + system, peak RSS), and exits with status 1 when a median ratio current / baseline
exceeds --max-wall-ratio or --max-cpu-ratio (default 1.25 each: the machine is shared, single
ratios move by ±15 %) or --max-rss-ratio (default 1.10). Under heavy load the wall ratio
against Gmsh (one thread) understates us and the CPU ratio is the steadier figure.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_real import baseline_binary  # noqa: E402  (the worktree build of a commit)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_BASELINE = "d434889"
GMSH = """
import gmsh, sys
gmsh.initialize(); gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(sys.argv[1]); gmsh.model.mesh.setOrder(int(sys.argv[2]))
gmsh.option.setNumber("Mesh.Binary", int(sys.argv[4])); gmsh.write(sys.argv[3])
gmsh.finalize()
"""


def run_child(cmd, timeout):
    """Run `cmd`: (wall s, CPU s, peak RSS MB) of that child alone, or None if it fails or
    runs past `timeout` seconds."""
    t = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        deadline = t + timeout
        while True:
            pid, status, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() > deadline:
                p.kill()
                os.wait4(p.pid, 0)
                sys.stderr.write("timed out after %g s: %s\n" % (timeout, " ".join(cmd)))
                return None
            time.sleep(0.01)
        wall = time.perf_counter() - t
        p.returncode = os.waitstatus_to_exitcode(status)
        if p.returncode != 0:
            err.seek(0)
            sys.stderr.write("failed (%d): %s\n%s\n" % (
                p.returncode, " ".join(cmd), err.read().decode(errors="replace")[-600:]))
            return None
    return wall, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="10000,50000,100000",
                    help="comma-separated `generate cylinder --elements` values")
    ap.add_argument("--large", action="store_true", help="add the 1M-hex cylinder")
    ap.add_argument("--runs", type=int, default=3, help="runs per program and size (median)")
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--ascii", action="store_true", help="ASCII output instead of binary MSH")
    ap.add_argument("--baseline", metavar="COMMIT", default=DEFAULT_BASELINE)
    ap.add_argument("--no-baseline", action="store_true")
    ap.add_argument("--baseline-dir", metavar="DIR")
    ap.add_argument("--no-gmsh", action="store_true")
    ap.add_argument("--python", metavar="PY", help="Python with the gmsh module")
    ap.add_argument("--exe", default=os.path.join(ROOT, "target", "release", "polyspline"))
    ap.add_argument("--max-wall-ratio", type=float, default=1.25)
    ap.add_argument("--max-cpu-ratio", type=float, default=1.25)
    ap.add_argument("--max-rss-ratio", type=float, default=1.10)
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    args = ap.parse_args(argv)
    try:
        args.sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        ap.error("--sizes: comma-separated integers expected, got %r" % args.sizes)
    if args.large and 1000000 not in args.sizes:
        args.sizes.append(1000000)
    if not args.sizes or min(args.sizes) <= 0:
        ap.error("--sizes: at least one positive size expected")
    if args.runs < 1:
        ap.error("--runs must be at least 1")
    if not os.access(args.exe, os.X_OK):
        ap.error("%s is not an executable: run `cargo build --release` first" % args.exe)
    args.python = args.python or os.environ.get("POLYSPLINE_PYTHON", "python3")
    return args


def main():
    args = parse_args()
    programs = {"current": args.exe}
    if not args.no_baseline:
        where = args.baseline_dir or "/tmp/polyspline-baseline-" + args.baseline
        try:
            programs["baseline"] = baseline_binary(args.baseline, where)
        except subprocess.CalledProcessError as e:
            sys.exit("bench_scale: cannot build baseline %s in %s: `%s` failed (exit %d)" % (
                args.baseline, where, " ".join(e.cmd), e.returncode))
    head = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    binary = [] if args.ascii else ["--binary"]
    med = statistics.median
    print("current = %s (HEAD %s)%s; order %d, %s output; median of %d interleaved runs" % (
        args.exe, head, "" if args.no_baseline else "; baseline = " + args.baseline,
        args.order, "ASCII" if args.ascii else "binary", args.runs))
    print("load average at start: %.1f on %d cores" % (os.getloadavg()[0], os.cpu_count()))
    print()
    print("| hexes | curve wall s | CPU s | peak MB | fit s | CG it. | µs CPU / hex "
          "| baseline wall s | CPU s | peak MB | wall / baseline | CPU / baseline | peak / baseline "
          "| Gmsh wall s | CPU s | peak MB | wall / Gmsh | CPU / Gmsh | peak / Gmsh |")
    print("|" + "---|" * 19)
    regressions = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sizes:
            mesh = os.path.join(tmp, "cyl%d.msh" % n)
            subprocess.run([args.exe, "generate", "cylinder", "--elements", str(n), "-o", mesh,
                            "--binary"], check=True, capture_output=True)
            cmds = {who: [exe, "curve", mesh, "-o", os.path.join(tmp, who + ".msh"), "--order",
                          str(args.order), "-q", "--report", os.path.join(tmp, who + ".json")]
                    + binary for who, exe in programs.items()}
            if not args.no_gmsh:
                cmds["gmsh"] = [args.python, "-c", GMSH, mesh, str(args.order),
                                os.path.join(tmp, "gmsh.msh"), "0" if args.ascii else "1"]
            order = list(cmds)
            runs = {who: [] for who in cmds}
            reports = []
            for k in range(args.runs):
                for who in order[k % len(order):] + order[:k % len(order)]:
                    r = run_child(cmds[who], args.timeout)
                    if r is not None:
                        runs[who].append(r)
                        if who == "current":
                            reports.append(json.load(open(os.path.join(tmp, "current.json"))))
            for f in [mesh] + [os.path.join(tmp, who + ".msh") for who in cmds]:
                if os.path.exists(f):
                    os.remove(f)

            def m(who, i):
                return med(r[i] for r in runs[who]) if runs.get(who) else None

            def cell(x, fmt):
                return fmt % x if x is not None else "–"

            def ratio(a, b):
                return a / b if a is not None and b else None

            if not reports:
                print("| %d | failed |" % n + " |" * 17, flush=True)
                regressions.append("%d: current build failed" % n)
                continue
            elements = reports[0]["elements"]
            fit = med(r["timings"].get("fit", 0.0) for r in reports)
            wall_b, cpu_b, rss_b = (ratio(m("current", i), m("baseline", i)) for i in range(3))
            print("| " + " | ".join([
                "{:,}".format(elements), cell(m("current", 0), "%.2f"), cell(m("current", 1), "%.2f"),
                cell(m("current", 2), "%.0f"), "%.2f" % fit, str(reports[-1].get("cg_iterations", "–")),
                "%.0f" % (1e6 * m("current", 1) / elements),
                cell(m("baseline", 0), "%.2f"), cell(m("baseline", 1), "%.2f"),
                cell(m("baseline", 2), "%.0f"),
                cell(wall_b, "%.2f"), cell(cpu_b, "%.2f"), cell(rss_b, "%.2f"),
                cell(m("gmsh", 0), "%.2f"), cell(m("gmsh", 1), "%.2f"), cell(m("gmsh", 2), "%.0f")]
                + [cell(ratio(m("current", i), m("gmsh", i)), "%.2f") for i in range(3)]) + " |",
                flush=True)
            if "baseline" in programs and not runs["baseline"]:
                regressions.append("%d: baseline failed" % n)
            if wall_b is not None and wall_b > args.max_wall_ratio:
                regressions.append("%d: wall %.2f× the baseline's" % (elements, wall_b))
            if cpu_b is not None and cpu_b > args.max_cpu_ratio:
                regressions.append("%d: CPU time %.2f× the baseline's" % (elements, cpu_b))
            if rss_b is not None and rss_b > args.max_rss_ratio:
                regressions.append("%d: peak RSS %.2f× the baseline's" % (elements, rss_b))
    print()
    print("load average at end: %.1f" % os.getloadavg()[0])
    if regressions:
        print("REGRESSION against %s: %s" % (args.baseline, "; ".join(regressions)))
        sys.exit(1)


if __name__ == "__main__":
    main()
