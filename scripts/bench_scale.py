#!/usr/bin/env python3
"""Scaling of `polyspline curve` from 10k to 1M hexes, with Gmsh's straight-sided elevation of
the same meshes as the reference, in the same run.

usage: python3 scripts/bench_scale.py [--sizes 10000,50000,100000,300000,1000000]
                                      [--orders 2,3] [--runs 3] [--real] [--no-gmsh]
                                      [--exe target/release/polyspline]
Builds nothing: run `cargo build --release` first. Meshes are generated into a temporary
directory (`polyspline generate cylinder --elements N --binary`) and deleted afterwards. For
every mesh and order it runs `curve` N times under `/usr/bin/time -v` (median wall time, CPU
time and peak RSS; fit and certificate seconds from the JSON report), then Gmsh's Python API
(read + `setOrder(P)` + write, MSH 4.1 ASCII like `curve`'s default output) as many times.
`--real` adds the largest bundled real meshes. Prints a Markdown table and the machine load.
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REAL = ["hopr/70degCone_3D.msh", "trixi-juliacon2024-naca4412/NACA4412_2.msh",
        "dealii/sphere_r6.msh", "dealii/hole8170.msh"]  # MSH files: Gmsh reads them too
GMSH = """
import gmsh, sys
gmsh.initialize(); gmsh.option.setNumber("General.Terminal", 0)
gmsh.open(sys.argv[1]); gmsh.model.mesh.setOrder(int(sys.argv[2])); gmsh.write(sys.argv[3])
gmsh.finalize()
"""


def timed(cmd):
    """Run `cmd` under /usr/bin/time -v: (wall s, cpu s, peak MB)."""
    p = subprocess.run(["/usr/bin/time", "-v"] + cmd, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{p.stderr[-2000:]}")
    field = lambda name: re.search(re.escape(name) + r": (.*)", p.stderr).group(1).strip()
    wall = 0.0
    for part in field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":"):
        wall = 60 * wall + float(part)
    cpu = float(field("User time (seconds)")) + float(field("System time (seconds)"))
    return wall, cpu, int(field("Maximum resident set size (kbytes)")) / 1024


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="10000,50000,100000,300000,1000000")
    ap.add_argument("--orders", default="2,3")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--real", action="store_true")
    ap.add_argument("--no-gmsh", action="store_true")
    ap.add_argument("--exe", default=os.path.join(ROOT, "target", "release", "polyspline"))
    args = ap.parse_args()
    med = statistics.median
    print(f"load average at start: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print("| mesh | elements | order | curve wall s | CPU s | fit s | certificate s | peak MB "
          "| Gmsh setOrder wall s | Gmsh CPU s | Gmsh peak MB | curve / Gmsh wall |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        inputs = []
        for n in [int(s) for s in args.sizes.split(",") if s]:
            path = os.path.join(tmp, f"cyl{n}.msh")
            subprocess.run([args.exe, "generate", "cylinder", "--elements", str(n), "-o", path,
                            "--binary"], check=True, capture_output=True)
            inputs.append((f"cylinder {n}", path))
        if args.real:
            inputs += [(m, os.path.join(ROOT, "meshes", "real", m)) for m in REAL]
        for name, path in inputs:
            for order in [int(o) for o in args.orders.split(",")]:
                out, rep = os.path.join(tmp, "o.msh"), os.path.join(tmp, "r.json")
                runs, reports = [], []
                for _ in range(args.runs):
                    runs.append(timed([args.exe, "curve", path, "-o", out, "--order", str(order),
                                       "--report", rep, "-q"]))
                    reports.append(json.load(open(rep)))
                os.remove(out)
                t = lambda k: med(r["timings"].get(k, 0.0) for r in reports)
                wall = med(r[0] for r in runs)
                row = [name, reports[0]["elements"], order, f"{wall:.2f}",
                       f"{med(r[1] for r in runs):.2f}", f"{t('fit'):.2f}", f"{t('validity'):.2f}",
                       f"{med(r[2] for r in runs):.0f}"]
                if args.no_gmsh:
                    row += ["-", "-", "-", "-"]
                else:
                    g = [timed([sys.executable, "-c", GMSH, path, str(order), out])
                         for _ in range(args.runs)]
                    os.remove(out)
                    gw = med(x[0] for x in g)
                    row += [f"{gw:.2f}", f"{med(x[1] for x in g):.2f}", f"{med(x[2] for x in g):.0f}",
                            f"{wall / gw:.2f}"]
                print("| " + " | ".join(str(x) for x in row) + " |", flush=True)
    print(f"load average at end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
