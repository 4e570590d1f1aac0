#!/usr/bin/env bash
# One-time setup: a Python virtualenv at .venv with the table readers used by the checks and
# the README's examples (pyarrow, duckdb, polars), and the release build of `granular`.
# Safe to run again: an existing .venv with the packages is kept, cargo rebuilds only changes.
# Set PYTHON to choose the interpreter (default python3, 3.9 or newer).
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
    echo "setup: creating .venv with $PYTHON"
    if ! "$PYTHON" -m venv .venv; then
        # Debian without python3-venv has no ensurepip: make the venv without pip and let the
        # interpreter's own pip install into it.
        rm -rf .venv
        "$PYTHON" -m venv --without-pip .venv
    fi
fi
if ! .venv/bin/python -c 'import pyarrow, duckdb, polars' 2>/dev/null; then
    echo "setup: installing pyarrow, duckdb, polars into .venv"
    if .venv/bin/python -m pip --version >/dev/null 2>&1; then
        .venv/bin/python -m pip install -q pyarrow duckdb polars
    else
        "$PYTHON" -m pip --python .venv/bin/python install -q pyarrow duckdb polars
    fi
fi

cargo build --release
echo "setup: done (binary: target/release/granular)"
