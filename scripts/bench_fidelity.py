#!/usr/bin/env python3
"""Boundary fidelity of polyspline against Gmsh with the exact CAD, on analytic shapes.

usage: python3 scripts/bench_fidelity.py [--level N] [--json] [SHAPE ...]

Builds nothing: run `cargo build --release` first (or set POLYSPLINE to a binary). Needs the
`gmsh` Python module (4.15), numpy and PyMFEM (`mfem.ser`).

Each shape of scripts/fidelity_shapes.py (disk, torus, cylinder, plate, ball) is made with Gmsh's
Python API at refinement LEVEL (default 1), written linear, and curved three ways: Gmsh
setOrder(2) (nodes on the exact CAD, the reference), polyspline `curve --order 2` and
`--order 3` (default least-squares fit), and `curve --order 2 --fit energy`. Measured:
* boundary distance from the exact surface over a dense lattice of parameter points per boundary
  side, relative to the bounding-box diagonal (scripts/fidelity_shapes.py measure), RMS and max,
  for the linear mesh, Gmsh-with-CAD and ours; the table gives ours/linear (RMS),
  ours/Gmsh-with-CAD (RMS and max) at orders 2 and 3, and energy/least squares (RMS and max);
* the enclosed volume (area in 2D) computed by MFEM from each file (Mesh.GetElementVolume summed
  over the elements of the curved mesh), as the relative error against the exact value.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
EXE = os.environ.get("POLYSPLINE", os.path.join(ROOT, "target", "release", "polyspline"))
sys.path.insert(0, HERE)
import fidelity_shapes as fs  # noqa: E402


def mfem_volume(path):
    """Volume of the mesh in `path` computed by MFEM (a subprocess: each reader in its own)."""
    code = (
        "import mfem.ser as mfem, sys\n"
        "m = mfem.Mesh(sys.argv[1], 1, 1)\n"
        "print(sum(m.GetElementVolume(i) for i in range(m.GetNE())))\n"
    )
    out = subprocess.run([sys.executable, "-c", code, path], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def measure(shape, path, only):
    out = subprocess.run(
        [sys.executable, os.path.join(HERE, "fidelity_shapes.py"), "measure", shape, "--only", only, path],
        capture_output=True, text=True, check=True,
    )
    return json.loads(out.stdout)


def run_shape(shape, level, tmp):
    lin, cad = os.path.join(tmp, f"{shape}.msh"), os.path.join(tmp, f"{shape}_cad.msh")
    made = json.loads(subprocess.run(
        [sys.executable, os.path.join(HERE, "fidelity_shapes.py"), "make", shape, str(level), lin, cad],
        capture_output=True, text=True, check=True,
    ).stdout)
    files = {"linear": lin, "gmsh_cad": cad}
    for name, args in [("ours_o2", ["--order", "2"]), ("ours_o3", ["--order", "3"]),
                       ("energy_o2", ["--order", "2", "--fit", "energy"])]:
        out = os.path.join(tmp, f"{shape}_{name}.msh")
        subprocess.run([EXE, "curve", lin, "-o", out, "--msh-version", "2.2", *args],
                       capture_output=True, check=True)
        files[name] = out
    row = {"shape": shape, "elements": made["elements"]}
    for name, path in files.items():
        row[name] = {"all": measure(shape, path, "all"), "curved": measure(shape, path, "curved")}
        try:
            v = mfem_volume(path)
            row[name]["volume_rel_error"] = abs(v - fs.VOLUME[shape]) / fs.VOLUME[shape]
        except subprocess.CalledProcessError as e:
            row[name]["volume_rel_error"] = None
            print(f"MFEM could not read {path}: {e.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
    return row


def table(rows):
    lines = [
        "| shape | elements | part | RMS ours/linear (o2) | RMS ours/Gmsh-CAD o2 / o3 | max ours/Gmsh-CAD o2 / o3 | energy/LS RMS, max | MFEM volume error: linear, Gmsh-CAD, ours o2, ours o3 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for part in ("all", "curved"):
            if part == "curved" and r["shape"] not in ("plate", "cylinder"):
                continue
            g = r["gmsh_cad"][part]
            o2, o3, lin, en = r["ours_o2"][part], r["ours_o3"][part], r["linear"][part], r["energy_o2"][part]
            vol = ", ".join(
                "n/a" if r[k]["volume_rel_error"] is None else f"{r[k]['volume_rel_error']:.2e}"
                for k in ("linear", "gmsh_cad", "ours_o2", "ours_o3")
            ) if part == "all" else ""
            lines.append(
                f"| {r['shape']} | {r['elements']} | {part} | {o2['rms'] / lin['rms']:.4f} "
                f"| {o2['rms'] / g['rms']:.2f} / {o3['rms'] / g['rms']:.2f} "
                f"| {o2['max'] / g['max']:.2f} / {o3['max'] / g['max']:.2f} "
                f"| {en['rms'] / o2['rms']:.2f}, {en['max'] / o2['max']:.2f} | {vol} |"
            )
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--level", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("shapes", nargs="*", default=fs.SHAPES)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rows = [run_shape(s, a.level, tmp) for s in a.shapes]
    if a.json:
        print(json.dumps(rows, indent=1))
    else:
        print(table(rows))
        print()
        for r in rows:
            print(r["shape"], {k: (r[k]["all"]["rms"], r[k]["all"]["max"]) for k in ("linear", "gmsh_cad", "ours_o2", "ours_o3", "energy_o2")})


if __name__ == "__main__":
    main()
