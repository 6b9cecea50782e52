"""Every failure is an exception of the polyspline hierarchy with the command line's line."""
import numpy as np
import pytest

import polyspline
from conftest import QUADS, cli_error


def test_unknown_keyword_is_a_type_error():
    with pytest.raises(TypeError, match="ordr"):
        polyspline.curve(QUADS, ordr=3)
    with pytest.raises(TypeError, match="msh_version"):
        # An output option is not an option of the job in memory.
        polyspline.curve(QUADS, msh_version="2.2")


def test_bad_value_is_a_value_error_with_the_cli_message(tmp_path):
    with pytest.raises(polyspline.ParameterError) as e:
        polyspline.curve_file(QUADS, tmp_path / "o.msh", order="two")
    assert isinstance(e.value, ValueError)
    assert str(e.value) == cli_error("curve", QUADS, "-o", tmp_path / "o.msh", "--order=two")
    with pytest.raises(polyspline.ParameterError, match="fit"):
        polyspline.curve(QUADS, fit="wiggly")


def test_out_of_range_option_has_the_cli_message(tmp_path):
    with pytest.raises(polyspline.ParameterError) as e:
        polyspline.curve_file(QUADS, tmp_path / "o.msh", order=20, backend="cpu")
    assert str(e.value) == cli_error("curve", QUADS, "-o", tmp_path / "o.msh", "--order", "20",
                                     "--backend", "cpu")
    with pytest.raises(polyspline.ParameterError):
        polyspline.curve(QUADS, cg_tol=-1.0, backend="cpu")
    with pytest.raises(polyspline.ParameterError, match="flag"):
        polyspline.curve(QUADS, snap_boundary="yes")


def test_an_option_the_job_cannot_use_is_refused_with_the_cli_message(tmp_path):
    with pytest.raises(polyspline.ParameterError) as e:
        polyspline.curve_file(QUADS, tmp_path / "o.msh", straight=True, snap_boundary=True,
                              backend="cpu")
    assert str(e.value) == cli_error("curve", QUADS, "-o", tmp_path / "o.msh", "--straight",
                                     "--snap-boundary", "--backend", "cpu")
    assert "--snap-boundary" in str(e.value) and not (tmp_path / "o.msh").exists()
    with pytest.raises(polyspline.ParameterError, match="--young"):
        polyspline.curve(QUADS, young=3.0, backend="cpu")
    c = polyspline.curve(QUADS, order=2, backend="cpu")
    with pytest.raises(polyspline.ParameterError, match="--binary"):
        c.write(tmp_path / "o.vtu", binary=True)
    assert not (tmp_path / "o.vtu").exists()
    c.write(tmp_path / "o.msh", binary=True)


def test_missing_and_garbled_inputs_are_input_errors(tmp_path):
    missing = tmp_path / "missing.msh"
    with pytest.raises(polyspline.InputError) as e:
        polyspline.curve_file(missing, tmp_path / "o.msh", backend="cpu")
    assert str(e.value) == cli_error("curve", missing, "-o", tmp_path / "o.msh", "--backend", "cpu")
    bad = tmp_path / "bad.msh"
    bad.write_text("$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\nnonsense\n")
    with pytest.raises(polyspline.InputError) as e:
        polyspline.curve(bad, backend="cpu")
    assert str(e.value) == cli_error("curve", bad, "-o", tmp_path / "o.msh", "--backend", "cpu")
    assert "\n" not in str(e.value) and str(bad) in str(e.value)


def test_bad_arrays_are_input_errors():
    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    with pytest.raises(polyspline.InputError, match="<memory>"):
        polyspline.curve((pts, np.array([[0, 1, 2, 7]])), backend="cpu")
    with pytest.raises(ValueError):
        polyspline.curve((pts, np.array([[0, 1, 2]])), backend="cpu")


def test_a_mesh_without_a_boundary_is_not_curvable():
    # Two quads on the same four nodes: duplicated elements.
    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    quads = np.array([[0, 1, 2, 3], [0, 1, 2, 3]])
    with pytest.raises(polyspline.NotCurvableError) as e:
        polyspline.curve((pts, quads), backend="cpu")
    assert isinstance(e.value, polyspline.InputError) and "cannot curve" in str(e.value)


def test_output_errors(tmp_path):
    with pytest.raises(polyspline.OutputError) as e:
        polyspline.curve_file(QUADS, tmp_path / "o.abc", backend="cpu")
    assert str(e.value) == cli_error("curve", QUADS, "-o", tmp_path / "o.abc", "--backend", "cpu")
    with pytest.raises(polyspline.OutputError):
        polyspline.curve_file(QUADS, QUADS, backend="cpu")
    c = polyspline.curve(QUADS, order=2, backend="cpu")
    with pytest.raises(polyspline.OutputError):
        c.write(tmp_path / "o.abc")
    with pytest.raises(polyspline.ParameterError):
        c.write(tmp_path / "o.msh", volume_name="")


EXAMPLE = QUADS.parent.parent / "real" / "dealii" / "example.msh"


def test_gpu_without_a_vulkan_driver_is_a_device_error(tmp_path):
    # The Vulkan loader reads its driver list from the environment of the process: a fresh
    # interpreter, and the command line, with a driver file that does not exist.
    import os
    import subprocess
    import sys

    from conftest import cli_path

    env = dict(os.environ, VK_DRIVER_FILES=str(tmp_path / "none.json"),
               VK_ICD_FILENAMES=str(tmp_path / "none.json"))
    code = (
        "import sys, polyspline\n"
        "try:\n"
        f"    polyspline.curve({str(QUADS)!r}, backend='gpu')\n"
        "except polyspline.DeviceError as e:\n"
        "    print(type(e).__name__, e, sep='|')\n"
    )
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    name, message = run.stdout.strip().split("|")
    cli = subprocess.run([str(cli_path()), "curve", str(QUADS), "-o", str(tmp_path / "o.msh"),
                          "--backend", "gpu"], env=env, capture_output=True, text=True)
    assert cli.returncode == 1
    assert name == "DeviceError"
    assert cli.stderr.strip() == "polyspline: error: " + message
    assert "no GPU adapter" in message


def test_a_cg_breakdown_is_a_solve_error(tmp_path):
    # No option caps the CG iterations; a tolerance below rounding makes the residual vanish
    # before convergence, and CG breaks down (pᵀAp = 0), as the command line reports.
    options = dict(fit_solver="cg", cg_tol=1e-300, backend="cpu")
    with pytest.raises(polyspline.SolveError) as e:
        polyspline.curve(EXAMPLE, **options)
    assert type(e.value).__name__ == "SolveError" and "conjugate gradients" in str(e.value)
    assert str(e.value) == cli_error("curve", EXAMPLE, "-o", tmp_path / "o.msh", "--fit-solver",
                                     "cg", "--cg-tol", "1e-300", "--backend", "cpu")
    with pytest.raises(polyspline.SolveError):
        polyspline.curve_file(EXAMPLE, tmp_path / "o.msh", **options)
    assert not (tmp_path / "o.msh").exists()


def test_every_error_class_is_in_the_hierarchy():
    for cls in (polyspline.InputError, polyspline.NotCurvableError, polyspline.ParameterError,
                polyspline.OutputError, polyspline.DeviceError, polyspline.SolveError,
                polyspline.ValidityError):
        assert issubclass(cls, polyspline.PolysplineError)
