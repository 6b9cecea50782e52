#!/usr/bin/env python3
"""End-to-end timings of `polyspline curve` on the bundled real meshes.

usage: python3 scripts/bench_real.py [--order P] [--runs N]
Builds nothing: run `cargo build --release` first. For each mesh, runs `curve` N times (default
3) and prints the median total and per-stage seconds from the JSON report, with the quality
figures of the last run, as a Markdown table.
"""
import argparse
import glob
import json
import os
import statistics
import subprocess
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXE = os.path.join(ROOT, "target", "release", "polyspline")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--order", type=int, default=2)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
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


if __name__ == "__main__":
    main()
