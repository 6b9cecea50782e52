#!/usr/bin/env python3
"""Boundary-layer meshes: polyspline against Gmsh with the exact CAD (issue 16).

usage: python3 scripts/bench_boundary_layer.py [--runs N] [--timeout S] [--json] [--keep DIR]
       [--gmsh setOrder(2),HighOrder,...] [CASE ...]

Builds nothing: run `cargo build --release` first (or set POLYSPLINE to a binary). Needs the
`gmsh` Python module (4.15) and numpy.

Cases (all built in Gmsh with the OpenCASCADE kernel, so Gmsh knows the exact ellipse):
  ellipse-0.2       2D O-grid around an ellipse of semi-axes 1 and 0.2, circular far field of
                    radius 20, 128 cells around, 4 transfinite blocks recombined to quads,
                    wall-normal geometric progression of ratio 1.28 with a first height ≈ 1e-5
  ellipse-0.3       the same with semi-axis 0.3 and ratio 1.32
  ellipse-0.2-hex1  one-layer hex extrusion of ellipse-0.2 (layer height 0.1)
  ellipse-0.2-hex3  three-layer extrusion (3 × 0.1)

For each case the linear mesh is written as MSH 4.1 with physical groups (wall, farfield, sides,
fluid); then, each in its own subprocess (Gmsh's optimisers may abort the process):
  Gmsh setOrder(2)            high-order nodes placed on the CAD
  Gmsh HighOrder / HighOrderElastic / HighOrderFastCurving
                              setOrder(2) then gmsh.model.mesh.optimize(METHOD); time is both
and polyspline `curve --straight --order 2` and `curve --order 2` (N runs, median times).
Every high-order mesh is measured by Gmsh: per element the Jacobian ratio minDetJac/maxDetJac
(Bézier bounds; scripts/jacobian_ratio.py handles Gmsh's sign convention for planar elements),
invalid elements (ratio <= 0), min and 1st percentile; and the wall error: distance of every node
of the wall's boundary elements (vertices, edge and face nodes) from the exact ellipse (cylinder
in 3D), RMS and max. The straight mesh's wall error is that of the linear mesh's chord
midpoints; ours is also given relative to it.

Prints the linear meshes' data and one Markdown table (or, with --json, one JSON object).
"""
import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
EXE = os.environ.get("POLYSPLINE", os.path.join(ROOT, "target", "release", "polyspline"))

# b: minor semi-axis (major is 1); ratio: wall-normal growth; layers: 0 for 2D, else hex layers.
CASES = {
    "ellipse-0.2": {"b": 0.2, "ratio": 1.28, "layers": 0},
    "ellipse-0.3": {"b": 0.3, "ratio": 1.32, "layers": 0},
    "ellipse-0.2-hex1": {"b": 0.2, "ratio": 1.28, "layers": 1},
    "ellipse-0.2-hex3": {"b": 0.2, "ratio": 1.28, "layers": 3},
}
FAR, AROUND, FIRST, LAYER_HEIGHT = 20.0, 128, 1e-5, 0.1
GMSH_METHODS = ["setOrder(2)", "HighOrder", "HighOrderElastic", "HighOrderFastCurving"]


# ---------------------------------------------------------------- geometry and distance


