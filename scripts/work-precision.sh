#!/usr/bin/env bash
# Run time against error for both DSMC methods (issue: "Run time against error").
# Sweeps N1 = 1e3 .. 1e6 (Table I power law, theta = 3, eps = 0.5, t = 100) x method, with
# replicas, then writes runs/work-precision/work_precision.parquet and work_precision.png:
# wall time per run against the error of species-1 temperature and MSD at t = 10 and 100,
# relative to kinetic theory, with its statistical noise.
#   scripts/work-precision.sh [max_N1] [replicas]     (defaults 1000000, 4; ~5 min on 2 cores)
set -euo pipefail
cd "$(dirname "$0")/.."
max=${1:-1000000}
reps=${2:-4}
out=runs/work-precision
sizes=$(python3 -c "print(', '.join(str(10**k) for k in range(3, 7) if 10**k <= $max))")
mkdir -p runs
cat > runs/work-precision.json <<JSON
{
  "name": "work-precision",
  "description": "Work-precision: both methods over N1 = 1e3 .. $max, $reps replicas",
  "model": "dsmc",
  "seed": 7,
  "replicas": $reps,
  "params": {
    "method": "low_rank",
    "species": {"power_law": {"n1": 0.1, "N1": 1000, "theta": 3}},
    "restitution": {"constant": 0.5},
    "t_end": 100,
    "output_times": {"list": [10, 100]},
    "observables": ["temperature", "msd"]
  },
  "sweep": {"method": ["low_rank", "bird"], "species.power_law.N1": [$sizes]}
}
JSON
cargo build --release --quiet
rm -rf "$out"
target/release/granular run runs/work-precision.json --out "$out" --quiet
.venv/bin/python -c 'import matplotlib' 2>/dev/null || .venv/bin/pip install -q matplotlib
.venv/bin/python scripts/work_precision.py "$out"
