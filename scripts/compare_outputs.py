#!/usr/bin/env python3
"""Byte-identity check of two polyspline builds: run both on the same inputs and `cmp` outputs.

    scripts/compare_outputs.py A_BIN B_BIN [--meshes DIR] [--elements N] [--jobs-dir DIR]

Inputs: every mesh of /work/shared/meshes (the files `curve` accepts: every file of the
per-source directories but the .md notes, as in scripts/bench_real.py), the repository's
meshes/generated/*.msh, and a disc, a cylinder and a torus made by `polyspline generate` (the
generated files of A and B are compared too). Cases per mesh: orders 2 and 3 as .msh, order 2
as .vtu, and on the meshes below `--energy-limit` elements also `--fit position` and
`--fit energy` (the default fit is `smooth`). Malformed inputs (empty, truncated, garbage
bytes) compare the exit status and the error line instead of an output file.

A case is identical when both builds exit with the same status and write byte-identical
files (or, on failure, the same last stderr line). Prints one line per case and a summary;
exits 1 if any case differs. Timings in the reports differ from run to run, so reports are
not compared; stdout is not written by `curve -q`.
"""
import argparse
import filecmp
import glob
import os
import subprocess
import sys
import tempfile
import time

SHARED = "/work/shared/meshes"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run(binary, args, cwd):
    p = subprocess.run([binary, *args], cwd=cwd, capture_output=True, text=True)
    last = p.stderr.strip().splitlines()[-1] if p.stderr.strip() else ""
    return p.returncode, last


def case(a, b, tmp, name, args, out_ext):
    """Run `curve` with `args` on both builds; compare status, error line and output bytes."""
    outs = {}
    res = {}
    for who, binary in (("A", a), ("B", b)):
        out = os.path.join(tmp, f"{who}.{out_ext}")
        if os.path.exists(out):
            os.remove(out)
        res[who] = run(binary, ["curve", "-q", *args, "-o", out], tmp)
        outs[who] = out
    same = res["A"][0] == res["B"][0]
    if res["A"][0] == 0:
        same = same and filecmp.cmp(outs["A"], outs["B"], shallow=False)
        what = f"{os.path.getsize(outs['A'])} bytes" if os.path.exists(outs["A"]) else "no file"
    else:
        same = same and res["A"][1] == res["B"][1]
        what = f"exit {res['A'][0]}: {res['A'][1][:90]}"
    print(f"{'same' if same else 'DIFF'}  {name:<70} {what}", flush=True)
    if not same:
        print(f"      A: {res['A']}\n      B: {res['B']}", flush=True)
    return same


def n_elements(binary, mesh):
    p = subprocess.run([binary, "info", mesh], capture_output=True, text=True)
    for line in p.stdout.splitlines():
        if "elements" in line.lower():
            digits = "".join(ch for ch in line.split(":")[-1] if ch.isdigit())
            if digits:
                return int(digits)
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--meshes", default=SHARED)
    ap.add_argument("--elements", type=int, default=3000, help="size of the generated meshes")
    ap.add_argument("--energy-limit", type=int, default=5000,
                    help="meshes with at most this many elements also run --fit position/energy")
    args = ap.parse_args()
    a, b = os.path.abspath(args.a), os.path.abspath(args.b)
    ok = True
    t0 = time.time()
    with tempfile.TemporaryDirectory(prefix="polyspline-cmp-") as tmp:
        meshes = sorted(p for p in glob.glob(os.path.join(args.meshes, "*", "*")) if not p.endswith(".md"))
        meshes += sorted(glob.glob(os.path.join(ROOT, "meshes", "generated", "*.msh")))
        for kind in ("disc", "cylinder", "torus"):
            gen = {}
            for who, binary in (("A", a), ("B", b)):
                gen[who] = os.path.join(tmp, f"gen-{kind}-{who}.msh")
                subprocess.run([binary, "generate", kind, "--elements", str(args.elements), "-o", gen[who]],
                               check=True, capture_output=True)
            same = filecmp.cmp(gen["A"], gen["B"], shallow=False)
            print(f"{'same' if same else 'DIFF'}  generate {kind}", flush=True)
            ok &= same
            meshes.append(gen["A"])
        for mesh in meshes:
            name = os.path.relpath(mesh, args.meshes) if mesh.startswith(args.meshes) else os.path.basename(mesh)
            cases = [(["--order", "2"], "msh"), (["--order", "3"], "msh"), (["--order", "2"], "vtu")]
            ne = n_elements(a, mesh)
            if ne is not None and ne <= args.energy_limit:
                cases += [(["--fit", "position"], "msh"), (["--fit", "energy"], "msh"),
                          (["--fit", "energy", "--order", "3"], "vtu")]
            for extra, ext in cases:
                ok &= case(a, b, tmp, f"{name} {' '.join(extra)} .{ext}", [mesh, *extra], ext)
        # Malformed inputs: the error line, not a file.
        src = os.path.join(ROOT, "meshes", "generated", "block_hex8_8.msh")
        data = open(src, "rb").read()
        bad = {"empty.msh": b"", "truncated.msh": data[: len(data) // 2],
               "garbage.msh": bytes(range(256)) * 8, "truncated.vtk": b"# vtk DataFile Version 3.0\nx\nASCII\n"}
        for fname, content in bad.items():
            path = os.path.join(tmp, fname)
            open(path, "wb").write(content)
            ok &= case(a, b, tmp, f"malformed {fname}", [path], "msh")
    print(f"{'ALL IDENTICAL' if ok else 'DIFFERENCES FOUND'} ({time.time() - t0:.0f} s)")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
