#!/usr/bin/env python3
"""Per-rank work, ghosts, halo, communication volume and memory of the distributed `curve`.

Strong scaling (default): generates a cylinder of about ELEMENTS hexes, runs the serial
`curve` (its peak memory from the kernel's rusage) and `mpirun --oversubscribe -np N
polyspline curve` for each N and each partition (`--partitions morton file-order`: the Morton
repartition after the read, or the file's runs kept, `POLYSPLINE_PARTITION`), and prints one
markdown table per run from the JSON reports (`per_rank`) and a summary line per run.

Weak scaling (`--weak E`): a cylinder of about E × N hexes for each N, so each rank holds
about E hexes.

`--json OUT` writes the summaries (one object per run) for the model in docs/benchmarks-history.md.
On a machine with fewer cores than ranks the wall times are not scaling figures: read the
volumes (elements, ghosts, halo, bytes, CG iterations).

    cargo build --release --features mpi
    python3 scripts/bench_distributed.py --elements 60000 --ranks 2 4
    python3 scripts/bench_distributed.py --weak 15000 --ranks 1 2 4 --partitions morton
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


def generate(tmp, elements):
    mesh = os.path.join(tmp, f"cylinder{elements}.msh")
    if not os.path.exists(mesh):
        # Binary MSH 4.1: each rank reads its run by offsets.
        run([BIN, "generate", "cylinder", "--elements", str(elements), "--binary", "-o", mesh])
    return mesh


def serial_run(tmp, mesh, env):
    out = os.path.join(tmp, "serial.json")
    run(["/usr/bin/time", "-f", "%M %U %S", "-o", out + ".time", BIN, "curve", mesh,
         "-o", os.path.join(tmp, "serial.msh"), "-q", "--report", out], env)
    s = json.load(open(out))
    kb, user, sys_ = open(out + ".time").read().split()[-3:]
    t = s["timings"]
    print(f"cylinder: {s['elements']} hexes, {s['control_points']} control points, "
          f"{s['cg_iterations']} CG iterations (serial, block Jacobi); peak {int(kb) / 1024:.0f} MB, "
          f"CPU {float(user) + float(sys_):.2f} s; wall: fit assembly {t.get('fit_assembly', 0):.2f} s, "
          f"CG {t.get('fit_cg', 0):.2f} s, validity {t['validity']:.2f} s, total {t['total']:.2f} s")
    s["cpu_s"] = float(user) + float(sys_)
    s["peak_bytes"] = int(kb) * 1024
    return s, int(kb) * 1024


def per_rank_table(r, serial_peak):
    print("| rank | elements | ghosts | control points | owned | shared (halo) | neighbours "
          "| K nonzeros | sent MB: fit / blend / nets | peak MB | peak / serial | assembly s | CG s | validity s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for f in r["per_rank"]:
        ft = f["timings"]
        print(f"| {f['rank']} | {f['elements']} | {f['ghost_elements']} | {f['control_points']} | "
              f"{f['owned_control_points']} | {f['shared_control_points']} | {f['neighbours']} | "
              f"{f['matrix_nonzeros']} | {f['bytes_fit'] / 1e6:.2f} / {f['bytes_validity'] / 1e6:.3f} / "
              f"{f['bytes_gather'] / 1e6:.2f} | "
              f"{f['peak_memory_bytes'] / 2**20:.0f} | {f['peak_memory_bytes'] / serial_peak:.2f} | "
              f"{ft['fit_assembly']:.2f} | {ft['fit_cg']:.2f} | {ft['validity']:.2f} |")


def summary(r, n, partition, serial):
    per = r["per_rank"]
    tot = lambda k: sum(f[k] for f in per)
    mx = lambda k: max(f[k] for f in per)
    s = {
        "ranks": n, "partition": partition, "hexes": r["elements"],
        "elements_max": mx("elements"), "ghosts_sum": tot("ghost_elements"),
        "ghosts_max": mx("ghost_elements"),
        "ghost_share": tot("ghost_elements") / tot("elements"),
        "shared_sum": tot("shared_control_points"), "shared_max": mx("shared_control_points"),
        "rows_max": mx("control_points"), "neighbours_max": mx("neighbours"),
        "fit_bytes_max": mx("bytes_fit"), "validity_bytes_max": mx("bytes_validity"),
        "gather_bytes_sum": tot("bytes_gather"), "bytes_max": mx("bytes_sent"),
        "cg_iterations": r["cg_iterations"], "serial_cg_iterations": serial["cg_iterations"],
        "peak_max": mx("peak_memory_bytes"), "total_s": r["timings"]["total"],
        "serial": {k: serial[k] for k in ["elements", "cpu_s", "peak_bytes", "timings",
                                          "cg_iterations"]},
    }
    print(f"summary: {n} ranks, {partition}: ghosts {s['ghosts_sum']} = {s['ghost_share']:.3f} × "
          f"own elements (max {s['ghosts_max']} on a rank), halo {s['shared_sum']} shared control "
          f"points (max {s['shared_max']}, {s['neighbours_max']} neighbours), CG {s['cg_iterations']} "
          f"iterations, fit bytes max {s['fit_bytes_max'] / 1e6:.2f} MB, wall {s['total_s']:.1f} s")
    return s


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--elements", type=int, default=50000)
    ap.add_argument("--weak", type=int, default=0, help="hexes per rank (weak scaling)")
    ap.add_argument("--ranks", type=int, nargs="+", default=[2, 4])
    ap.add_argument("--partitions", nargs="+", default=["morton", "file-order"],
                    choices=["morton", "file-order"])
    ap.add_argument("--threads", type=int, default=1, help="rayon threads per process")
    ap.add_argument("--json", help="write the summaries here")
    ap.add_argument("--model", nargs="+", metavar="JSON",
                    help="print the model at 10^8 hexes from these summaries (no runs)")
    args = ap.parse_args()
    if args.model:
        model([s for f in args.model for s in json.load(open(f))])
        return
    env = dict(os.environ, RAYON_NUM_THREADS=str(args.threads),
               OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_mpi_yield_when_idle="1")
    tmp = tempfile.mkdtemp(prefix="bench_distributed_")
    summaries = []
    serial, serial_peak = None, None
    for n in args.ranks:
        mesh = generate(tmp, args.weak * n if args.weak else args.elements)
        if args.weak or serial is None:
            serial, serial_peak = serial_run(tmp, mesh, env)
        if n == 1:
            continue
        for partition in args.partitions:
            rep = os.path.join(tmp, f"np{n}_{partition}.json")
            run(["mpirun", "--oversubscribe", "-np", str(n), BIN, "curve", mesh,
                 "-o", os.path.join(tmp, f"np{n}.msh"), "-q", "--report", rep],
                dict(env, POLYSPLINE_PARTITION=partition))
            r = json.load(open(rep))
            print()
            print(f"### {n} ranks, {partition} partition: {r['cg_iterations']} CG iterations, "
                  f"relative residual {r['cg_rel_residual']:.2e}")
            print()
            per_rank_table(r, serial_peak)
            summaries.append(summary(r, n, partition, serial))
    if args.json:
        json.dump(summaries, open(args.json, "w"), indent=1)


def model(runs, hexes=1e8, ranks=(64, 128, 256, 512, 1024)):
    """Time and memory per rank at `hexes` hexes from the measured Morton runs.

    Per-hex costs: the serial run's CPU time and peak memory divided by its hexes, the CPU
    time split over the stages in proportion to their wall times (one thread); the CG's
    share per iteration. Halo and ghosts: s = c n^(2/3) shared control points and
    g = k n^(2/3) ghost elements for n hexes per rank (surface over volume), c and k the
    largest measured over the Morton runs (an interior rank of a large job has more
    neighbours than the measured ones: c and k are scaled by 6 faces / the measured
    neighbours, at most 3). Network: 10 GB/s, 2 us per reduction step (log2 P steps, 3
    all-reduces per CG iteration). CG iterations: the largest measured.
    """
    import math
    m = [r for r in runs if r["partition"] == "morton"]
    if not m:
        sys.exit("no Morton runs in the summaries")
    s = m[0]["serial"]
    t = s["timings"]
    stages = {k: t.get(k, 0.0) for k in ["read", "topology", "spline", "fit_assembly", "fit_cg",
                                         "validity", "sample", "quality", "write"]}
    wall = sum(stages.values())
    per_hex = {k: s["cpu_s"] * v / wall / s["elements"] for k, v in stages.items()}
    cg_iter = per_hex.pop("fit_cg") / s["cg_iterations"]
    mem_hex = s["peak_bytes"] / s["elements"]
    scale = lambda r: min(3.0, 6.0 / max(r["neighbours_max"], 1))
    c = max(r["shared_max"] / r["elements_max"] ** (2 / 3) * scale(r) for r in m)
    k = max(r["ghosts_max"] / r["elements_max"] ** (2 / 3) * scale(r) for r in m)
    iters = max(r["cg_iterations"] for r in m)
    print(f"per hex (CPU, from {s['elements']} hexes serial): "
          + ", ".join(f"{a} {v * 1e6:.2f} us" for a, v in per_hex.items())
          + f"; CG iteration {cg_iter * 1e6:.3f} us; memory {mem_hex / 1e3:.2f} KB")
    print(f"halo: s = {c:.1f} n^(2/3) shared control points, ghosts = {k:.1f} n^(2/3) elements; "
          f"{iters} CG iterations")
    print()
    print("| ranks P | hexes per rank n | ghosts (share) | shared points s | CG iteration: compute / halo / "
          "reductions | CG total | whole job per rank | memory per rank | nets to rank 0 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for p in ranks:
        n = hexes / p
        g = k * n ** (2 / 3)
        sh = c * n ** (2 / 3)
        comp = n * cg_iter
        halo = 24 * sh / 10e9
        red = 3 * 2e-6 * math.log2(p)
        cg = iters * (comp + halo + red)
        setup = (n + g) * (per_hex["read"] + per_hex["topology"] + per_hex["spline"])
        own = n * (per_hex["fit_assembly"] + per_hex["validity"])
        job = setup + own + cg
        mem = mem_hex * (n + g)
        print(f"| {p} | {n / 1e6:.2f}M | {g / 1e3:.0f}k ({g / n:.2f}) | {sh / 1e3:.0f}k | "
              f"{comp * 1e3:.1f} ms / {halo * 1e3:.2f} ms / {red * 1e3:.3f} ms | {cg:.0f} s | "
              f"{job:.0f} s | {mem / 1e9:.2f} GB | {648 * hexes / 1e9:.0f} GB |")


if __name__ == "__main__":
    main()
