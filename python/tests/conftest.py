"""Shared helpers of the Python package's tests: the command line to compare with, Gmsh as the
independent checker of written files, and visible skips (a failure under CI=true), as the Rust
tests have them (tests/common/mod.rs)."""
import contextlib
import os
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MESHES = REPO / "meshes"
QUADS = MESHES / "generated" / "star5_quad4_20.msh"
HEXES = MESHES / "generated" / "block_hex8_8.msh"


def skip(why):
    """Skip visibly: recorded in $POLYSPLINE_SKIP_LOG; under CI=true a failure instead."""
    if os.environ.get("CI") == "true":
        pytest.fail(f"required under CI: {why}")
    log = os.environ.get("POLYSPLINE_SKIP_LOG", str(REPO / "target" / "test-skips.log"))
    test = os.environ.get("PYTEST_CURRENT_TEST", "python").split(" ")[0]
    try:
        with open(log, "a") as f:
            f.write(f"SKIPPED: {test}: {why}\n")
    except OSError:
        pass
    pytest.skip(why)


def need(module):
    try:
        return __import__(module)
    except ImportError:
        skip(f"Python module {module} is not installed")


def cli_path():
    path = Path(os.environ.get("POLYSPLINE_BIN", REPO / "target" / "release" / "polyspline"))
    if not path.exists():
        skip(f"the command line {path} is not built (cargo build --release)")
    return path


def cli(*args):
    """Run the command line; (exit status, stderr)."""
    run = subprocess.run([str(cli_path()), *map(str, args)], capture_output=True, text=True)
    return run.returncode, run.stderr


def cli_error(*args):
    """The one error line the command line prints, without its prefix."""
    status, err = cli(*args)
    assert status != 0, err
    line = err.strip().splitlines()[0]
    for prefix in ("polyspline: error: ", "error: "):
        if line.startswith(prefix):
            return line[len(prefix):]
    return line


@contextlib.contextmanager
def gmsh_open(path):
    """Gmsh with `path` open and its terminal output off, finalized afterwards: yields the gmsh
    module and the mesh's dimension."""
    gmsh = need("gmsh")
    # interruptible=False: otherwise Gmsh sets SIGINT to its default action for the rest of
    # the process, and the Ctrl-C tests that run later would kill pytest.
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(path))
        yield gmsh, gmsh.model.getDimension()
    finally:
        gmsh.finalize()


def gmsh_jacobians(path):
    """Gmsh's own reading of a mesh file: (volume elements, min det J, max det J, volume),
    det J at Gauss points of degree 2p+2 and the volume integrated with them."""
    import numpy as np

    with gmsh_open(path) as (gmsh, dim):
        types, tags, _ = gmsh.model.mesh.getElements(dim)
        assert len(types) == 1, types
        etype = types[0]
        order = gmsh.model.mesh.getElementProperties(etype)[2]
        loc, weights = gmsh.model.mesh.getIntegrationPoints(etype, "Gauss%d" % (2 * order + 2))
        _, dets, _ = gmsh.model.mesh.getJacobians(etype, loc)
        dets = np.asarray(dets).reshape(len(tags[0]), -1)
        volume = float(np.sum(dets * np.asarray(weights)[None, :]))
        return len(tags[0]), float(dets.min()), float(dets.max()), volume
