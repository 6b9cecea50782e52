"""Progress, Ctrl-C, the GIL, and PyFR reading a file written from Python."""
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

import polyspline
from conftest import HEXES, MESHES, QUADS, need, skip

BIG = MESHES / "real" / "dealii" / "hole8170.msh"


def test_progress_reports_every_timed_stage(tmp_path):
    events = []
    report = polyspline.curve_file(QUADS, tmp_path / "o.msh", order=2, backend="cpu",
                                   progress=events.append)
    started = [e["stage"] for e in events if e["event"] == "started"]
    finished = [e["stage"] for e in events if e["event"] == "finished"]
    assert started[0] == "read" and finished[-1] == "write"
    timed = set(report["timings"]) - {"total", "fit_assembly", "fit_cg", "elastic_assembly",
                                      "elastic_cg"}
    assert timed == set(started) == set(finished)
    cg = [e for e in events if e["event"] == "cg"]
    assert all(e["rel_residual"] >= 0 and e["iteration"] >= 0 for e in cg)


def test_an_exception_in_the_callback_stops_the_job_and_writes_nothing(tmp_path):
    class Stop(Exception):
        pass

    def progress(e):
        if e["event"] == "finished" and e["stage"] == "topology":
            raise Stop

    out = tmp_path / "o.msh"
    with pytest.raises(Stop):
        polyspline.curve_file(QUADS, out, backend="cpu", progress=progress)
    assert not out.exists() and os.listdir(tmp_path) == []


def test_ctrl_c_interrupts_the_job(tmp_path):
    def progress(e):
        if e["event"] == "started" and e["stage"] == "spline":
            signal.raise_signal(signal.SIGINT)

    out = tmp_path / "o.msh"
    with pytest.raises(KeyboardInterrupt):
        polyspline.curve_file(HEXES, out, backend="cpu", progress=progress)
    assert not out.exists()
    with pytest.raises(KeyboardInterrupt):
        polyspline.curve(HEXES, backend="cpu", progress=progress)


def test_the_gil_is_released_during_the_job():
    if not BIG.exists():
        skip(f"{BIG} is not in this checkout")
    done = threading.Event()
    result = {}

    def job():
        t = time.perf_counter()
        result["curved"] = polyspline.curve(BIG, order=3, backend="cpu")
        result["seconds"] = time.perf_counter() - t
        done.set()

    ticks = 0
    thread = threading.Thread(target=job)
    thread.start()
    while not done.is_set():
        ticks += 1
        time.sleep(0.001)
    thread.join()
    # With the GIL held, this loop would stop for the whole job.
    assert result["seconds"] > 0.05
    assert ticks > result["seconds"] / 0.001 * 0.2, (ticks, result["seconds"])


def test_pyfr_imports_a_mesh_written_from_python(tmp_path):
    need("pyfr")
    h5py = need("h5py")
    from test_numpy import square_grid

    # No named region: the volume group is `fluid`, where PyFR looks for its elements.
    curved = polyspline.curve(square_grid(4), order=3, backend="cpu")
    msh = tmp_path / "m.msh"
    curved.write(msh)
    out = tmp_path / "m.pyfrm"
    run = subprocess.run([sys.executable, "-m", "pyfr", "import", str(msh), str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    with h5py.File(out, "r") as f:
        n = sum(int(d.shape[0]) for d in f["eles"].values())
        assert list(f["eles"]) == ["quad"]
    assert n == len(curved.cells)


def test_sigint_during_the_job_stops_it_before_writing(tmp_path):
    # SIGINT arrives while Rust runs with the GIL released: only the job's own check of
    # Python's signals at its next stage can stop it before the output is written.
    if not BIG.exists():
        skip(f"{BIG} is not in this checkout")
    out = tmp_path / "o.msh"
    timer = threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            polyspline.curve_file(BIG, out, order=4, backend="cpu")
    finally:
        timer.cancel()
    assert not out.exists()


def test_ctrl_c_during_the_cg_solve_stops_within_a_fraction_of_a_second(tmp_path):
    # A CG-heavy fit (point Jacobi, tolerance 1e-14): the solve alone takes about a second. A
    # SIGINT from another thread a few iterations in must stop the job within one iteration,
    # not when the solve (and the fit stage) ends.
    if not BIG.exists():
        skip(f"{BIG} is not in this checkout")
    options = dict(order=2, fit_solver="cg", cg_tol=1e-14, cg_preconditioner="jacobi",
                   backend="cpu")
    full = polyspline.curve_file(BIG, tmp_path / "full.msh", **options)
    cg_seconds = full["timings"]["fit_cg"]
    sent = {}

    def interrupt():
        sent["t"] = time.perf_counter()
        os.kill(os.getpid(), signal.SIGINT)

    def progress(e):
        if e["event"] == "cg" and e["iteration"] == 10 and "timer" not in sent:
            sent["timer"] = threading.Timer(0.05, interrupt)
            sent["timer"].start()
            sent["iteration"] = e["iteration"]

    out = tmp_path / "o.msh"
    with pytest.raises(KeyboardInterrupt):
        polyspline.curve_file(BIG, out, progress=progress, **options)
    latency = time.perf_counter() - sent["t"]
    assert not out.exists()
    # A solve that ignored the signal would run on for about the rest of the solve after the
    # signal (sent 0.05 s after iteration 10): the bound stays well below that on any machine.
    assert cg_seconds > 0.2, f"the solve is too short to tell ({cg_seconds:.2f} s)"
    bound = min(0.2, (cg_seconds - 0.05) / 2)
    assert latency < bound, f"stopped {latency:.3f} s after SIGINT (solve: {cg_seconds:.2f} s)"
    print(f"SIGINT latency {latency * 1000:.1f} ms, uninterrupted CG {cg_seconds:.2f} s")
