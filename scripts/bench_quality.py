#!/usr/bin/env python3
"""Cell quality of the curved output against the straight-sided elevation, measured by Gmsh.

For every real mesh in meshes/real (and generated disc, cylinder, torus, boundary-layer
O-/C-grids when the binary has those generators), curve it at order 2 with the default options
and write the straight-sided order-2 elevation, then measure both with Gmsh's Bézier bounds
(scripts/jacobian_ratio.py): Jacobian ratio min and 1st percentile, ours / straight. Also the
report's min scaled Jacobian in → out, boundary vertex deviation, elements the certified blend
held back, and `curve`'s wall time (median of --repeat runs).

Usage: scripts/bench_quality.py [--bin target/release/polyspline] [--repeat 3] [--json]
"""
import argparse
import glob
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(__file__))
from jacobian_ratio import ratios  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(cmd):
    t = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    return p, time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", default=os.path.join(ROOT, "target/release/polyspline"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="bench_quality_")
    inputs = sorted(
        f
        for f in glob.glob(os.path.join(ROOT, "meshes/real/*/*"))
        if not f.endswith((".md", ".txt"))
    )
    generated = [
        ("disc", ["generate", "disc", "--elements", "10000"]),
        ("cylinder", ["generate", "cylinder", "--elements", "10000"]),
        ("torus", ["generate", "torus", "--elements", "10000"]),
        ("ogrid_ellipse_2d", ["generate", "ogrid", "--wall", "ellipse", "--thickness", "0.2",
                              "--first-height", "1e-5", "--growth", "1.28"]),
        ("ogrid_ellipse_1layer", ["generate", "ogrid", "--wall", "ellipse", "--thickness", "0.2",
                                  "--first-height", "1e-5", "--growth", "1.28", "--layers", "1"]),
        ("ogrid_ellipse_3layer", ["generate", "ogrid", "--wall", "ellipse", "--thickness", "0.3",
                                  "--first-height", "1e-5", "--growth", "1.32", "--layers", "3"]),
        ("cgrid_naca0012", ["generate", "cgrid", "--first-height", "1e-5", "--growth", "1.25"]),
    ]
    for name, cmd in generated:
        out = os.path.join(tmp, name + ".msh")
        p, _ = run([a.bin] + cmd + ["-o", out])
        if p.returncode == 0:
            inputs.append(out)
        else:
            print(f"skipped {name}: {p.stderr.strip()[:200]}", file=sys.stderr)
    rows = []
    for f in inputs:
        name = os.path.relpath(f, os.path.join(ROOT, "meshes/real")) if ROOT in f else os.path.basename(f)
        ours, straight, rep = (os.path.join(tmp, x) for x in ("o.msh", "s.msh", "r.json"))
        times = []
        for _ in range(a.repeat):
            p, t = run([a.bin, "curve", "-q", f, "-o", ours, "--report", rep])
            if p.returncode != 0:
                break
            times.append(t)
        if p.returncode != 0:
            rows.append({"mesh": name, "error": p.stderr.strip()[:300]})
            continue
        r = json.load(open(rep))
        run([a.bin, "curve", "-q", "--straight", f, "-o", straight])
        o, s = ratios(ours), ratios(straight)
        b = r.get("blend") or {}
        rows.append({
            "mesh": name, "elements": r["elements"],
            "ratio_min": o["min"], "straight_min": s["min"],
            "ratio_p1": o["p1"], "straight_p1": s["p1"],
            "sj_in": r["input_min_scaled_jacobian"], "sj_out": r["min_scaled_jacobian"],
            "deviation": r["boundary_vertex_deviation_max"],
            # The report's top-level count (older reports nested it under "blend").
            "reduced": r.get("reduced_elements", b.get("reduced_elements", 0)),
            "seconds": statistics.median(times),
        })
    if a.json:
        print(json.dumps(rows, indent=1))
        return
    print("| mesh | elements | ratio min ours / straight | p1 ours / straight | min SJ in → out | "
          "boundary dev. | elements held back | s |")
    print("|---|---|---|---|---|---|---|---|")
    for x in rows:
        if "error" in x:
            print(f"| {x['mesh']} | | FAILED: {x['error']} | | | | | |")
            continue
        print(f"| {x['mesh']} | {x['elements']} | {x['ratio_min']:.3f} / {x['straight_min']:.3f} "
              f"({x['ratio_min'] / x['straight_min']:.2f}×) | {x['ratio_p1']:.3f} / "
              f"{x['straight_p1']:.3f} ({x['ratio_p1'] / x['straight_p1']:.2f}×) | "
              f"{x['sj_in']:.3f} → {x['sj_out']:.3f} | {x['deviation']:.2e} | {x['reduced']} | "
              f"{x['seconds']:.2f} |")


if __name__ == "__main__":
    main()
