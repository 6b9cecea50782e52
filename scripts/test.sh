#!/usr/bin/env bash
# The test command (README, second command; `.ci/run` runs exactly this).
#
# On a fresh Debian machine it installs what the tests need, runs every test target, and ends
# with the checks that were skipped and why, then one line `total: N passed, M failed`:
#  1. Debian packages, where it may (root, or passwordless sudo): Mesa's Vulkan drivers
#     (lavapipe) for the GPU tests, the X/GL libraries the gmsh wheel links against, and
#     python3-venv where Python lacks ensurepip. Otherwise it says what it could not install.
#  2. The Python checkers of tests/requirements.txt (Gmsh, VTK, meshio, PyFR, PyMFEM, PyHOPE)
#     in a virtual environment of their own, .venv-tests (re-used while the requirements are
#     unchanged). The tests find it through POLYSPLINE_PYTHON.
#  3. `cargo test --release --all-targets` (or `cargo test --release ARGS…` when given
#     arguments, e.g. `--test integration curve::`): the library's unit tests and the test
#     binaries by kind, library, integration, geometry, cross_validation and clients
#     (docs/architecture.md). A test whose checker is missing skips visibly
#     (a failure under CI=true) and appends a line to target/test-skips.log.
#  4. Without arguments: the Python package (python/, docs/python.md), built with maturin
#     (release, in the workspace's target directory, so the library is not compiled again) and
#     installed into .venv-tests, then its pytest tests (python/tests/); their passes, failures
#     and skips count in the summary below.
#  5. Lints, without arguments only: `cargo fmt --all --check`, `cargo clippy --workspace
#     --all-targets -- -D warnings` and `cargo doc --no-deps` with RUSTDOCFLAGS=-D warnings
#     (both with --release), each a pass/fail line in the summary (a failure fails the run;
#     its output is in target/lint-NAME.log).
#  6. Without arguments, also Open MPI and the distributed test binary (`--features mpi`,
#     which it requires, so step 3 does not build it).
set -uo pipefail
cd "$(dirname "$0")/.."
root=$PWD

export DEBIAN_FRONTEND=noninteractive
# Mesa's Vulkan drivers warn on every process start without a runtime directory.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp}"

notes=()

# 1. Debian packages.
need=()
# cgns-convert: the CGNS library's `cgnscheck`, which checks the CGNS files polyspline writes.
for pkg in mesa-vulkan-drivers libvulkan1 libglu1-mesa libxcursor1 libxft2 libxinerama1 cgns-convert; do
    dpkg -s "$pkg" >/dev/null 2>&1 || need+=("$pkg")
done
if ! python3 -c 'import ensurepip, venv' >/dev/null 2>&1; then
    need+=(python3-venv)
