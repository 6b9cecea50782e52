#!/usr/bin/env python3
"""Interleaved A/B of criterion bench binaries of two builds: medians and ratios.

    scripts/bench_criterion_ab.py A_DIR B_DIR [--rounds 3] [--bench NAME=FILTER ...]

A_DIR and B_DIR are the `target/release/deps` directories of two builds made with
`cargo bench --no-run --bench stages --bench fit --bench spline`. Each round runs every bench
binary of A, then of B, with the filter given (criterion's regex on benchmark ids), each with
its own CRITERION_HOME, and reads criterion's median estimate of every benchmark
(`new/estimates.json`). Prints per benchmark the median over rounds of A's and B's medians and
B/A: on a loaded machine the ratio of interleaved runs is the figure to quote, not the times.
"""
import argparse
import glob
import json
import os
import statistics
import subprocess
import tempfile

DEFAULT = [
    "stages=stages/(assembly|cg_block_jacobi|certificate|sample_p2)/",
    "fit=fit/(assemble|apply_assembled|apply_matrix_free)/8000",
    "spline=spline_bezier_nets",
]


def binary(deps, name):
    found = [p for p in glob.glob(os.path.join(deps, f"{name}-*"))
             if os.access(p, os.X_OK) and not p.endswith(".d")]
    if not found:
        raise SystemExit(f"no bench binary {name} in {deps}")
    return max(found, key=os.path.getmtime)


def medians(home):
    out = {}
    for est in glob.glob(os.path.join(home, "**", "new", "estimates.json"), recursive=True):
        bench = json.load(open(os.path.join(os.path.dirname(est), "benchmark.json")))
        out[bench["full_id"]] = json.load(open(est))["median"]["point_estimate"]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--bench", action="append", help="NAME=FILTER (default: %s)" % DEFAULT)
    ap.add_argument("--sizes", default="10000", help="POLYSPLINE_BENCH_SIZES of the stages bench")
    ap.add_argument("--measurement-time", default="3")
    args = ap.parse_args()
    benches = [b.split("=", 1) for b in (args.bench or DEFAULT)]
    results = {"A": {}, "B": {}}
    env = dict(os.environ, POLYSPLINE_BENCH_SIZES=args.sizes)
    with tempfile.TemporaryDirectory(prefix="polyspline-crit-") as tmp:
        for r in range(args.rounds):
            for who, deps in (("A", args.a), ("B", args.b)):
                for name, filt in benches:
                    home = os.path.join(tmp, f"{who}{r}{name}")
                    cmd = [binary(deps, name), "--bench", filt, "--noplot", "--warm-up-time", "1",
                           "--measurement-time", args.measurement_time]
                    subprocess.run(cmd, env=dict(env, CRITERION_HOME=home), check=True,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                    for k, v in medians(home).items():
                        results[who].setdefault(k, []).append(v)
            print(f"round {r + 1} done", flush=True)
    print(f"{'benchmark (median of per-run medians)':<44}{'A ms':>9}{'B ms':>9}{'B/A':>6}"
          f"  {'per-round B/A':<20}")
    for k in sorted(results["A"]):
        ra, rb = results["A"][k], results["B"].get(k, [float("nan")])
        a, b = statistics.median(ra) / 1e6, statistics.median(rb) / 1e6
        rounds = " ".join(f"{y / x:.2f}" for x, y in zip(ra, rb))
        print(f"{k:<44}{a:>9.3f}{b:>9.3f}{b / a:>6.2f}  {rounds}")


if __name__ == "__main__":
    main()
