#!/usr/bin/env python3
"""Curve the real meshes with sharp edges and generated ones with features kept and ignored;
print a markdown table of what `curve --report` measures (docs/benchmarks-history.md, "Sharp features").

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


# Generated meshes (`polyspline generate` arguments): a coarse torus (smooth: no creases at
# the default angle), a coarse ellipse O-grid, a C-grid (straight outflow side) and one- and
# three-layer extrusions of an ellipse O-grid (planar caps around a curved wall).
GENERATED = [
    ("torus, 189 hexes", ["torus", "--elements", "243"]),
    ("ellipse O-grid 32×12", ["ogrid", "--around", "32", "--across", "12"]),
    ("NACA C-grid 64×24", ["cgrid", "--around", "64", "--across", "24"]),
] + [
    (f"ellipse O-grid 128×48, {n} layer(s)",
     ["ogrid", "--around", "128", "--across", "48", "--growth", "1.28", "--span", "0.1",
      "--layers", str(n)])
    for n in (1, 3)
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
    print("| mesh | features | feature edges / corners / patches (planar or straight) "
          "| Q2 (crease) | reduced by the blend | feature vertex dev. | planarity "
          "| boundary dev. max | min SJ (input) |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        inputs = [(m, os.path.join(root, m)) for m in MESHES]
        for i, (name, args) in enumerate(GENERATED):
            path = os.path.join(tmp, f"gen{i}.msh")
            subprocess.run([exe, "generate"] + args + ["-o", path], check=True,
                           capture_output=True)
            inputs.append((name, path))
        for m, path in inputs:
            for mode, extra in [("kept", []), ("ignored", ["--ignore-features"])]:
                r = run(exe, path, extra, tmp)
                f = r["features"] or {}
                crease = f.get("crease_elements", 0) if mode == "kept" else 0
                found = (f"{f['feature_edges']} / {f['feature_corners']} / "
                         f"{f['patches']} ({f['planar_patches']})") if f else "none"
                dev = (f"{f['feature_vertex_deviation_max']:.2e} | {f['planarity_max']:.2e}"
                       if f else "– | –")
                print(f"| {m} | {mode} | {found} | {r['q2_elements']} ({crease}) "
                      f"| {r['reduced_elements']} | {dev} "
                      f"| {r['boundary_vertex_deviation_max']:.2e} "
                      f"| {r['min_scaled_jacobian']:.3f} ({r['input_min_scaled_jacobian']:.3f}) |",
                      flush=True)


if __name__ == "__main__":
    main()