fi
if [ ${#need[@]} -gt 0 ]; then
    if ! command -v apt-get >/dev/null 2>&1; then
        notes+=("no apt-get: not installed: ${need[*]}")
    else
        sudo=""
        if [ "$(id -u)" != 0 ]; then
            if sudo -n true 2>/dev/null; then sudo="sudo -n"; else sudo="none"; fi
        fi
        if [ "$sudo" = none ]; then
            notes+=("not root and no passwordless sudo: not installed: ${need[*]}")
        elif ! { $sudo apt-get update -qq && $sudo apt-get install -y -qq --no-install-recommends "${need[@]}"; } >/dev/null; then
            notes+=("apt-get failed: not installed: ${need[*]}")
        fi
    fi
fi

# 2. The Python checkers in their own virtual environment.
venv="$root/.venv-tests"
req="$root/tests/requirements.txt"
stamp="$venv/.requirements"
if [ -x "$venv/bin/python" ] && cmp -s "$req" "$stamp"; then
    :
elif { [ -x "$venv/bin/python" ] || python3 -m venv "$venv"; } &&
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$req"; then
    cp "$req" "$stamp"
else
    notes+=("the Python checkers could not be installed into $venv (see the pip output above)")
fi
if [ -x "$venv/bin/python" ]; then
    export POLYSPLINE_PYTHON="$venv/bin/python"
fi

# 3. The tests.
mkdir -p "$root/target"
export POLYSPLINE_SKIP_LOG="$root/target/test-skips.log"
: >"$POLYSPLINE_SKIP_LOG"
out="$root/target/test-output.log"
# Arguments replace `--all-targets` (e.g. `bash scripts/test.sh --test clients`).
if [ $# -gt 0 ]; then
    cargo test --release "$@" 2>&1 | tee "$out"
else
    cargo test --release --all-targets --no-fail-fast 2>&1 | tee "$out"
fi
status=${PIPESTATUS[0]}

# 4. The Python package and its tests.
py_passed=0
py_failed=0
if [ $# -eq 0 ]; then
    pylog="$root/target/python-build.log"
    pyout="$root/target/pytest-output.log"
    if [ ! -x "$venv/bin/python" ]; then
        notes+=("no $venv: the Python package was not built or tested")
    elif ! VIRTUAL_ENV="$venv" "$venv/bin/python" -m maturin develop --release --quiet \
        --manifest-path "$root/python/Cargo.toml" >"$pylog" 2>&1; then
        tail -n 40 "$pylog"
        echo "the Python package did not build (see target/python-build.log)"
        py_failed=1
    else
        POLYSPLINE_BIN="$root/target/release/polyspline" "$venv/bin/python" -m pytest \
            "$root/python/tests" -q -rs -p no:cacheprovider 2>&1 | tee "$pyout"
        py_status=${PIPESTATUS[0]}
        summary=$(grep -E '[0-9]+ (passed|failed|errors?|skipped).* in [0-9.]+s' "$pyout" | tail -n 1)
        py_passed=$(grep -Eo '[0-9]+ passed' <<<"$summary" | grep -Eo '[0-9]+' || echo 0)
        py_failed=$(grep -Eo '[0-9]+ (failed|errors?)' <<<"$summary" | awk '{s+=$1} END {print s+0}')
        if [ "$py_status" != 0 ] && [ "$py_failed" = 0 ]; then
            echo "pytest exited with status $py_status (see above)"
            py_failed=1
        fi
    fi
    [ "$py_failed" = 0 ] || status=1
fi

# 5. Lints: formatting, clippy and rustdoc, each with warnings denied.
lints=()
lint_failed=0
lint() {
    local name=$1 log="$root/target/lint-$1.log"
    shift
    if "$@" >"$log" 2>&1; then
        lints+=("lint $name: pass")
    else
        tail -n 60 "$log"
        lints+=("lint $name: FAIL (see target/lint-$name.log)")
        lint_failed=1
    fi
}
if [ $# -eq 0 ]; then
    for tool in clippy rustfmt; do
        if ! cargo "${tool/rustfmt/fmt}" --version >/dev/null 2>&1 && command -v rustup >/dev/null 2>&1; then
            rustup component add "$tool" >/dev/null 2>&1
        fi
    done
    # --release: the build scripts' outputs of the test build are reused.
    lint fmt cargo fmt --all --check
    lint clippy cargo clippy --release --workspace --all-targets -- -D warnings
    lint doc env RUSTDOCFLAGS="-D warnings" cargo doc --release --no-deps
fi
# ---- 6. Distributed curving (feature `mpi`, docs/distributed.md) -------------------------
# With no arguments: Open MPI and the headers rsmpi's bindings are generated from, then the
# tests that run `mpirun --oversubscribe -np 1,2,4` against the serial result. Their results
# count in the totals below.
if [ $# -eq 0 ]; then
    mpi_need=()
    for pkg in libopenmpi-dev openmpi-bin libclang-dev; do
        dpkg -s "$pkg" >/dev/null 2>&1 || mpi_need+=("$pkg")
    done
    if [ ${#mpi_need[@]} -gt 0 ]; then
        mpi_sudo=""
        [ "$(id -u)" = 0 ] || mpi_sudo="sudo -n"
        if ! { $mpi_sudo apt-get update -qq && $mpi_sudo apt-get install -y -qq --no-install-recommends "${mpi_need[@]}"; } >/dev/null 2>&1; then
            notes+=("could not install ${mpi_need[*]}: the distributed tests cannot build")
        fi
    fi
    # mpirun refuses root unless told (CI containers run as root).
    export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
    cargo test --release --features mpi --test distributed 2>&1 | tee -a "$out"
    mpi_status=${PIPESTATUS[0]}
    [ "$mpi_status" = 0 ] || status=$mpi_status
fi
# ---- end of step 6 ------------------------------------------------------------------------

echo
echo "== skipped checks =="
if [ ${#notes[@]} -gt 0 ]; then
    printf 'setup: %s\n' "${notes[@]}"
fi
if [ -s "$POLYSPLINE_SKIP_LOG" ]; then
    sort "$POLYSPLINE_SKIP_LOG" | uniq -c | sed 's/^ *\([0-9]*\) \(.*\)/\2 (x\1)/'
else
    echo "none"
fi
# The harness's own ignored tests, if any.
grep -E '^test .* \.\.\. ignored' "$out" || true

passed=$(grep -Eo 'test result: [A-Za-z]+\. [0-9]+ passed' "$out" | grep -Eo '[0-9]+ passed' | awk '{s+=$1} END {print s+0}')
failed=$(grep -Eo '[0-9]+ failed;' "$out" | awk '{s+=$1} END {print s+0}')
# The Python package's pytest counts (step 4).
passed=$((passed + py_passed))
failed=$((failed + py_failed))
if [ "$status" != 0 ] && [ "$failed" = 0 ]; then
    echo "cargo test exited with status $status (build error or crash; see above)"
    failed=1
fi
if [ ${#lints[@]} -gt 0 ]; then
    echo
    echo "== lints =="
    printf '%s\n' "${lints[@]}"
    [ "$lint_failed" = 0 ] || [ "$status" != 0 ] || status=1
fi
echo "total: $passed passed, $failed failed"
exit "$status"
