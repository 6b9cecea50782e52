#!/usr/bin/env python3
"""Least squares against the degeneration-energy fit (L-BFGS and coloured) on real meshes.

usage: python3 scripts/bench_energy.py [--runs N] [--timeout S] [MESH ...]
Builds nothing: run `cargo build --release` first (or set POLYSPLINE to a binary). For each mesh, runs
`curve --fit smooth`, `curve --fit energy` and `curve --fit energy --energy-solver colored`
(order 2) N times (default 1) and prints a Markdown table: smallest step factor of the
least-squares line search, min scaled Jacobian (input and output), boundary deviation max
(relative to the bounding-box diagonal), median total and energy seconds, iterations/sweeps.
"""
import argparse
import json
import os
import statistics
import subprocess
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXE = os.environ.get("POLYSPLINE", os.path.join(ROOT, "target", "release", "polyspline"))
MESHES = [
    "su2-testcases/mesh_vki_turbine_prepbc.su2",
    "su2-testcases/n0012_113-33.su2",
    "trixi-juliacon2024-naca4412/NACA4412_2.msh",
    "dealii/hole8170.msh",
    "mfem/cylinder-hex.mesh",
]
MODES = [
    ("smooth", ["--fit", "smooth"]),
    ("lbfgs", ["--fit", "energy"]),
    ("colored", ["--fit", "energy", "--energy-solver", "colored"]),
]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per run")
    ap.add_argument("meshes", nargs="*", default=MESHES)
    args = ap.parse_args()
    print("| mesh | elements | fit | LS step | min SJ in → out | boundary dev. max | it. | energy s | total s |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for mesh in args.meshes:
            path = os.path.join(ROOT, "meshes", "real", mesh)
            for name, flags in MODES:
                totals, energies, r = [], [], None
                for _ in range(args.runs):
                    out, rep = os.path.join(tmp, "o.msh"), os.path.join(tmp, "r.json")
                    try:
                        subprocess.run([EXE, "curve", path, "-o", out, "--report", rep, *flags],
                                       check=True, capture_output=True, timeout=args.timeout)
                    except subprocess.TimeoutExpired:
                        r = None
                        break
                    r = json.load(open(rep))
                    totals.append(r["timings"]["total"])
                    energies.append(r["timings"].get("energy", 0.0))
                if r is None:
                    print(f"| {mesh} | | {name} | | | | timeout ({args.timeout} s) | | |", flush=True)
                    continue
                e = r.get("energy")
                it = f"{e['iterations']} ({e['stop']})" if e else "–"
                print(f"| {mesh} | {r['elements']} | {name} | {r['line_search_alpha']:.3g} | "
                      f"{r['input_min_scaled_jacobian']:.3f} → {r['min_scaled_jacobian']:.3f} | "
                      f"{r['boundary_vertex_deviation_max']:.2e} | {it} | "
                      f"{statistics.median(energies):.2f} | {statistics.median(totals):.2f} |", flush=True)


if __name__ == "__main__":
    main()
