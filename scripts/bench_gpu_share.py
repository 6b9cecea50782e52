#!/usr/bin/env python3
"""The GPU share of `curve`: per stage, where it runs under `--backend gpu`, what it moves and
dispatches (measured), its CPU-backend time at the large size, and a projected time on a
discrete GPU from a stated bandwidth and dispatch model.

usage: python3 scripts/bench_gpu_share.py [--gpu-sizes 30000,100000] [--cpu-size 1000000]
                                          [--precision f32] [--binary PATH] [--dir DIR]
                                          [--cpu-report FILE] [--gpu-report FILE ...]
                                          [--cpu-small-report FILE] [--cpu-idle-total S]
                                          [--device-gbs 500] [--pcie-gbs 16] [--dispatch-us 10]

Builds nothing: run `cargo build --release` first. Meshes are generated into DIR (default a
temporary directory; reused when present) with `generate cylinder --elements N --binary`. Each
GPU size runs `curve --order 2 --binary --backend gpu --precision P --report` once (lavapipe is
selected through VK_DRIVER_FILES when no other Vulkan driver is configured); the report's
`gpu_traffic` gives, per stage, the bytes uploaded, downloaded and bound to dispatches
(device-memory traffic), the dispatches, submits and read-backs, and the seconds the host
waited for the device. `--backend cpu` runs once at the largest GPU size and once at the CPU
size, for the stage clock. Reports already made can be given instead (`--gpu-report` once per
size, `--cpu-small-report` at the largest GPU size, `--cpu-report` at the CPU size).

Linearity: the bytes per hex (the fit's per knot pass, `knot_passes`) at the two largest GPU
sizes are shown side by side. The bytes at the CPU size are the largest GPU run's scaled by
the ratio of hexes (the fit's also by the ratio of knot passes); dispatches, submits and
read-backs are the largest GPU run's as measured (times the ratio of knot passes for the fit):
they follow the CG's iterations (which do not grow with the size, see the report's
`cg_iterations`) and the blend's rounds, not the hexes, except for one more chunk per
binding-sized slice of a stage's arrays.

Projection (an estimate, not a measurement): a stage without kernels keeps its CPU-backend
time; a stage with kernels takes its host part, the CPU-backend time at the CPU size times the
ratio measured at the largest GPU size of (GPU run's stage seconds − seconds waited for the
device) to the CPU run's stage seconds, plus device_bytes / device bandwidth + (uploaded +
downloaded) / PCIe bandwidth + (dispatches + submits) × dispatch latency. With
`--cpu-idle-total S` (an idle-machine wall time of the same job) the CPU-backend stage times are
scaled to total S before projecting, for runs measured on a loaded machine.

Prints the Markdown table with its model line.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAVAPIPE = "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json"

# The rows: (report key or None, name, where under --backend gpu). Sub-stages that the stage
# clock does not time separately name their enclosing key.
ROWS = [
    ("read", "read", "CPU"),
    ("topology", "topology", "CPU"),
    ("spline", "spline space, features, knot survey", "CPU"),
    ("fit_assembly", "fit assembly", "CPU"),
    ("fit_cg", "CG", "WGSL `spmv`, `dot_partial`, `finalize_alpha`, `update_xr`, "
     "`finalize_beta`, `update_p`; f64 residuals on the CPU"),
    ("validity", "certificate, blend rounds", "CPU screen and nets; WGSL `jacobian_check` "
     "for the undecided elements"),
    ("sample", "sample", "WGSL `evaluate`; numbering and nets on the CPU"),
    ("quality", "quality, the report's distances", "CPU"),
    ("write", "write", "CPU"),
    ("other", "report assembly, untimed (total − stages)", "CPU"),
]
# The report's `gpu_traffic` key of each row's traffic (the fit's traffic is its CG's).
TRAFFIC_KEY = {"fit_cg": "fit", "validity": "validity", "sample": "sample"}
FIELDS = ["uploaded_bytes", "downloaded_bytes", "device_bytes", "dispatches", "submits",
          "readbacks"]


def generate(binary, n, d):
    path = os.path.join(d, "cyl%d.msh" % n)
    if not os.path.exists(path):
        subprocess.run([binary, "generate", "cylinder", "--elements", str(n), "--binary",
                        "-o", path], check=True, stdout=subprocess.DEVNULL)
    return path


def curve(binary, mesh, d, tag, args):
    report = os.path.join(d, "%s.json" % tag)
    env = dict(os.environ)
    if "VK_DRIVER_FILES" not in env and os.path.exists(LAVAPIPE):
        env["VK_DRIVER_FILES"] = LAVAPIPE
    env.setdefault("XDG_RUNTIME_DIR", "/tmp")
    subprocess.run([binary, "curve", mesh, "-o", os.path.join(d, "%s.out.msh" % tag),
                    "--order", "2", "--binary", "--report", report, "-q"] + args,
                   check=True, env=env)
    with open(report) as f:
        return json.load(f)


def load(path):
    with open(path) as f:
        return json.load(f)


def stage_seconds(report):
    t = dict(report["timings"])
    parts = ["read", "topology", "spline", "fit", "validity", "sample", "snap", "periodic",
             "quality", "write"]
    t["other"] = max(0.0, t["total"] - sum(t.get(k, 0.0) for k in parts))
    return t


def fmt_bytes(b):
    for unit, s in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if b >= s:
            return "%.3g %s" % (b / s, unit)
    return "%d B" % b if b else "0"


def fmt_count(c):
    if c >= 1e6:
        return "%.3g M" % (c / 1e6)
    if c >= 1e3:
        return "%.3g k" % (c / 1e3)
    return "%d" % c


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--gpu-sizes", default="30000,100000")
    ap.add_argument("--cpu-size", type=int, default=1000000)
    ap.add_argument("--precision", default="f32", choices=["f32", "f64"])
    ap.add_argument("--binary", default=os.path.join(ROOT, "target/release/polyspline"))
    ap.add_argument("--dir")
    ap.add_argument("--cpu-report")
    ap.add_argument("--cpu-small-report")
    ap.add_argument("--gpu-report", action="append", default=[])
    ap.add_argument("--cpu-idle-total", type=float)
    ap.add_argument("--device-gbs", type=float, default=500.0)
    ap.add_argument("--pcie-gbs", type=float, default=16.0)
    ap.add_argument("--dispatch-us", type=float, default=10.0)
    a = ap.parse_args(argv)
    d = a.dir or tempfile.mkdtemp(prefix="gpu_share_")
    os.makedirs(d, exist_ok=True)

    gpu = [load(p) for p in a.gpu_report] or [
        curve(a.binary, generate(a.binary, n, d), d, "gpu%d" % n,
              ["--backend", "gpu", "--precision", a.precision])
        for n in map(int, a.gpu_sizes.split(","))]
    gpu.sort(key=lambda r: r["elements"])
    for r in gpu:
        if "gpu_traffic" not in r:
            sys.exit("the report of %d hexes has no gpu_traffic (not --backend gpu?)"
                     % r["elements"])
    r_g = gpu[-1]
    n_g = r_g["elements"]
    small = load(a.cpu_small_report) if a.cpu_small_report else curve(
        a.binary, r_g["input"], d, "cpu%d" % n_g, ["--backend", "cpu"])
    cpu = load(a.cpu_report) if a.cpu_report else curve(
        a.binary, generate(a.binary, a.cpu_size, d), d, "cpu%d" % a.cpu_size,
        ["--backend", "cpu"])
    n_big = cpu["elements"]
    cpu_t = stage_seconds(cpu)
    idle = (a.cpu_idle_total / cpu_t["total"]) if a.cpu_idle_total else 1.0
    small_t = stage_seconds(small)
    scale = n_big / n_g

    def passes(r):
        return r.get("knot_passes") or 1

    def counts(r, tk):
        """The stage's counts per hex (the fit's per knot pass)."""
        t = r["gpu_traffic"].get(tk, {})
        div = r["elements"] * (passes(r) if tk == "fit" else 1)
        return {f: t.get(f, 0) / div for f in FIELDS}

    lines = [
        "| stage (report key) | under `--backend gpu` | CPU backend s at %s hexes%s (share) "
        "| up / down | device memory | dispatches / submits / read-backs | per hex at %s "
        "(up, down, device) | projected s: host + device |" % (
            "{:,}".format(n_big), " → idle-scaled" if a.cpu_idle_total else "",
            " → ".join("{:,}".format(r["elements"]) for r in gpu[-2:])),
        "|---|---|---|---|---|---|---|---|",
    ]
    total_proj = 0.0
    for key, name, where in ROWS:
        secs = cpu_t.get(key, 0.0)
        share = "%.1f%s (%.0f %%)" % (
            secs, " → %.2f" % (secs * idle) if a.cpu_idle_total else "",
            100 * secs / cpu_t["total"])
        tk = TRAFFIC_KEY.get(key)
        if tk is None:
            total_proj += secs * idle
            lines.append("| %s (`%s`) | %s | %s | 0 | 0 | 0 | – | %.2f |" % (
                name, key, where, share, secs * idle))
            continue
        per = counts(r_g, tk)
        mult = n_big * (passes(cpu) if tk == "fit" else 1)
        t = {f: per[f] * mult for f in FIELDS if f.endswith("bytes")}
        for f in FIELDS:
            if not f.endswith("bytes"):
                t[f] = r_g["gpu_traffic"].get(tk, {}).get(f, 0) * (
                    passes(cpu) / passes(r_g) if tk == "fit" else 1)
        lin = " → ".join("%s" % "/".join("%.0f" % c[f] for f in
                                         ("uploaded_bytes", "downloaded_bytes",
                                          "device_bytes"))
                         for c in (counts(r, tk) for r in gpu[-2:]))
        device = (t["device_bytes"] / (a.device_gbs * 1e9)
                  + (t["uploaded_bytes"] + t["downloaded_bytes"]) / (a.pcie_gbs * 1e9)
                  + (t["dispatches"] + t["submits"]) * a.dispatch_us * 1e-6)
        # What stays on the host, as a share of the CPU backend's stage at the GPU size.
        waited = r_g["gpu_traffic"].get(tk, {}).get("wait_seconds", 0.0)
        ratio = max(0.0, r_g["timings"].get(key, 0.0) - waited) / small_t[key]
        host = ratio * secs * idle
        total_proj += host + device
        lines.append("| %s (`%s`; traffic `%s`) | %s | %s | %s / %s | %s | %s / %s / %s | %s "
                     "| %.2f (%.2f × CPU) + %.3f = **%.2f** |" % (
                         name, key, tk, where, share, fmt_bytes(t["uploaded_bytes"]),
                         fmt_bytes(t["downloaded_bytes"]), fmt_bytes(t["device_bytes"]),
                         fmt_count(t["dispatches"]), fmt_count(t["submits"]),
                         fmt_count(t["readbacks"]), lin, host, ratio, device,
                         host + device))
    lines.append("| total | | %.1f%s | | | | | **%.1f** |" % (
        cpu_t["total"], " → %.2f" % (cpu_t["total"] * idle) if a.cpu_idle_total else "",
        total_proj))
    print("\n".join(lines))
    print()
    print("Model (an estimate): %g GB/s device memory, %g GB/s PCIe, %g µs per dispatch and "
          "per submit%s. Bytes at %s hexes: the %s-hex GPU run's (precision %s) × %.2f, "
          "dispatches, submits and read-backs as measured there; knot "
          "passes %s (GPU runs) and %d (CPU run); CG iterations %s (GPU, point Jacobi) and "
          "%s (CPU at %s hexes)." % (
              a.device_gbs, a.pcie_gbs, a.dispatch_us,
              "; CPU stage times scaled by %.3f to the idle total %.1f s" % (
                  idle, a.cpu_idle_total) if a.cpu_idle_total else "",
              "{:,}".format(n_big), "{:,}".format(n_g), a.precision, scale,
              " / ".join(str(passes(r)) for r in gpu), passes(cpu),
              " / ".join(str(r.get("cg_iterations")) for r in gpu),
              cpu.get("cg_iterations"), "{:,}".format(n_big)))
    print("Host waits on lavapipe (s waited of the stage's s): %s." % "; ".join(
        "%s hexes: %s" % ("{:,}".format(r["elements"]), ", ".join(
            "%s %.2f of %.2f" % (k, v["wait_seconds"], r["timings"].get(
                "fit_cg" if k == "fit" else k, 0.0))
            for k, v in sorted(r["gpu_traffic"].items()) if v["readbacks"]))
        for r in gpu))
    # Anything moved outside the rows above is shown, not hidden.
    stray = {k: v for r in gpu for k, v in r["gpu_traffic"].items()
             if k not in TRAFFIC_KEY.values() and any(v.get(f, 0) for f in FIELDS)}
    if stray:
        print("Traffic in other stages: %s" % json.dumps(stray))


if __name__ == "__main__":
    main()
