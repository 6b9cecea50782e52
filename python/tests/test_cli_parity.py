"""The Python package and the command line give the same files for the same options."""
import json

import pytest

import polyspline
from conftest import HEXES, QUADS, cli

CASES = [
    (QUADS, "out.msh", {"order": 3}),
    (HEXES, "out.vtu", {"order": 2}),
    (QUADS, "out.msh", {"order": 2, "fit": "position", "msh_version": "2.2", "binary": True}),
    (HEXES, "out.msh", {"order": 2, "kink_angle": 20.0, "snap_boundary": True, "volume_name": "air"}),
    (HEXES, "out.cgns", {"order": 3}),
    (QUADS, "out.inp", {"order": 2}),
    (HEXES, "out.vtu", {"order": 2, "vtu_encoding": "ascii"}),
]


def cli_args(options):
    args = []
    for key, value in options.items():
        flag = "--" + key.replace("_", "-")
        if value is True:
            args.append(flag)
        elif value is not False:
            args += [flag, str(value)]
    return args


@pytest.mark.parametrize("mesh,name,options", CASES)
def test_curve_file_is_byte_identical_to_the_cli(tmp_path, mesh, name, options):
    ours = tmp_path / ("py_" + name)
    theirs = tmp_path / ("cli_" + name)
    report = polyspline.curve_file(mesh, ours, backend="cpu", **options)
    status, err = cli("curve", mesh, "-o", theirs, "--backend", "cpu", *cli_args(options))
    assert status == 0, err
    assert ours.read_bytes() == theirs.read_bytes()
    assert report["output_elements"] > 0 and report["order"] == options["order"]


@pytest.mark.parametrize("mesh,name,options", CASES)
def test_curve_in_memory_then_write_is_byte_identical_to_the_cli(tmp_path, mesh, name, options):
    job = {k: v for k, v in options.items() if k in polyspline.options("curve")}
    out = {k: v for k, v in options.items() if k not in job}
    curved = polyspline.curve(mesh, backend="cpu", **job)
    ours = tmp_path / ("py_" + name)
    curved.write(ours, **out)
    theirs = tmp_path / ("cli_" + name)
    status, err = cli("curve", mesh, "-o", theirs, "--backend", "cpu", *cli_args(options))
    assert status == 0, err
    assert ours.read_bytes() == theirs.read_bytes()


def test_report_has_the_cli_report_keys_and_values(tmp_path):
    ours = polyspline.curve_file(QUADS, tmp_path / "a.msh", order=2, backend="cpu",
                                 report=tmp_path / "a.json")
    status, err = cli("curve", QUADS, "-o", tmp_path / "b.msh", "--order", "2", "--backend", "cpu",
                      "--report", tmp_path / "b.json")
    assert status == 0, err
    theirs = json.loads((tmp_path / "b.json").read_text())
    written = json.loads((tmp_path / "a.json").read_text())
    assert set(ours) == set(theirs) == set(written)
    skip = {"timings", "output"}
    assert {k: v for k, v in ours.items() if k not in skip} == {
        k: v for k, v in theirs.items() if k not in skip}
    in_memory = polyspline.curve(QUADS, order=2, backend="cpu").report
    assert set(in_memory) == set(theirs)
    assert in_memory["min_scaled_jacobian"] == theirs["min_scaled_jacobian"]


def test_options_are_the_cli_options_with_its_defaults():
    opts = polyspline.options("curve")
    assert opts["order"] == "2" and opts["fit"] == "smooth" and opts["backend"] == "auto"
    assert opts["snap_boundary"] is False
    write = polyspline.options("write")
    assert write["volume_name"] == "fluid" and "order" not in write
    files = polyspline.options("curve_file")
    assert set(opts) | set(write) <= set(files) and "report" in files
