#!/usr/bin/env python3
"""Smoothness, held-back elements and cell quality of `curve` on the bundled real meshes, with
graded and uniform knot intervals against the straight-sided elevation.

usage: python3 scripts/bench_smoothness.py [--timeout S] [--knots graded,uniform]
       [--no-elastic] [MESH ...]

Builds nothing: run `cargo build --release` first ($POLYSPLINE_EXE overrides the binary). For each mesh (default: every file under
meshes/real/), runs `curve` (order 2, otherwise default options) with `--knot-intervals graded`
and `uniform` (`--knots` names the modes, comma-separated), `curve --straight` and `curve
--method elastic` (the elastic analogy inside the smooth fit's boundary; `--no-elastic` skips
it), each writing MSH and a JSON report. Measures every written
file with Gmsh alone (`tests/external/facet_angles.py`: the angle between the two elements'
derivatives transversal to each interior facet at its centre, and Gmsh's Jacobian ratio per
element); Python from $POLYSPLINE_PYTHON, else python3. Prints a Markdown table: held back
(`reduced_elements` / `elements`), Q2 elements, facet angle mean / p99 / max (ours, straight,
elastic), min scaled Jacobian in → out (the report's; elastic's), Gmsh's min Jacobian ratio,
the knot surfaces graded / left uniform (report `knot_surfaces`) and the `curve` wall time
(report total). `--extra ARGS` adds options to every run but the uniform one.
"""
import argparse
import glob
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXE = os.environ.get("POLYSPLINE_EXE") or os.path.join(ROOT, "target", "release", "polyspline")
PROBE = os.path.join(ROOT, "tests", "external", "facet_angles.py")
PY = os.environ.get("POLYSPLINE_PYTHON") or "python3"


def curve(mesh, out, report, extra, timeout):
    cmd = [EXE, "curve", mesh, "-o", out, "--report", report] + extra
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, "timeout"
    if p.returncode != 0:
        return None, p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "failed"
    with open(report) as f:
        return json.load(f), None


def measure(files):
    p = subprocess.run([PY, PROBE] + files, capture_output=True, text=True, check=True)
    return json.loads(p.stdout)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--timeout", type=float, default=900)
    ap.add_argument("--extra", default="", help="more options of every run but the uniform one")
    ap.add_argument("--knots", default="graded,uniform")
    ap.add_argument("--no-elastic", action="store_true")
    ap.add_argument("meshes", nargs="*")
    a = ap.parse_args()
    meshes = a.meshes or sorted(
        f for f in glob.glob(os.path.join(ROOT, "meshes", "real", "*", "*"))
        if not f.endswith(".md"))
    tmp = tempfile.mkdtemp(prefix="smoothness-")
    print("| mesh | knots | held back | Q2 | facet angle mean / p99 / max | straight | elastic | "
          "min scaled Jacobian in → out | elastic | Jacobian ratio min (straight) | "
          "surfaces graded / uniform | curve s |")
    print("|---|---|---:|---:|---|---|---|---|---|---|---|---:|")
    knots = a.knots.split(",")
    for mesh in meshes:
        name = os.path.relpath(mesh, os.path.join(ROOT, "meshes", "real"))
        base = os.path.join(tmp, name.replace("/", "_"))
        runs = {}
        modes = [(k, ["--knot-intervals", k] + (a.extra.split() if k != "uniform" else []))
                 for k in knots] + [("straight", ["--straight"])]
        if not a.no_elastic:
            modes.append(("elastic", ["--method", "elastic"]))
        for mode, extra in modes:
            out = base + "_" + mode + ".msh"
            rep, err = curve(mesh, out, base + "_" + mode + ".json", extra, a.timeout)
            runs[mode] = (out, rep, err)
        if runs["straight"][1] is None:
            print("| %s | | %s |" % (name, runs["straight"][2]))
            continue
        ok = [k for k, _ in modes if runs[k][1] is not None]
        try:
            m = dict(zip(ok, measure([runs[k][0] for k in ok])))
        except subprocess.CalledProcessError as e:
            print("| %s | | Gmsh probe failed: %s |" % (name, e.stderr.strip()[-200:]))
            continue
        s = m["straight"]
        el = m.get("elastic")
        el_angles = ("%.2f° / %.1f° / %.1f°" % (el["angle_mean"], el["angle_p99"], el["angle_max"])
                     if el else runs.get("elastic", (None, None, "–"))[2])
        el_msj = "%.3f" % runs["elastic"][1]["min_scaled_jacobian"] if el else "–"
        for k in knots:
            out, rep, err = runs[k]
            if rep is None:
                print("| %s | %s | %s |" % (name, k, err))
                continue
            g = m[k]
            ks = rep.get("knot_surfaces")
            surf = "%d / %d" % (ks["graded"], ks["surfaces"] - ks["graded"]) if ks else "–"
            print("| %s | %s | %.0f %% | %.0f %% | %.2f° / %.1f° / %.1f° | %.2f° / %.1f° / %.1f° | "
                  "%s | %.3f → %.3f | %s | %.3f (%.3f) | %s | %.2f |" % (
                      name, k, 100.0 * rep["reduced_elements"] / rep["elements"],
                      100.0 * rep["q2_elements"] / rep["elements"],
                      g["angle_mean"], g["angle_p99"], g["angle_max"],
                      s["angle_mean"], s["angle_p99"], s["angle_max"], el_angles,
                      rep["input_min_scaled_jacobian"], rep["min_scaled_jacobian"], el_msj,
                      g["ratio_min"], s["ratio_min"], surf, rep["timings"]["total"]))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
