#!/usr/bin/env python3
"""IGA against the elastic analogy on the bundled real meshes (`polyspline compare`).

usage: python3 scripts/bench_compare.py [--order P] [--runs N] [--timeout S] [MESH ...]
Builds nothing: run `cargo build --release` first. For each mesh (default: every file under
meshes/real/), runs `compare --json` N times (default 3; each run curves the mesh with every
method in one process) and prints two Markdown tables: the medians of each method's own
seconds with the median over runs of the elastic / iga-smooth ratio, and the quality and
facet-angle-jump figures of the last run. A method that failed shows its failure; a mesh whose
`compare` run fails or takes longer than --timeout seconds (default: none) is listed as such.
"""
import argparse
import glob
import json
import os
import statistics
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXE = os.path.join(ROOT, "target", "release", "polyspline")
METHODS = ["straight", "iga-position", "iga-frame", "iga-smooth", "elastic"]


def fail_note(row):
    if row.get("invalid_elements"):
        return "invalid (%d)" % row["invalid_elements"]
    if "did not converge" in (row.get("error") or ""):
        return "CG did not converge"
    return "failed"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--timeout", type=float, help="seconds per `compare` run")
    ap.add_argument("meshes", nargs="*")
    args = ap.parse_args()
    meshes = args.meshes or sorted(
        p for p in glob.glob(os.path.join(ROOT, "meshes", "real", "*", "*")) if not p.endswith(".md"))
    if args.runs < 1:
        ap.error("--runs must be at least 1")
    results, skipped = [], []
    for mesh in meshes:
        name = os.path.relpath(mesh, os.path.join(ROOT, "meshes", "real"))
        runs = []
        for _ in range(args.runs):
            try:
                out = subprocess.run([EXE, "compare", mesh, "--json", "--order", str(args.order)],
                                     capture_output=True, text=True, timeout=args.timeout)
            except subprocess.TimeoutExpired:
                skipped.append((name, "timed out after %g s" % args.timeout))
                break
            if out.returncode != 0:
                skipped.append((name, "failed: " + out.stderr.strip()[-200:]))
                break
            runs.append(json.loads(out.stdout))
        else:
            results.append((name, runs))

    print("Seconds of each method's own stages (median of %d runs), order %d:\n" % (args.runs, args.order))
    print("| mesh | dim | elements | " + " | ".join(METHODS) + " | elastic CG it. | elastic / iga-smooth |")
    print("|---" * (len(METHODS) + 5) + "|")
    for name, runs in results:
        last = runs[-1]
        cells = []
        for i, m in enumerate(METHODS):
            secs = [r["rows"][i]["method_seconds"] for r in runs if r["rows"][i]["method_seconds"] is not None]
            cells.append("%.3f" % statistics.median(secs) if secs else fail_note(last["rows"][i]))
        ratios = [r["elastic_over_iga_time"] for r in runs if r["elastic_over_iga_time"] is not None]
        it = last["rows"][4]["cg_iterations"]
        print("| %s | %dD | %d | %s | %s | %s |" % (
            name, last["dimension"], last["elements"], " | ".join(cells),
            it if it is not None else "-",
            "%.1f×" % statistics.median(ratios) if ratios else "-"))
    for name, why in skipped:
        print("| %s | | | %s |" % (name, why) + " |" * (len(METHODS) + 1))

    print("\nQuality and facet angle jump (mean°, interior facets / facets near the boundary), last run:\n")
    print("| mesh | method | min SJ | boundary dev. max | jump interior mean / max | jump near boundary mean / max |")
    print("|---|---|---|---|---|---|")
    for name, runs in results:
        for row in runs[-1]["rows"]:
            if row["error"] is not None:
                print("| %s | %s | %s | | | |" % (name, row["method"], fail_note(row)))
                continue
            s = row["smoothness"]

            def jump(g):
                return "%.2f / %.1f" % (g["mean_deg"], g["max_deg"]) if g["points"] else "- (no facets)"
            print("| %s | %s | %.3f | %.2e | %s | %s |" % (
                name, row["method"], row["min_scaled_jacobian"], row["boundary_vertex_deviation_max"],
                jump(s["interior"]), jump(s["near_boundary"])))


if __name__ == "__main__":
    main()
