#!/usr/bin/env bash
# Engine overhead at scale: a campaign of N short runs (default 100 000: 100 restitution
# values x 1000 replicas of a 20-particle DSMC run to t = 0.01, microseconds of physics each).
# Measures, with the release binary:
#   - validate (plan expansion) time;
#   - run wall time, per-run cost (wall x threads / runs, physics included) and peak RSS;
#   - status time on the half-done campaign (interrupted by SIGINT), and resume start-up
#     (process start to the shard plan being logged);
#   - status after completion, compact, status and verify after compaction.
#   - verify (the full scrub: SHA-256 of every file) and verify --quick (sizes).
# Usage: scripts/bench-scale.sh [RUNS_PER_POINT (1000)] [THREADS (2)]
#        BIN=path/to/granular (default: this checkout's release build), SHARDS=N (1000; 0: none)
# Targets (issue 6): status < 1 s, resume start-up < 2 s, overhead < 5 ms per run, memory bounded.
set -euo pipefail
cd "$(dirname "$0")/.."
reps=${1:-1000}
threads=${2:-2}
if [ -z "${BIN:-}" ]; then cargo build --release -q; fi
bin=${BIN:-$PWD/target/release/granular}
work=$(mktemp -d /tmp/granular-bench-scale.XXXXXX)
trap 'rm -rf "$work"' EXIT
eps=$(python3 -c 'print(",".join(f"{0.5 + 0.005*i:.3f}" for i in range(100)))')
cat > "$work/m.json" <<JSON
{
  "name": "bench-scale",
  "description": "engine overhead: 100 x $reps tiny DSMC runs",
  "model": "dsmc",
  "seed": 1,
  "replicas": $reps,
  "params": {
    "method": "low_rank",
    "species": {"list": [{"mass": 1, "diameter": 1, "count": 20}]},
    "volume": 100,
    "restitution": {"constant": 0.9},
    "t_end": 0.01,
    "output_times": {"list": [0.01]},
    "observables": ["temperature"]
  },
  "sweep": {"restitution.constant": [$eps]}
}
JSON
now() { date +%s.%N; }
secs() { python3 -c "print(f'{$2 - $1:.3f}')"; }

t0=$(now); "$bin" validate "$work/m.json"; t1=$(now)
echo "validate: $(secs $t0 $t1) s"

# Half the campaign (shard 1 of 2: every other run), timed.
d=$work/c
/usr/bin/time -f '%e s wall, %M kB max RSS' -o "$work/time1.txt" \
    "$bin" run "$work/m.json" --out "$d" --threads "$threads" --shard 1/2 --quiet > "$work/run1.log" 2>&1
half=$((50 * reps))
echo "run of shard 1/2 ($half runs): $(cat "$work/time1.txt")"
python3 -c "import re; w=float(open('$work/time1.txt').read().split()[0]); print(f'per run (wall x threads / runs, physics included): {w*$threads/$half*1e3:.3f} ms')"
t0=$(now); "$bin" status "$d" > "$work/status.txt"; t1=$(now)
echo "status (half done: $(head -1 "$work/status.txt" | cut -d: -f2-)): $(secs $t0 $t1) s"
echo "commit records: $(find "$d/ledger" -name 'commit-*.json' | wc -l), table files: $(find -L "$d/tables" -name '*.parquet' | wc -l)"

# Resume: start-up = process start to the shard plan; then the rest with /usr/bin/time.
t0=$(now)
/usr/bin/time -f '%e s wall, %M kB max RSS' -o "$work/time.txt" \
    "$bin" resume "$d" --threads "$threads" --quiet --log-format json > "$work/run2.log" 2>&1
t1=$(now)
plan_ts=$(grep -m1 '"shard plan"' "$work/run2.log" | python3 -c 'import json,sys,datetime; print(datetime.datetime.fromisoformat(json.loads(sys.stdin.readline())["timestamp"].replace("Z","+00:00")).timestamp())')
echo "resume start-up (process start -> shard plan): $(secs $t0 $plan_ts) s"
pending=$(grep -m1 '"shard plan"' "$work/run2.log" | python3 -c 'import json,sys; print(json.loads(sys.stdin.readline())["fields"]["pending"])')
echo "resume of $pending runs: $(cat "$work/time.txt")"
python3 -c "w=$t1-$plan_ts; print(f'per run (wall x threads / runs, physics included): {w*$threads/max($pending,1)*1e3:.3f} ms')"

t0=$(now); "$bin" status "$d" > "$work/status.txt"; t1=$(now)
echo "status (complete): $(secs $t0 $t1) s: $(head -1 "$work/status.txt")"
t0=$(now); "$bin" compact "$d" > "$work/compact.txt"; t1=$(now)
echo "compact: $(secs $t0 $t1) s ($(grep -c generation "$work/compact.txt") tables; $(tail -1 "$work/compact.txt"))"
t0=$(now); "$bin" status "$d" > /dev/null; t1=$(now)
echo "status (compacted): $(secs $t0 $t1) s"
t0=$(now); "$bin" resume "$d" --quiet > /dev/null 2>&1; t1=$(now)
echo "resume of the finished, compacted campaign (nothing to do): $(secs $t0 $t1) s"
t0=$(now); "$bin" verify "$d" | tail -1; t1=$(now)
echo "verify: $(secs $t0 $t1) s"
if "$bin" verify --help | grep -q -- --quick; then
    t0=$(now); "$bin" verify "$d" --quick | tail -1; t1=$(now)
    echo "verify --quick: $(secs $t0 $t1) s"
fi

# The same campaign as SLURM runs it: one process per shard (default 1000 shards of 100 runs),
# so the ledger holds one commit directory per shard until compaction.
shards=${SHARDS:-1000}
if [ "$shards" -gt 0 ]; then
    d2=$work/sharded
    "$bin" run "$work/m.json" --out "$d2" --threads 1 --shard "1/$shards" --quiet 2>/dev/null
    t0=$(now)
    for i in $(seq 2 "$shards"); do
        "$bin" resume "$d2" --threads 1 --shard "$i/$shards" --quiet 2>/dev/null
    done
    t1=$(now)
    echo "$shards shard processes: $(secs $t0 $t1) s ($(python3 -c "print(f'{($t1-$t0)/($shards-1)*1e3:.0f}')") ms per process of $((100 * reps / shards)) runs)"
    echo "commit records: $(find "$d2/ledger" -name 'commit-*.json' | wc -l), table files: $(find -L "$d2/tables" -name '*.parquet' | wc -l)"
    t0=$(now); "$bin" status "$d2" | head -1; t1=$(now)
    echo "status ($shards shards, not compacted): $(secs $t0 $t1) s"
    t0=$(now); "$bin" compact "$d2" | tail -1; t1=$(now)
    echo "compact: $(secs $t0 $t1) s"
    t0=$(now); "$bin" status "$d2" > /dev/null; t1=$(now)
    echo "status ($shards shards, compacted): $(secs $t0 $t1) s"
    "$bin" verify "$d2" | tail -1
fi
