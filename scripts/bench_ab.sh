#!/usr/bin/env bash
# Same-run A/B of two polyspline builds: alternate A and B on one mesh, N runs each, and print
# the median wall time, CPU time (user + sys), peak RSS and per-stage seconds (from --report).
# Interleaving the runs exposes both builds to the same background load.
#
#   scripts/bench_ab.sh A_BINARY B_BINARY MESH [RUNS=5] [-- extra curve options]
#   e.g. git worktree add /tmp/base main && (cd /tmp/base && cargo build --release)
#        scripts/bench_ab.sh /tmp/base/target/release/polyspline target/release/polyspline cyl50k.msh 5
set -euo pipefail
a=$1 b=$2 mesh=$3 runs=${4:-5}
shift $(( $# < 4 ? $# : 4 ))
[ "${1:-}" = "--" ] && shift
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for i in $(seq "$runs"); do
    for who in A B; do
        bin=$a; [ "$who" = B ] && bin=$b
        /usr/bin/time -f "%e %U %S %M" -o "$tmp/$who.$i.time" \
            "$bin" curve "$mesh" -o "$tmp/out.msh" --report "$tmp/$who.$i.json" "$@" >/dev/null 2>"$tmp/log" || { cat "$tmp/log"; exit 1; }
    done
done
python3 - "$tmp" "$runs" <<'PY'
import json, statistics, sys
tmp, runs = sys.argv[1], int(sys.argv[2])
med = statistics.median
rows = {}
for who in "AB":
    t = [open(f"{tmp}/{who}.{i}.time").read().split() for i in range(1, runs + 1)]
    r = [json.load(open(f"{tmp}/{who}.{i}.json"))["timings"] for i in range(1, runs + 1)]
    rows[who] = {"wall s": med(float(x[0]) for x in t),
                 "cpu s": med(float(x[1]) + float(x[2]) for x in t),
                 "peak MB": med(int(x[3]) for x in t) / 1024}
    for k in sorted(r[0]):
        rows[who][k] = med(x[k] for x in r)
print(f"{'median of ' + str(runs):<16}{'A':>10}{'B':>10}{'B/A':>8}")
for k in rows["A"]:
    va, vb = rows["A"][k], rows["B"].get(k, float("nan"))
    print(f"{k:<16}{va:>10.3f}{vb:>10.3f}{(vb / va if va else float('nan')):>8.2f}")
PY
