#!/usr/bin/env python3
"""The GPU share of `curve`: per stage, where it runs under `--backend gpu`, what it moves and
dispatches (measured), its CPU-backend time at the large size, and a projected time on a
discrete GPU from a stated bandwidth and dispatch model.

usage: python3 scripts/bench_gpu_share.py [--gpu-sizes 100000,300000] [--cpu-size 1000000]
                                          [--precision f32] [--binary PATH] [--dir DIR]
                                          [--cpu-report FILE] [--gpu-report N=FILE ...]
                                          [--device-gbs 500] [--pcie-gbs 16] [--dispatch-us 10]

Builds nothing: run `cargo build --release` first. Meshes are generated into DIR (default a
temporary directory; reused when present) with `generate cylinder --elements N --binary`. Each
GPU size runs `curve --order 2 --binary --backend gpu --precision P --report` once (lavapipe is
selected through VK_DRIVER_FILES when no other Vulkan driver is configured); the report's
`gpu_traffic` gives, per stage, the bytes uploaded, downloaded and bound to dispatches
(device-memory traffic), the dispatches, submits and read-backs, and the seconds the host
waited for the device. The CPU size runs `--backend cpu` once for the stage clock. Reports
already made can be given instead (`--cpu-report`, `--gpu-report 98304=g.json`: N the mesh's
hexes).

The counts are checked to scale linearly: per hex at the two largest GPU sizes (a ratio ≠ 1
by more than 25 % is flagged with `!`); the figures at the CPU size are the largest GPU size's
scaled by the ratio of hexes. Projection (an estimate, not a measurement): a stage with
kernels takes its host seconds (measured: the stage's seconds in the largest GPU run minus the
seconds the host waited for the device there, scaled by the ratio of hexes) plus
device_bytes / device bandwidth + (uploaded + downloaded) / PCIe bandwidth + (dispatches +
submits) × the dispatch latency; a stage without kernels keeps its CPU-backend time.

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
    ("read", "read", "CPU (MSH parse)"),
    ("topology", "topology", "CPU (face/edge hashing)"),
    ("spline", "spline space, features, knot survey", "CPU (graph work on the boundary)"),
    ("fit_assembly", "fit assembly", "CPU (per-element blocks, scatter into CSR)"),
    ("fit_cg", "CG", "WGSL `spmv`, `dot_partial`, `finalize_alpha`, `update_xr`, "
     "`finalize_beta`, `update_p`; f64 residual of each refinement round on the CPU"),
    ("validity", "certificate and blend rounds", "CPU screen and nets per round; WGSL "
     "`jacobian_check` for the elements the screen leaves undecided"),
    ("sample", "sample", "WGSL `evaluate` for the nodes; numbering and nets on the CPU"),
    ("quality", "quality and the report's boundary distances", "CPU (sampled det J, distances)"),
    ("write", "write", "CPU (binary MSH)"),
    ("other", "report and untimed (total − stages)", "CPU"),
]
# The report's `gpu_traffic` key of each row's traffic (the fit's traffic is its CG's).
TRAFFIC_KEY = {"fit_cg": "fit", "validity": "validity", "sample": "sample"}


def generate(binary, n, d):
    path = os.path.join(d, "cyl%d.msh" % n)
    if not os.path.exists(path):
        subprocess.run([binary, "generate", "cylinder", "--elements", str(n), "--binary",
                        "-o", path, "-q"], check=True, stdout=subprocess.DEVNULL)
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
    ap.add_argument("--gpu-sizes", default="100000,300000")
    ap.add_argument("--cpu-size", type=int, default=1000000)
    ap.add_argument("--precision", default="f32", choices=["f32", "f64"])
    ap.add_argument("--binary", default=os.path.join(ROOT, "target/release/polyspline"))
    ap.add_argument("--dir")
    ap.add_argument("--cpu-report")
    ap.add_argument("--gpu-report", action="append", default=[])
    ap.add_argument("--device-gbs", type=float, default=500.0)
    ap.add_argument("--pcie-gbs", type=float, default=16.0)
    ap.add_argument("--dispatch-us", type=float, default=10.0)
    a = ap.parse_args(argv)
    d = a.dir or tempfile.mkdtemp(prefix="gpu_share_")
    os.makedirs(d, exist_ok=True)

    gpu = []  # (hexes, report)
    for spec in a.gpu_report:
        n, path = spec.split("=", 1)
        gpu.append((int(n), load(path)))
    if not gpu:
        for n in map(int, a.gpu_sizes.split(",")):
            r = curve(a.binary, generate(a.binary, n, d), d, "gpu%d" % n,
                      ["--backend", "gpu", "--precision", a.precision])
            gpu.append((r["elements"], r))
    gpu.sort(key=lambda x: x[0])
    for n, r in gpu:
        if "gpu_traffic" not in r:
            sys.exit("the report of %d hexes has no gpu_traffic (not --backend gpu?)" % n)
    cpu = load(a.cpu_report) if a.cpu_report else curve(
        a.binary, generate(a.binary, a.cpu_size, d), d, "cpu%d" % a.cpu_size,
        ["--backend", "cpu"])
    n_big = cpu["elements"]
    cpu_t = stage_seconds(cpu)
    n_g, r_g = gpu[-1]
    scale = n_big / n_g

    def per_hex(r, n, key, field):
        return r["gpu_traffic"].get(key, {}).get(field, 0) / n

    fields = ["uploaded_bytes", "downloaded_bytes", "device_bytes", "dispatches", "submits",
              "readbacks"]
    lines = []
    lines.append("| stage (report key) | under `--backend gpu` | CPU backend s at %s hexes "
                 "(share) | up / down at %s (measured at %s, ×%.2f) | device memory | "
                 "dispatches / submits / read-backs | per hex %s → %s (up, device) | "
                 "projected s |" % ("{:,}".format(n_big), "{:,}".format(n_big),
                                    "{:,}".format(n_g), scale,
                                    "{:,}".format(gpu[0][0]), "{:,}".format(n_g)))
    lines.append("|---|---|---|---|---|---|---|---|")
    total_cpu, total_proj = cpu_t["total"], 0.0
    for key, name, where in ROWS:
        secs = cpu_t.get(key, 0.0)
        tk = TRAFFIC_KEY.get(key)
        share = "%.2f (%d %%)" % (secs, round(100 * secs / total_cpu))
        if tk is None:
            # Every stage without a row of its own must have moved nothing.
            lines.append("| %s (`%s`) | %s | %s | 0 | 0 | 0 | – | %.2f |" % (
                name, key, where, share, secs))
            total_proj += secs
            continue
        t = {f: r_g["gpu_traffic"].get(tk, {}).get(f, 0) * scale for f in fields}
        lin = []
        for f in ("uploaded_bytes", "device_bytes"):
            a0 = per_hex(gpu[0][1], gpu[0][0], tk, f)
            a1 = per_hex(r_g, n_g, tk, f)
            flag = "" if a0 == 0 or abs(a1 / a0 - 1) <= 0.25 else " !"
            lin.append("%.0f → %.0f B%s" % (a0, a1, flag))
        device = (t["device_bytes"] / (a.device_gbs * 1e9)
                  + (t["uploaded_bytes"] + t["downloaded_bytes"]) / (a.pcie_gbs * 1e9)
                  + (t["dispatches"] + t["submits"]) * a.dispatch_us * 1e-6)
        # What stays on the host: the GPU run's stage time less its waits for the device.
        host = max(0.0, r_g["timings"].get(key, 0.0)
                   - r_g["gpu_traffic"].get(tk, {}).get("wait_seconds", 0.0)) * scale
        proj = host + device
        total_proj += proj
        lines.append("| %s (`%s`; traffic `%s`) | %s | %s | %s / %s | %s | %s / %s / %s | "
                     "%s | %.2f host + %.3f device = **%.2f** |" % (
                         name, key, tk, where, share, fmt_bytes(t["uploaded_bytes"]),
                         fmt_bytes(t["downloaded_bytes"]), fmt_bytes(t["device_bytes"]),
                         fmt_count(t["dispatches"]), fmt_count(t["submits"]),
                         fmt_count(t["readbacks"]), ", ".join(lin), host, device, proj))
    lines.append("| total | | %.2f | | | | | **%.1f** |" % (total_cpu, total_proj))
    # Anything the GPU run moved outside the rows above is shown, not hidden.
    stray = {k: v for k, v in r_g["gpu_traffic"].items()
             if k not in TRAFFIC_KEY.values() and any(v.get(f, 0) for f in fields)}
    print("\n".join(lines))
    print()
    print("Model (an estimate): %g GB/s device memory, %g GB/s PCIe, %g µs per dispatch and "
          "per submit. GPU runs: %s; precision %s; "
          "CG iterations %s (GPU, point Jacobi) vs %s (CPU)." % (
              a.device_gbs, a.pcie_gbs, a.dispatch_us,
              ", ".join("{:,}".format(n) for n, _ in gpu), a.precision,
              " / ".join(str(r.get("cg_iterations")) for _, r in gpu),
              cpu.get("cg_iterations")))
    print("Host wait for the device on lavapipe (s): %s" % "; ".join(
        "%s: %s" % ("{:,}".format(n), ", ".join(
            "%s %.2f of %.2f" % (k, v["wait_seconds"], r["timings"].get(
                "fit_cg" if k == "fit" else k, 0.0))
            for k, v in sorted(r["gpu_traffic"].items()) if v["readbacks"]))
        for n, r in gpu))
    if stray:
        print("Traffic in other stages: %s" % json.dumps(stray))


if __name__ == "__main__":
    main()
