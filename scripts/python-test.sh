#!/usr/bin/env bash
# The Python package (pyproject.toml, python/granular): `pip install .` into a fresh virtualenv
# (not .venv, so nothing installed by hand or by scripts/setup.sh is seen), which builds the wheel
# with maturin (bindings = "bin": the release binary, built by cargo in this checkout's target/,
# so after `cargo build --release` nothing is compiled again) and installs `granular` on the
# venv's PATH beside the pure-Python package; then the package's tests (tests/python, pytest),
# run from outside the checkout so that `import granular` is the installed package. pytest's
# count of tests is printed; a run that collects no test fails (pytest exits 5).
# Needs python3 (3.9 or newer) and network access to PyPI (maturin, polars, pyarrow, duckdb,
# pytest) or pip's cache. Set PYTHON to choose the interpreter.
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$PWD
PYTHON=${PYTHON:-python3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
v="$work/venv"
if ! "$PYTHON" -m venv "$v" 2>/dev/null; then
    # Debian without python3-venv has no ensurepip: a venv without pip, filled by the
    # interpreter's own pip.
    rm -rf "$v"
    "$PYTHON" -m venv --without-pip "$v"
fi
pip_() {
    if "$v/bin/python" -m pip --version >/dev/null 2>&1; then
        "$v/bin/python" -m pip "$@"
    else
        "$PYTHON" -m pip --python "$v/bin/python" "$@"
    fi
}
start=$(date +%s)
pip_ install -q --disable-pip-version-check "$repo" pytest
echo "python: wheel built and installed into a fresh venv in $(( $(date +%s) - start )) s"
test -x "$v/bin/granular" || { echo "python: the wheel did not install bin/granular" >&2; exit 1; }
cd "$work"
set +e
"$v/bin/python" -m pytest "$repo/tests/python" -q -p no:cacheprovider -o console_output_style=classic 2>&1 | tee "$work/pytest.log"
rc=${PIPESTATUS[0]}
set -e
if [ "$rc" -ne 0 ]; then
    echo "python: pytest failed (exit $rc; 5 = no test collected)" >&2
    exit 1
fi
passed=$(grep -Eo '[0-9]+ passed' "$work/pytest.log" | tail -1 | grep -Eo '[0-9]+' || echo 0)
if [ "$passed" -eq 0 ]; then
    echo "python: no test passed" >&2
    exit 1
fi
echo "python: $passed tests passed ($(( $(date +%s) - start )) s for the wheel, the venv and the tests)"