def ellipse_distance(x, y, a, b):
    """Distance of points (x, y) from the ellipse (a cos t, b sin t): best of a fine sampling of
    t, then Newton on d/dt |p(t) - q|^2 = 0 (converges to the nearest foot from there)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    ts = np.linspace(0.0, 2.0 * math.pi, 4096, endpoint=False)
    d2 = (a * np.cos(ts)[None, :] - x[:, None]) ** 2 + (b * np.sin(ts)[None, :] - y[:, None]) ** 2
    t = ts[np.argmin(d2, axis=1)]
    for _ in range(30):
        c, s = np.cos(t), np.sin(t)
        # g(t) = (p - q) . p'(t), p = (a c, b s), p' = (-a s, b c)
        g = (a * c - x) * (-a * s) + (b * s - y) * (b * c)
        dg = (a * s) ** 2 + (b * c) ** 2 + (a * c - x) * (-a * c) + (b * s - y) * (-b * s)
        step = np.where(np.abs(dg) > 1e-300, g / np.where(dg == 0, 1.0, dg), 0.0)
        # Keep Newton local: the sampled start is within one sample of the foot.
        step = np.clip(step, -0.01, 0.01)
        t = t - step
        if np.max(np.abs(step)) < 1e-15:
            break
    return np.hypot(a * np.cos(t) - x, b * np.sin(t) - y)


def build(case):
    """Builds the CAD and the linear boundary-layer mesh of a case in the current Gmsh model.
    Returns the number of wall-normal cells and the first cell height on the major axis."""
    import gmsh

    p = CASES[case]
    a, b, ratio, layers = 1.0, p["b"], p["ratio"], p["layers"]
    # Cells n with FIRST * (ratio^n - 1) / (ratio - 1) = FAR - a (along the major axis).
    n = round(math.log(1.0 + (FAR - a) * (ratio - 1.0) / FIRST) / math.log(ratio))
    first = (FAR - a) * (ratio - 1.0) / (ratio**n - 1.0)
    occ = gmsh.model.occ
    pe = [occ.addPoint(a * math.cos(k * math.pi / 2), b * math.sin(k * math.pi / 2), 0) for k in range(4)]
    pc = [occ.addPoint(FAR * math.cos(k * math.pi / 2), FAR * math.sin(k * math.pi / 2), 0) for k in range(4)]
    c0 = occ.addPoint(0, 0, 0)
    ell = [occ.addEllipseArc(pe[k], c0, pe[0], pe[(k + 1) % 4]) for k in range(4)]
    cir = [occ.addCircleArc(pc[k], c0, pc[(k + 1) % 4]) for k in range(4)]
    rad = [occ.addLine(pe[k], pc[k]) for k in range(4)]  # oriented wall -> far field
    surfs = []
    for k in range(4):
        loop = occ.addCurveLoop([ell[k], rad[(k + 1) % 4], cir[k], rad[k]])
        surfs.append(occ.addPlaneSurface([loop]))
    if layers:
        occ.extrude([(2, s) for s in surfs], 0, 0, LAYER_HEIGHT * layers, numElements=[layers], recombine=True)
    occ.synchronize()
    mesh = gmsh.model.mesh
    for c in ell + cir:
        mesh.setTransfiniteCurve(c, AROUND // 4 + 1)
    for c in rad:
        mesh.setTransfiniteCurve(c, n + 1, "Progression", ratio)
    for s in surfs:
        mesh.setTransfiniteSurface(s)
        mesh.setRecombine(2, s)
    if not layers:
        gmsh.model.addPhysicalGroup(1, ell, name="wall")
        gmsh.model.addPhysicalGroup(1, cir, name="farfield")
        gmsh.model.addPhysicalGroup(2, surfs, name="fluid")
    else:
        wall, farfield, sides = [], [], []
        for _, s in gmsh.model.getEntities(2):
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, s)
            if z1 - z0 < 1e-9:
                sides.append(s)
            elif x1 - x0 < 1e-9 or y1 - y0 < 1e-9:
                continue  # block interface (extruded radial line), interior
            elif max(abs(x0), abs(x1), abs(y0), abs(y1)) < 2.0 * a:
                wall.append(s)
            else:
                farfield.append(s)
        gmsh.model.addPhysicalGroup(2, wall, name="wall")
        gmsh.model.addPhysicalGroup(2, farfield, name="farfield")
        gmsh.model.addPhysicalGroup(2, sides, name="sides")
        gmsh.model.addPhysicalGroup(3, [v for _, v in gmsh.model.getEntities(3)], name="fluid")
    mesh.generate(3 if layers else 2)
    return n, first


def measure(case):
    """Jacobian ratios and wall error of the mesh in the current Gmsh model (its own nodes)."""
    import gmsh

    sys.path.insert(0, HERE)
    from jacobian_ratio import model_ratios

    dim, _, r = model_ratios()
    wall = [t for d, t in gmsh.model.getPhysicalGroups(dim - 1) if gmsh.model.getPhysicalName(d, t) == "wall"]
    if len(wall) != 1:
        raise RuntimeError(f"expected one physical group 'wall' of dimension {dim - 1}, found {len(wall)}")
    _, xyz = gmsh.model.mesh.getNodesForPhysicalGroup(dim - 1, wall[0])
    xyz = np.asarray(xyz).reshape(-1, 3)
    d = ellipse_distance(xyz[:, 0], xyz[:, 1], 1.0, CASES[case]["b"])
    return {
        "elements": int(len(r)),
        "invalid": int(np.sum(r <= 0)),
        "ratio_min": float(r.min()),
        "ratio_p1": float(np.percentile(r, 1)),
        "wall_nodes": int(len(d)),
        "wall_rms": float(np.sqrt(np.mean(d * d))),
        "wall_max": float(d.max()),
    }


# ---------------------------------------------------------------- subprocess workers


def worker(kind, case, arg):
    """Runs in its own process; prints one JSON object. kind: linear (arg: output .msh), gmsh
    (arg: one of GMSH_METHODS), file (arg: a high-order .msh to measure)."""
    import gmsh

    gmsh.initialize(["-nopopup"])
    gmsh.option.setNumber("General.Terminal", 0)
    out = {}
    if kind == "file":
        gmsh.open(arg)
        out = measure(case)
    else:
        n, first = build(case)
        if kind == "linear":
            dim = 3 if CASES[case]["layers"] else 2
            tags = []
            for t in gmsh.model.mesh.getElementTypes(dim):
                tags.extend(gmsh.model.mesh.getElementsByType(t)[0])
            sj = np.array(gmsh.model.mesh.getElementQualities(tags, "minSJ"))
            gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
            gmsh.write(arg)
            out = {"elements": len(tags), "normal_cells": n, "first_height": first, "min_sj": float(np.abs(sj).min())}
        else:
            t0 = time.perf_counter()
            gmsh.model.mesh.setOrder(2)
            if arg != "setOrder(2)":
                gmsh.model.mesh.optimize(arg)
            out = {"time": time.perf_counter() - t0}
            out.update(measure(case))
    gmsh.finalize()
    print(json.dumps(out))


def run_worker(kind, case, arg, timeout):
    """The worker's JSON, or {"error": ...} when it raised, aborted or timed out."""
    cmd = [sys.executable, os.path.abspath(__file__), "--worker", kind, case, arg]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout after {timeout:.0f} s"}
    if p.returncode != 0:
        lines = [ln for ln in (p.stderr or "").splitlines() if ln.strip()]
        why = next((ln.strip() for ln in reversed(lines) if "what()" in ln or "Error" in ln), lines[-1] if lines else "")
        sig = f"signal {-p.returncode}" if p.returncode < 0 else f"exit {p.returncode}"
        return {"error": f"{sig}: {why[:200]}"}
    return json.loads(p.stdout.strip().splitlines()[-1])


