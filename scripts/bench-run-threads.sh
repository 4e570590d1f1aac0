#!/usr/bin/env bash
# One run on several threads (issue 25): a single 2D RFM run of N = 27 000 discs at the thesis's
# large-system density (jobs/thesis-df-large.json: phi = 0.530, eps_n = eps_t = 0.1, dt = 1e-6 s),
# 2 ms warm-up + 10 ms sampled (12 000 steps, 3.2e8 particle-steps; samples every 500 steps), run as a campaign with
# --threads 1 and with --threads 2 (a campaign of one run: the run itself takes the threads).
# Prints the wall seconds of each (best of REPEATS, default 3, interleaved), particle-steps per
# second, the speedup, and whether the two campaigns' tables are identical
# (scripts/compare_tables.py): they must be, whatever the thread count.
# Usage: scripts/bench-run-threads.sh [REPEATS]   BIN=path/to/granular (default: release build)
#        N=27000 STEPS_MS=10 override the size and the sampled time.
set -euo pipefail
cd "$(dirname "$0")/.."
reps=${1:-3}
if [ -z "${BIN:-}" ]; then cargo build --release -q; fi
bin=${BIN:-$PWD/target/release/granular}
py=${PYTHON:-.venv/bin/python}
n=${N:-27000}
ms=${STEPS_MS:-10}
work=$(mktemp -d /tmp/granular-bench-threads.XXXXXX)
trap 'rm -rf "$work"' EXIT
cat > "$work/m.json" <<JSON
{
  "name": "bench-run-threads",
  "description": "one 2D RFM run of N = $n, thesis-df-large density, $ms ms sampled",
  "model": "rfm",
  "seed": 4301,
  "replicas": 1,
  "params": {
    "dim": 2,
    "n_particles": $n,
    "packing_fraction": 0.530,
    "restitution_normal": 0.1,
    "restitution_tangential": 0.1,
    "dt": 1e-06,
    "warmup": 0.002,
    "duration": $(python3 -c "print($ms / 1000)"),
    "sample_every": 500,
    "observables": ["temperature", "velocity_moments"]
  }
}
JSON
best() { sort -g | head -1; }
declare -A t
for th in 1 2; do : > "$work/times-$th"; done
for r in $(seq 1 "$reps"); do
  for th in 1 2; do
    rm -rf "$work/c$th"
    s=$(date +%s.%N)
    "$bin" run "$work/m.json" --out "$work/c$th" --threads "$th" --quiet 2>>"$work/log"
    e=$(date +%s.%N)
    python3 -c "print($e - $s)" >> "$work/times-$th"
  done
done
steps=$(python3 -c "print(round((0.002 + $ms / 1000) / 1e-6))")
t1=$(best < "$work/times-1"); t2=$(best < "$work/times-2")
python3 - "$t1" "$t2" "$n" "$steps" <<'PY'
import sys
t1, t2, n, steps = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
ps = n * steps
print(f"N = {n}, {steps} steps ({ps:.3g} particle-steps), best wall seconds:")
print(f"  --threads 1: {t1:.3f} s = {ps / t1:.3e} particle-steps/s")
print(f"  --threads 2: {t2:.3f} s = {ps / t2:.3e} particle-steps/s")
print(f"  speedup on 2 threads: {t1 / t2:.2f}x")
PY
if "$py" scripts/compare_tables.py "$work/c1" "$work/c2" > "$work/cmp.txt" 2>&1; then
  echo "tables: identical for --threads 1 and --threads 2"
else
  cat "$work/cmp.txt"; echo "tables: DIFFER between --threads 1 and --threads 2"; exit 1
fi
