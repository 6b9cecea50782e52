#!/usr/bin/env python3
"""End-to-end timings of `polyspline curve` on the bundled real meshes.

usage: python3 scripts/bench_real.py [--order P] [--runs N]
       python3 scripts/bench_real.py --baseline COMMIT [--runs N] [--baseline-dir DIR] [--no-cylinder] [--no-gmsh]

Builds nothing in the first form: run `cargo build --release` first. For each mesh, runs `curve`
N times (default 3) and prints the median total and per-stage seconds from the JSON report, with
the quality figures of the last run, as a Markdown table.

With --baseline, an A/B of this checkout's release build (B) against the build of COMMIT (A),
checked out in its own worktree with its own target directory (DIR, default
/tmp/polyspline-baseline-COMMIT; built there on first use, seeded with a copy of this checkout's
target/ so that only polyspline itself compiles). Every real mesh, then the generated 50k-hex
cylinder (`generate cylinder --elements 50000`), runs N times per build, A and B interleaved so
that both see the same background load; the table gives the median wall time of the whole
`curve` process and the median CPU time (user + system), each with the ratio B/A. On the
cylinder, Gmsh's straight-sided elevation (read, `setOrder(2)`, write; Python from
$POLYSPLINE_PYTHON, else python3) is timed in the same rotation.
"""
import argparse
import glob
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXE = os.path.join(ROOT, "target", "release", "polyspline")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--baseline", metavar="COMMIT", help="A/B against the build of COMMIT")
    ap.add_argument("--baseline-dir", metavar="DIR", help="worktree of the baseline build")
    ap.add_argument("--no-cylinder", action="store_true", help="A/B: skip the 50k-hex cylinder")
    ap.add_argument("--no-gmsh", action="store_true", help="A/B: do not time Gmsh on the cylinder")
    args = ap.parse_args()
    if args.baseline:
        return ab(args)
    meshes = sorted(p for p in glob.glob(os.path.join(ROOT, "meshes", "real", "*", "*")) if not p.endswith(".md"))
    print("| mesh | elements | spline/Q2 | CG it. | step | fit s | validity s | total s | min SJ in/out | boundary dev. max |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for mesh in meshes:
            totals, fits, vals, r = [], [], [], None
            for _ in range(args.runs):
                out, rep = os.path.join(tmp, "o.msh"), os.path.join(tmp, "r.json")
                subprocess.run([EXE, "curve", mesh, "-o", out, "--order", str(args.order), "--report", rep],
                               check=True, capture_output=True)
                r = json.load(open(rep))
                totals.append(r["timings"]["total"])
                fits.append(r["timings"].get("fit", 0.0))
                vals.append(r["timings"].get("validity", 0.0))
            name = os.path.relpath(mesh, os.path.join(ROOT, "meshes", "real"))
            print("| %s | %d | %d/%d | %s | %.3g | %.3f | %.3f | %.3f | %.3f / %.3f | %.2e |" % (
                name, r["elements"], r["spline_elements"], r["q2_elements"], r["cg_iterations"],
                r["line_search_alpha"], statistics.median(fits), statistics.median(vals),
                statistics.median(totals), r["input_min_scaled_jacobian"], r["min_scaled_jacobian"],
                r["boundary_vertex_deviation_max"]))


def baseline_binary(commit, where):
    """The release binary of `commit`, built in the worktree `where` on first use."""
    exe = os.path.join(where, "target", "release", "polyspline")
    if os.path.exists(exe):
        return exe
    if not os.path.exists(where):
        subprocess.run(["git", "-C", ROOT, "worktree", "add", "--detach", where, commit], check=True)
    seed = os.path.join(ROOT, "target")
    if not os.path.exists(os.path.join(where, "target")) and os.path.isdir(seed):
        shutil.copytree(seed, os.path.join(where, "target"), symlinks=True)
    subprocess.run(["cargo", "build", "--release", "--bin", "polyspline"], cwd=where, check=True)
    return exe


def timed(cmd):
    """(wall seconds, CPU seconds of the child), or None when the command fails."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.stderr.write("failed: %s\n%s" % (" ".join(cmd), done.stderr.decode()[-400:]))
        return None
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


GMSH_ELEVATE = """
import sys, gmsh
gmsh.initialize(); gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(sys.argv[1]); gmsh.model.mesh.setOrder(2); gmsh.write(sys.argv[2]); gmsh.finalize()
"""


def ab(args):
    base = baseline_binary(args.baseline, args.baseline_dir or "/tmp/polyspline-baseline-" + args.baseline)
    builds = {"A": base, "B": EXE}
    meshes = sorted(p for p in glob.glob(os.path.join(ROOT, "meshes", "real", "*", "*")) if not p.endswith(".md"))
    med = statistics.median
    print("A = %s (%s), B = this checkout (%s); median of %d interleaved runs; wall and CPU (user + system) "
          "seconds of the whole `curve` process" % (args.baseline, base, EXE, args.runs))
    print()
    print("| mesh | elements | A wall s | B wall s | B/A wall | A CPU s | B CPU s | B/A CPU |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        if not args.no_cylinder:
            cyl = os.path.join(tmp, "cyl50k.msh")
            subprocess.run([EXE, "generate", "cylinder", "--elements", "50000", "-o", cyl], check=True,
                           capture_output=True)
            meshes.append(cyl)
        ratios = []
        for mesh in meshes:
            runs = {"A": [], "B": [], "gmsh": []}
            rep = os.path.join(tmp, "r.json")
            elements = None
            for _ in range(args.runs):
                for who, exe in builds.items():
                    r = timed([exe, "curve", mesh, "-o", os.path.join(tmp, "o.msh"), "--report", rep])
                    if r is not None:
                        runs[who].append(r)
                        elements = json.load(open(rep))["elements"]
                if mesh.endswith("cyl50k.msh") and not args.no_gmsh:
                    py = os.environ.get("POLYSPLINE_PYTHON", "python3")
                    r = timed([py, "-c", GMSH_ELEVATE, mesh, os.path.join(tmp, "g.msh")])
                    if r is not None:
                        runs["gmsh"].append(r)
            name = "generated cylinder, 50k" if mesh.endswith("cyl50k.msh") else \
                os.path.relpath(mesh, os.path.join(ROOT, "meshes", "real"))

            def cell(who, k):
                return "%.3f" % med(r[k] for r in runs[who]) if runs[who] else "failed"

            def ratio(k):
                if not runs["A"] or not runs["B"]:
                    return "-"
                q = med(r[k] for r in runs["B"]) / med(r[k] for r in runs["A"])
                if k == 0:
                    ratios.append((name, q))
                return "%.2f" % q

            print("| %s | %s | %s | %s | %s | %s | %s | %s |" % (
                name, elements, cell("A", 0), cell("B", 0), ratio(0), cell("A", 1), cell("B", 1), ratio(1)))
            if runs["gmsh"]:
                print("| Gmsh `setOrder(2)`, same cylinder (read, elevate, write) | %s | | %s | B/Gmsh %.2f | | %s | B/Gmsh %.2f |" % (
                    elements, cell("gmsh", 0), med(r[0] for r in runs["B"]) / med(r[0] for r in runs["gmsh"]),
                    cell("gmsh", 1), med(r[1] for r in runs["B"]) / med(r[1] for r in runs["gmsh"])))
            sys.stdout.flush()
    if ratios:
        worst = max(ratios, key=lambda x: x[1])
        print()
        print("largest wall ratio B/A: %.2f (%s)" % (worst[1], worst[0]))


if __name__ == "__main__":
    main()
