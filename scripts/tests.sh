#!/usr/bin/env bash
# The tests: `cargo test --release`, then a tiny campaign run with the release binary whose
# tables are read back with DuckDB, pyarrow and Polars (scripts/check_tables.py), grown and
# compared with the campaign of its final manifest (scripts/compare_tables.py --current), the
# report and the live dashboard in headless Chromium (scripts/browser-test.sh, which installs
# Debian's chromium when missing), and the SLURM test. The tutorial's commands and queries
# (scripts/tutorial_test.py) run before the browser test, then the Python package: its wheel
# installed into a fresh virtualenv and its tests run with pytest (scripts/python-test.sh).
# Needs scripts/setup.sh to have been run once (for .venv).
set -euo pipefail
cd "$(dirname "$0")/.."

if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c 'import pyarrow, duckdb, polars' 2>/dev/null; then
    echo "tests: .venv with pyarrow, duckdb, polars not found; run scripts/setup.sh first" >&2
    exit 2
fi

echo "== cargo test --release"
cargo test --release

echo "== tiny campaign"
cargo build --release
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat > "$tmp/tiny.json" <<'JSON'
{
  "name": "ci-tiny",
  "description": "CI: 2 methods x 2 replicas, N1 = 2000, t_end = 10",
  "model": "dsmc",
  "seed": 20240601,
  "replicas": 2,
  "params": {
    "method": "low_rank",
    "species": {"power_law": {"n1": 0.1, "N1": 2000, "theta": 3}},
    "restitution": {"constant": 0.5},
    "initial_temperature": 1.0,
    "t_end": 10.0,
    "output_times": {"log": {"from": 0.01, "to": 10.0, "per_decade": 10}},
    "observables": ["temperature", "msd"]
  },
  "sweep": {"method": ["low_rank", "bird"]}
}
JSON
bin=target/release/granular
"$bin" validate "$tmp/tiny.json"
"$bin" run "$tmp/tiny.json" --out "$tmp/runs" --quiet
"$bin" status "$tmp/runs"

echo "== table check"
.venv/bin/python scripts/check_tables.py "$tmp/runs"

echo "== growth: a third replica and t_end 20 (the old end kept as an output, so runs continue)"
.venv/bin/python - "$tmp/tiny.json" "$tmp/grown.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
m["replicas"] = 3
m["params"]["t_end"] = 20.0
m["params"]["output_times"]["log"]["to"] = 20.0
m["params"]["output_times"]["list"] = [10.0]
json.dump(m, open(sys.argv[2], "w"))
PY
"$bin" plan "$tmp/grown.json" --out "$tmp/runs"
"$bin" run "$tmp/grown.json" --out "$tmp/runs" --quiet
"$bin" run "$tmp/grown.json" --out "$tmp/direct" --quiet
.venv/bin/python scripts/compare_tables.py "$tmp/runs" "$tmp/direct" --current
.venv/bin/python scripts/check_tables.py "$tmp/runs"

echo "== compaction while readers read, then the tables again"
.venv/bin/python scripts/compact_readers.py "$bin" "$tmp/tiny.json" "$tmp/compact"
"$bin" compact "$tmp/runs"
"$bin" verify "$tmp/runs"
.venv/bin/python scripts/check_tables.py "$tmp/runs"

echo "== the tutorial (docs/tutorial.md): every command and query run, every output shown checked"
.venv/bin/python scripts/tutorial_test.py "$bin"

echo "== the Python package: pip install . into a fresh venv, pytest (tests/python)"
bash scripts/python-test.sh

echo "== the report and the live dashboard in a real browser (headless Chromium)"
bash scripts/browser-test.sh

echo "== SLURM (a real one-node cluster)"
bash scripts/slurm-test.sh
echo "tests: all passed"
