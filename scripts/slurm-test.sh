#!/usr/bin/env bash
# The SLURM test against a real one-node cluster (scripts/slurm-local.sh): a small campaign is
# submitted as a job array with `granular submit --slurm`, one array task is cancelled while it
# runs, `granular submit --missing` resubmits the unfinished shard, the chained compaction job
# merges the parts, and the final tables must equal those of a single-machine `granular run`
# of the same manifest (scripts/compare_tables.py; only runs.wall_seconds differs); the campaign
# directory's name holds spaces, quotes, $(), backticks, ;, # and % (quoting). Then an
# error-target campaign runs its rounds as chained arrays (each array followed by a round job,
# afterany, that submits the next round's array) until every target is met, and its tables
# must equal a local `granular run` of the same manifest. Stops the daemons it started. Needs target/release/granular and .venv (scripts/setup.sh).
# ~1-2 min on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
bin=$root/target/release/granular
py=$root/.venv/bin/python
[ -x "$bin" ] || { echo "slurm-test: build first (cargo build --release)" >&2; exit 2; }

work=$(mktemp -d /tmp/granular-slurm-test.XXXXXX)
chmod 755 "$work"
cleanup() {
    scancel --name=granular-slurm-ci >/dev/null 2>&1 || true
    scancel --name=granular-slurm-ci-compact >/dev/null 2>&1 || true
    for n in granular-slurm-ci-target granular-slurm-ci-target-round granular-slurm-ci-target-compact; do
        scancel --name="$n" >/dev/null 2>&1 || true
    done
    bash "$root/scripts/slurm-local.sh" stop || true
    rm -rf "$work"
}
trap cleanup EXIT
bash scripts/slurm-local.sh start

cat > "$work/m.json" <<'JSON'
{
  "name": "slurm-ci",
  "description": "SLURM test: 8 low-rank DSMC runs of a few seconds each (N1 = 1e6, t_end = 100)",
  "model": "dsmc",
  "seed": 7,
  "replicas": 4,
  "params": {
    "method": "low_rank",
    "species": {"power_law": {"n1": 0.1, "N1": 1000000, "theta": 3}},
    "restitution": {"constant": 0.5},
    "initial_temperature": 1.0,
    "t_end": 100.0,
    "output_times": {"log": {"from": 0.01, "to": 100.0, "per_decade": 5}},
    "observables": ["temperature"]
  },
  "sweep": {"restitution.constant": [0.5, 0.9]}
}
JSON
# An awkward campaign directory (spaces, quotes, $(), backticks, ;, #, %): sbatch must read the
# scripts' #SBATCH lines into single arguments, SLURM must write the task logs into it, and
# nothing in its name may run (granular quotes it for bash and for sbatch).
out=$work/'slurm run '\''q'\'' "dq" $(touch PWNED) `touch PWNED`; #1 %A 100%'

echo "== submit --dry-run writes nothing"
"$bin" submit "$work/m.json" --out "$out" --slurm --tasks 2 --per-task-runs 2 --time 00:10:00 --dry-run > "$work/dry.txt"
grep -q -- '--array=0-3%2' "$work/dry.txt"
[ ! -e "$out" ] || { echo "FAIL: --dry-run created $out"; exit 1; }

echo "== submit: 8 runs as 4 array tasks of 2 runs, 2 at a time"
"$bin" submit "$work/m.json" --out "$out" --slurm --tasks 2 --per-task-runs 2 --time 00:10:00 | tee "$work/submit1.txt"
array=$("$py" -c 'import json,sys; print(json.load(open(sys.argv[1]))["submissions"][0]["array_job"])' "$out/slurm/submission.json")
test -f "$out/slurm/array-001.sh"

echo "== cancel a running task (array job $array)"
victim=
for _ in $(seq 600); do
    # a running task whose heartbeat lists a run in progress
    for k in $(squeue -h -r -j "$array" -t RUNNING -o '%K'); do
        hb="$out/locks/s$((k + 1))of4.running.json"
        if [ -f "$hb" ] && grep -q '"running":\[[0-9]' "$hb"; then victim=$k; break; fi
    done
    [ -n "$victim" ] && break
    sleep 0.2
done
[ -n "$victim" ] || { echo "FAIL: no array task ran"; squeue; exit 1; }
scancel "${array}_${victim}"
echo "cancelled task $victim"

echo "== wait for the array"
for _ in $(seq 900); do
    squeue -h -j "$array" | grep -q . || break
    sleep 1
