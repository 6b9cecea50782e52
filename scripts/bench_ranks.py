#!/usr/bin/env python3
"""The distributed `curve` against the serial run: largest node distance per element over the
bounding-box diagonal, CG iterations and wall time, at each rank count.

Generates a binary cylinder of about ELEMENTS hexes (or takes `--input`, a binary MSH 4.1
file), runs the serial `curve` and `mpirun --oversubscribe -np N` for each N, all with the same
extra options (the knots too: under mpirun `auto` chooses them as the serial run does), and
prints one row per run: CG iterations, the knots used (intervals and passes), wall time, peak
memory (the serial run's one thread; the largest rank's) and the largest node distance. Nodes
are compared element by element (the same element tags, the same node order in each element),
read with Gmsh's Python API (`POLYSPLINE_PYTHON` or this interpreter must import gmsh).

    cargo build --release --features mpi
    python3 scripts/bench_ranks.py --elements 300000 --ranks 2 4 [-- EXTRA CURVE OPTIONS]
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.environ.get("POLYSPLINE_BIN", os.path.join(ROOT, "target", "release", "polyspline"))


def run(cmd, env=None):
    t = time.time()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return time.time() - t


def serial_peak(cmd, env):
    """Wall seconds and peak resident memory (bytes) of one process."""
    import resource

    t = time.time()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return time.time() - t, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024


def knots(r):
    return f"{r.get('knot_intervals')} ({r.get('knot_passes')} pass{'es' if r.get('knot_passes') != 1 else ''})"


def element_nodes(path):
    """Element tag → row of node coordinates (volume elements), and the bounding-box diagonal."""
    import gmsh

    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(path)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    xyz = np.zeros((int(tags.max()) + 1, 3))
    xyz[tags.astype(np.int64)] = coords.reshape(-1, 3)
    types, etags, enodes = gmsh.model.mesh.getElements(3)
    gmsh.finalize()
    out = {}
    for t, e, n in zip(types, etags, enodes):
        n = n.astype(np.int64).reshape(len(e), -1)
        out[int(t)] = (e.astype(np.int64), xyz[n])
    lo, hi = coords.reshape(-1, 3).min(0), coords.reshape(-1, 3).max(0)
    return out, float(np.linalg.norm(hi - lo))


def largest_distance(a, b):
    worst = 0.0
    for t, (ea, xa) in a.items():
        eb, xb = b[t]
        ia, ib = np.argsort(ea), np.argsort(eb)
        assert np.array_equal(ea[ia], eb[ib]), "different element tags"
        d = np.linalg.norm(xa[ia] - xb[ib], axis=2).max()
        worst = max(worst, float(d))
    return worst


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--elements", type=int, default=1500)
    p.add_argument("--ranks", type=int, nargs="+", default=[2, 4])
    p.add_argument("--input", default=None, help="a binary MSH 4.1 mesh instead of the cylinder")
    p.add_argument("--tmp", default=None)
    p.add_argument("extra", nargs="*")
    a = p.parse_args()
    tmp = a.tmp or tempfile.mkdtemp(prefix="ranks")
    mesh = a.input or os.path.join(tmp, f"cylinder{a.elements}.msh")
    if not os.path.exists(mesh):
        run([BIN, "generate", "cylinder", "--elements", str(a.elements), "--binary", "-o", mesh])
    env = dict(os.environ, OMPI_MCA_mpi_yield_when_idle="1", RAYON_NUM_THREADS="1",
               OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    s_out, s_rep = os.path.join(tmp, "serial.msh"), os.path.join(tmp, "serial.json")
    wall, peak = serial_peak([BIN, "curve", mesh, "-o", s_out, "-q", "--report", s_rep, *a.extra], env)
    serial, diag = element_nodes(s_out)
    r = json.load(open(s_rep))
    print(f"{os.path.basename(mesh)}: {r['elements']} elements, diagonal {diag:.4g}; options: {' '.join(a.extra) or 'default'}")
    print("| run | CG iterations | knots | wall s | peak MB | largest node distance / diagonal |")
    print("|---|---|---|---|---|---|")
    print(f"| serial | {r['cg_iterations']} | {knots(r)} | {wall:.2f} | {peak / 1e6:.0f} | — |")
    for np_ in a.ranks:
        out, rep = os.path.join(tmp, f"np{np_}.msh"), os.path.join(tmp, f"np{np_}.json")
        wall = run(["mpirun", "--oversubscribe", "-np", str(np_), BIN, "curve", mesh, "-o", out,
                    "-q", "--report", rep, *a.extra], env)
        d = largest_distance(serial, element_nodes(out)[0]) / diag
        r = json.load(open(rep))
        peak = max(f["peak_memory_bytes"] for f in r.get("per_rank") or [{"peak_memory_bytes": 0}])
        print(f"| {np_} ranks | {r['cg_iterations']} | {knots(r)} | {wall:.2f} | {peak / 1e6:.0f} | {d:.2e} |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
