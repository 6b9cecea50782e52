#!/usr/bin/env python3
"""Per-rank work, halo, communication volume and memory of the distributed `curve`.

Generates a cylinder of about ELEMENTS hexes, runs the serial `curve` (its peak memory from
the kernel's rusage) and `mpirun --oversubscribe -np N polyspline curve` for each N, and
prints one markdown table per run from the JSON reports (`per_rank`). On a machine with fewer
cores than ranks the wall times are not scaling figures: read the volumes.

    cargo build --release --features mpi
    python3 scripts/bench_distributed.py --elements 50000 --ranks 2 4
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.environ.get("POLYSPLINE_BIN", os.path.join(ROOT, "target", "release", "polyspline"))


def run(cmd, env=None):
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{r.stderr}")
    return r


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--elements", type=int, default=50000)
    ap.add_argument("--ranks", type=int, nargs="+", default=[2, 4])
    ap.add_argument("--threads", type=int, default=1, help="rayon threads per process")
    args = ap.parse_args()
    env = dict(os.environ, RAYON_NUM_THREADS=str(args.threads),
               OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    tmp = tempfile.mkdtemp(prefix="bench_distributed_")
    mesh = os.path.join(tmp, "cylinder.msh")
    # Binary MSH 4.1: each rank reads its share by offsets.
    run([BIN, "generate", "cylinder", "--elements", str(args.elements), "--binary", "-o", mesh])
    serial = os.path.join(tmp, "serial.json")
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    run([BIN, "curve", mesh, "-o", os.path.join(tmp, "serial.msh"), "-q", "--report", serial], env)
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    s = json.load(open(serial))
    t = s["timings"]
    print(f"cylinder: {s['elements']} hexes, {s['control_points']} control points, "
          f"{s['cg_iterations']} CG iterations (serial, block Jacobi)")
    print(f"serial: peak memory {peak / 1024:.0f} MB (max over the runs so far: {before / 1024:.0f} MB before), "
          f"fit assembly {t.get('fit_assembly', 0):.2f} s, CG {t.get('fit_cg', 0):.2f} s, "
          f"validity {t['validity']:.2f} s, total {t['total']:.2f} s")
    for n in args.ranks:
        rep = os.path.join(tmp, f"np{n}.json")
        run(["mpirun", "--oversubscribe", "-np", str(n), BIN, "curve", mesh,
             "-o", os.path.join(tmp, f"np{n}.msh"), "-q", "--report", rep], env)
        r = json.load(open(rep))
        print()
        print(f"### {n} ranks: {r['cg_iterations']} CG iterations (block Jacobi), "
              f"relative residual {r['cg_rel_residual']:.2e}")
        print()
        print("| rank | elements | ghosts | control points | owned | shared (halo) | neighbours "
              "| K nonzeros | sent MB: fit / blend / nets | peak MB | peak / serial | assembly s | CG s | validity s |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for f in r["per_rank"]:
            ft = f["timings"]
            print(f"| {f['rank']} | {f['elements']} | {f['ghost_elements']} | {f['control_points']} | "
                  f"{f['owned_control_points']} | {f['shared_control_points']} | {f['neighbours']} | "
                  f"{f['matrix_nonzeros']} | {f['bytes_fit'] / 1e6:.2f} / {f['bytes_validity'] / 1e6:.3f} / "
                  f"{f['bytes_gather'] / 1e6:.2f} | "
                  f"{f['peak_memory_bytes'] / 2**20:.0f} | {f['peak_memory_bytes'] / 1024 / peak:.2f} | "
                  f"{ft['fit_assembly']:.2f} | "
                  f"{ft['fit_cg']:.2f} | {ft['validity']:.2f} |")


if __name__ == "__main__":
    main()