done
"$bin" status "$out" | tee "$work/status1.txt"
pending=$("$bin" status "$out" --json | "$py" -c 'import json,sys; s=json.load(sys.stdin); print(s["pending"] + s["running"])')
[ "$pending" -gt 0 ] || { echo "FAIL: the cancelled task left no unfinished runs (it finished before the cancel landed)"; exit 1; }
grep -q "checkpointed and stopped" "$out/slurm/logs/${array}_${victim}.out" \
    || { echo "FAIL: the cancelled task did not checkpoint"; cat "$out/slurm/logs/${array}_${victim}.out"; exit 1; }
ls "$out"/checkpoints/run-*.ckpt >/dev/null || { echo "FAIL: no checkpoint to resume from"; exit 1; }

echo "== submit --missing"
"$bin" submit --missing "$out" | tee "$work/submit2.txt"
grep -q "array ${victim}%2" "$work/submit2.txt" || { echo "FAIL: expected only shard index $victim to be resubmitted"; exit 1; }
ids=$("$py" -c 'import json,sys; s=json.load(open(sys.argv[1]))["submissions"][1]; print(s["array_job"] + "," + s["compact_job"])' "$out/slurm/submission.json")
for _ in $(seq 900); do
    squeue -h -j "$ids" 2>/dev/null | grep -q . || break
    sleep 1
done
"$bin" status "$out"
compact_job=${ids#*,}
cat "$out/slurm/logs/compact-${compact_job}.out"
[ -f "$out/ledger/index.json" ] || { echo "FAIL: the compaction job did not run"; exit 1; }
"$bin" verify "$out"

echo "== single-machine reference"
"$bin" run "$work/m.json" --out "$work/reference" --threads 2 --quiet
"$py" scripts/compare_tables.py "$work/reference" "$out"
if find "$work" "$root" -maxdepth 3 -name PWNED | grep -q .; then
    echo "FAIL: a command injected through the directory name ran"; exit 1
fi

echo "== error targets: the rounds as chained arrays"
cat > "$work/t.json" <<'JSON'
{
  "name": "slurm-ci-target",
  "description": "SLURM test: a binary mixture (500 + 500 particles), gamma = T_2/T_1 at t_end to 0.5 % at two mass ratios, 3 pilot replicas, more in rounds",
  "model": "dsmc",
  "seed": 31,
  "min_replicas": 3,
  "max_replicas": 200,
  "params": {
    "method": "low_rank",
    "species": {"list": [
      {"mass": 1, "diameter": 1, "count": 500},
      {"mass": 2, "diameter": 1, "count": 500}
    ]},
    "volume": 10000,
    "restitution": {"constant": 0.8},
    "initial_temperature": {"hcs": {"mean": 1.0}},
    "t_end": 2,
    "output_times": {"list": [1, 2]},
    "observables": ["temperature"]
  },
  "sweep": {"species.list.1.mass": [2, 8]},
  "derived": {"gamma": "temperature[species=2] / temperature[species=1]"},
  "target": [{"quantity": "gamma", "t": "t_end", "sem_rel": 0.005}]
}
JSON
tout=$work/target
"$bin" submit "$work/t.json" --out "$tout" --slurm --tasks 2 --per-task-runs 2 --time 00:10:00 | tee "$work/tsubmit.txt"
grep -q "round 1 job" "$work/tsubmit.txt" || { echo "FAIL: no round job chained after the pilot array"; exit 1; }
record() { "$py" -c 'import json,sys; r=json.load(open(sys.argv[1])); print(eval(sys.argv[2]))' "$tout/slurm/submission.json" "$1"; }
verdict=
for _ in $(seq 900); do
    verdict=$(record '(r.get("outcome") or {}).get("verdict", "")')
    [ -n "$verdict" ] && break
    sleep 1
done
"$bin" status "$tout" | tee "$work/tstatus.txt"
if [ "$verdict" != met ]; then
    echo "FAIL: the chain of round jobs ended with ${verdict:-nothing} (expected every target met)"
    cat "$tout"/slurm/logs/round-*.out 2>/dev/null || true
    exit 1
fi
arrays=$(record 'len(r["submissions"])')
[ "$arrays" -ge 2 ] || { echo "FAIL: the pilot met the targets; no chained round was run"; exit 1; }
compact_job=$(record 'r["submissions"][-1]["compact_job"]')
for _ in $(seq 900); do
    squeue -h -j "$compact_job" 2>/dev/null | grep -q . || break
    sleep 1
done
cat "$tout"/slurm/logs/round-*.out
[ -f "$tout/ledger/index.json" ] || { echo "FAIL: the compaction job after the last round did not run"; exit 1; }
"$bin" verify "$tout"
"$bin" run "$work/t.json" --out "$work/treference" --threads 2 --quiet
"$py" scripts/compare_tables.py "$work/treference" "$tout"
echo "error targets: $arrays chained arrays, every target met, tables equal a local run's"
echo "slurm-test: passed"