def run_ours(lin, out, extra, runs, timeout):
    """Runs `polyspline curve` `runs` times; median report total and wall-clock seconds."""
    rep = out + ".json"
    totals, walls = [], []
    for _ in range(runs):
        t0 = time.perf_counter()
        try:
            p = subprocess.run([EXE, "curve", lin, "-o", out, "--order", "2", "--report", rep, "-q", *extra],
                               capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"error": f"timeout after {timeout:.0f} s"}
        if p.returncode != 0:
            lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
            return {"error": f"exit {p.returncode}: {(lines[-1] if lines else '')[:300]}"}
        walls.append(time.perf_counter() - t0)
        report = json.load(open(rep))
        totals.append(report["timings"]["total"])
    return {"time": statistics.median(totals), "wall_clock": statistics.median(walls), "runs": runs,
            "input_min_sj": report["input_min_scaled_jacobian"]}


# ---------------------------------------------------------------- driver


def bench(case, tmp, runs, timeout, gmsh_methods):
    lin = os.path.join(tmp, case + ".msh")
    info = run_worker("linear", case, lin, timeout)
    rows = []
    if "error" in info:
        return info, [{"method": "linear mesh", "error": info["error"]}]
    for name, extra in (("straight", ["--straight"]), ("ours", [])):
        out = os.path.join(tmp, f"{case}-{name}.msh")
        row = {"method": name}
        row.update(run_ours(lin, out, extra, runs, timeout))
        if "error" not in row:
            row.update(run_worker("file", case, out, timeout))
        rows.append(row)
    for m in gmsh_methods:
        row = {"method": "Gmsh " + m}
        row.update(run_worker("gmsh", case, m, timeout))
        rows.append(row)
    ref = rows[0]
    for row in rows[1:]:
        if "wall_rms" in row and "wall_rms" in ref and ref["wall_rms"] > 0:
            row["wall_rms_vs_straight"] = row["wall_rms"] / ref["wall_rms"]
            row["wall_max_vs_straight"] = row["wall_max"] / ref["wall_max"]
    if "input_min_sj" in rows[0]:
        info["polyspline_min_sj"] = rows[0]["input_min_sj"]
    return info, rows


