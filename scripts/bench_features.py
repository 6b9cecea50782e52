#!/usr/bin/env python3
"""Curve the real meshes with sharp edges with features kept and ignored; print a markdown
table of what `curve --report` measures (BENCHMARKS.md, "Sharp features").

usage: scripts/bench_features.py [POLYSPLINE] (default target/release/polyspline)
"""
import json
import os
import subprocess
import sys
import tempfile

MESHES = [
    "sfepy/acoustics_mesh3d.mesh",
    "hopr/70degCone_3D.msh",
    "su2-testcases/cylinder.su2",
    "libmesh/systems_of_equations_ex9.exo",
    "mfem/cylinder-hex.mesh",
]


def run(exe, mesh, extra, tmp):
    report = os.path.join(tmp, "r.json")
    out = os.path.join(tmp, "o.msh")
    subprocess.run([exe, "curve", mesh, "-o", out, "--report", report] + extra,
                   check=True, capture_output=True)
    return json.load(open(report))


def main():
    exe = sys.argv[1] if len(sys.argv) > 1 else "target/release/polyspline"
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "meshes", "real")
    print("| mesh | features | feature edges / corners / patches (planar) | Q2 (crease) "
          "| feature vertex dev. | planarity | boundary dev. max | min SJ (input) |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for m in MESHES:
            for mode, extra in [("kept", []), ("ignored", ["--ignore-features"])]:
                r = run(exe, os.path.join(root, m), extra, tmp)
                f = r["features"]
                crease = f["crease_elements"] if mode == "kept" else 0
                print(f"| {m} | {mode} | {f['feature_edges']} / {f['feature_corners']} / "
                      f"{f['patches']} ({f['planar_patches']}) | {r['q2_elements']} ({crease}) "
                      f"| {f['feature_vertex_deviation_max']:.2e} | {f['planarity_max']:.2e} "
                      f"| {r['boundary_vertex_deviation_max']:.2e} "
                      f"| {r['min_scaled_jacobian']:.3f} ({r['input_min_scaled_jacobian']:.3f}) |",
                      flush=True)


if __name__ == "__main__":
    main()
