#!/usr/bin/env bash
# Growth, end to end: a DSMC and an RFM campaign grown step by step (more replicas, one more
# sweep value, a longer t_end / duration), each step's plan and the runs it executed, then the
# campaign run directly from the final manifest and compared with scripts/compare_tables.py
# --current (keyed by params and replica). About 3 minutes on 2 cores.
#
# Usage: scripts/growth-demo.sh [OUTDIR]   (default: a temporary directory, removed at the end)
# Needs the release binary (cargo build --release) and .venv (scripts/setup.sh).
#
# Expected: every step runs exactly the runs its plan announces (DSMC 8, +4, +6, +18 of which 18
# continued; RFM 4, +2, +3, +9 of which 9 continued), and both comparisons print
# "all tables identical".
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/granular
py=.venv/bin/python
out=${1:-}
if [ -z "$out" ]; then
    out=$(mktemp -d)
    trap 'rm -rf "$out"' EXIT
fi
mkdir -p "$out"

# DSMC: jobs/table1-small.json (2 methods x eps 0.5, 0.9 x 2 replicas, N1 = 1e5, t_end = 100).
cp jobs/table1-small.json "$out/dsmc-0.json"
# RFM: 2D, N = 500, two packing fractions, 2 replicas, 0.1 s sampled.
cat > "$out/rfm-0.json" <<'JSON'
{
  "name": "growth-demo-rfm",
  "description": "scripts/growth-demo.sh: a small 2D RFM sweep that grows",
  "model": "rfm",
  "seed": 11,
  "replicas": 2,
  "params": {
    "dim": 2, "n_particles": 500, "packing_fraction": 0.3,
    "restitution_normal": 0.6, "restitution_tangential": 0.6,
    "warmup": 0.05, "duration": 0.1, "sample_every": 1000,
    "observables": ["temperature", "velocity_moments", "velocity_histogram", "structure_factor"],
    "velocity_histogram": {"range": [-4, 4], "bins": 200},
    "structure_factor": {"k_max": 10, "every": 5}
  },
  "sweep": {"packing_fraction": [0.2, 0.3]}
}
JSON

# The three growth steps of each campaign.
$py - "$out" <<'PY'
import json, sys
out = sys.argv[1]
def grow(name, steps):
    m = json.load(open(f"{out}/{name}-0.json"))
    for k, f in enumerate(steps, 1):
        f(m)
        json.dump(m, open(f"{out}/{name}-{k}.json", "w"), indent=1)
def more_replicas(m): m["replicas"] = 3
def dsmc_value(m): m["sweep"]["restitution.constant"] = [0.5, 0.7, 0.9]
def dsmc_longer(m):
    m["params"]["t_end"] = 200.0
    m["params"]["output_times"]["log"]["to"] = 200.0
def rfm_value(m): m["sweep"]["packing_fraction"] = [0.2, 0.3, 0.4]
def rfm_longer(m): m["params"]["duration"] = 0.2
grow("dsmc", [more_replicas, dsmc_value, dsmc_longer])
grow("rfm", [more_replicas, rfm_value, rfm_longer])
PY

runs() { [ -d "$1/tables/runs" ] && $py -c "import duckdb; print(duckdb.connect().execute(\"select count(*) from read_parquet('$1/tables/runs/*.parquet')\").fetchall()[0][0])" || echo 0; }
for name in dsmc rfm; do
    c="$out/$name-grown"
    echo "== $name: grown step by step in $c"
    printf '%-22s %8s %9s %9s %8s\n' step "planned" continued executed "wall s"
    for k in 0 1 2 3; do
        m="$out/$name-$k.json"
        plan=$("$bin" plan "$m" --out "$c" --json)
        new=$(echo "$plan" | $py -c 'import json,sys; d=json.load(sys.stdin); print(d["to_run"], d["continued_runs"])')
        before=$(runs "$c")
        s=$(date +%s.%N)
        "$bin" run "$m" --out "$c" --quiet 2>>"$out/$name.log"
        e=$(date +%s.%N)
        after=$(runs "$c")
        label=$(case $k in 0) echo "start";; 1) echo "more replicas";; 2) echo "one more sweep value";; 3) echo "longer t_end/duration";; esac)
        read -r planned cont <<<"$new"
        printf '%-22s %8s %9s %9s %8.1f\n' "$label" "$planned" "$cont" $((after - before)) "$(echo "$e - $s" | bc)"
    done
    d="$out/$name-direct"
    s=$(date +%s.%N)
    "$bin" run "$out/$name-3.json" --out "$d" --quiet 2>>"$out/$name.log"
    e=$(date +%s.%N)
    printf '%-22s %8s %9s %9s %8.1f\n' "direct, final manifest" "" "" "$(runs "$d")" "$(echo "$e - $s" | bc)"
    $py scripts/compare_tables.py "$c" "$d" --current
    du -sh "$c/finals" | awk '{print "final states kept: " $1}'
done