def case_line(case, i):
    return (f"{case}: {i.get('elements')} elements, {i.get('normal_cells')} wall-normal cells, "
            f"first height {i.get('first_height', float('nan')):.3g}, linear min scaled Jacobian "
            f"{i.get('min_sj', float('nan')):.3f} (Gmsh minSJ), "
            f"{i.get('polyspline_min_sj', float('nan')):.3f} (polyspline's report)")


def fmt_row(case, info, row):
    el = info.get("elements", "")
    if "error" in row and "invalid" not in row:
        return f"| {case} | {el} | {row['method']} | **failed: {row['error']}** | | | | |"
    t = f"{row['time']:.2f}" if "time" in row else ""
    if "wall_clock" in row:
        t += f" ({row['wall_clock']:.2f} wall)"
    wall = f"{row['wall_rms']:.2e} / {row['wall_max']:.2e}"
    if "wall_rms_vs_straight" in row:
        wall += f" ({row['wall_rms_vs_straight']:.2g} / {row['wall_max_vs_straight']:.2g} × straight)"
    return (f"| {case} | {row['elements']} | {row['method']} | {row['invalid']} | {row['ratio_min']:.3g} | "
            f"{row['ratio_p1']:.3g} | {t} | {wall} |")


def main():
    if len(sys.argv) == 5 and sys.argv[1] == "--worker":
        worker(*sys.argv[2:])
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="runs of polyspline per mesh (median time)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per run or Gmsh method")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of Markdown")
    ap.add_argument("--keep", help="write the meshes into this directory instead of a temporary one")
    ap.add_argument("--table-from", metavar="JSON", help="print the table of an earlier --json run, run nothing")
    ap.add_argument("--gmsh", default=",".join(GMSH_METHODS), metavar="LIST",
                    help="Gmsh methods to run, comma-separated (empty: none; the optimisers take minutes)")
    ap.add_argument("cases", nargs="*", metavar="CASE", help=f"default: all of {', '.join(CASES)}")
    args = ap.parse_args()
    args.cases = args.cases or list(CASES)
    for c in args.cases:
        if c not in CASES:
            ap.error(f"unknown case {c!r} (cases: {', '.join(CASES)})")
    gmsh_methods = [m for m in args.gmsh.split(",") if m]
    for m in gmsh_methods:
        if m not in GMSH_METHODS:
            ap.error(f"unknown Gmsh method {m!r} (methods: {', '.join(GMSH_METHODS)})")
    if args.table_from:
        print_table(json.load(open(args.table_from)))
        return
    if not os.path.isfile(EXE):
        sys.exit(f"{EXE}: not found; run `cargo build --release` first or set POLYSPLINE")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        if args.keep:
            os.makedirs(args.keep, exist_ok=True)
            tmp = args.keep
        for case in args.cases:
            info, rows = bench(case, tmp, args.runs, args.timeout, gmsh_methods)
            results[case] = {"linear": info, "rows": rows}
            if not args.json:
                print(case_line(case, info), file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps(results, indent=1))
    else:
        print_table(results)


def print_table(results):
    print("| case | elements | method | invalid | ratio min | ratio p1 | time s | wall RMS / max error |")
    print("|---|---|---|---|---|---|---|---|")
    for case, res in results.items():
        for row in res["rows"]:
            print(fmt_row(case, res["linear"], row))
    print()
    for case, res in results.items():
        print(case_line(case, res["linear"]))


if __name__ == "__main__":
    main()
