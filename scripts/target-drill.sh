#!/usr/bin/env bash
# Error targets, the acceptance drill of issue 24: a target campaign (default
# jobs/target-mixture.json) run from scratch twice, with --threads 1, as 2 shards running side
# by side, and with 5 kill -9 at random moments (each followed by `resume`) must decide the
# same replicas (campaign.json's rounds) and write the same tables (scripts/compare_tables.py);
# every target must be met, and the replicas asked must be within 1.3x of the fewest that the
# final variances imply.
# Usage: scripts/target-drill.sh [BINARY] [MANIFEST] [OUT]  (defaults: target/release/granular,
#        jobs/target-mixture.json, a new temporary directory). Prints one line per check, and
#        "target-drill: passed" or exits 1.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=$(realpath "${1:-target/release/granular}")
JOB=$(realpath "${2:-jobs/target-mixture.json}")
OUT=${3:-$(mktemp -d /tmp/target-drill.XXXXXX)}
PY=${PYTHON:-.venv/bin/python}
mkdir -p "$OUT"
fail() { echo "target-drill: FAILED: $*"; exit 1; }
rounds() { "$PY" -c 'import json,sys; print(json.dumps(json.load(open(sys.argv[1]))["rounds"], sort_keys=True))' "$1/campaign.json"; }
same() { # DIR_A DIR_B WHAT
  [ "$(rounds "$1")" = "$(rounds "$2")" ] || fail "$3: the rounds differ"
  "$PY" scripts/compare_tables.py "$1" "$2" >"$OUT/compare.log" 2>&1 || { cat "$OUT/compare.log"; fail "$3: the tables differ"; }
  echo "  $3: same rounds, $(tail -1 "$OUT/compare.log")"
}
t0=$(date +%s.%N)
"$BIN" run "$JOB" --out "$OUT/a" --threads 2 --quiet 2>"$OUT/a.log"
t1=$(date +%s.%N)
secs=$(echo "$t1 - $t0" | bc)
echo "from scratch: $(printf %.1f "$secs") s"
"$BIN" status "$OUT/a" --json >"$OUT/a.status.json"
"$PY" - "$OUT/a.status.json" <<'PY' || fail "a target not met, or more than 1.3x the implied replicas"
import json, sys
t = json.load(open(sys.argv[1]))["targets"]
for r in t["rows"]:
    print(f"  point {r['point_id']} {r['point']:<28} {r['quantity']} = {r['mean']:.5f} +- {r['sem']:.2e} "
          f"(sem_rel {r['sem'] / abs(r['mean']):.2e}, goal {r['goal']:.2e}) n {r['n']} {'met' if r['met'] else 'NOT MET'}")
ratio = t["replicas_asked"] / t["replicas_implied"]
print(f"  replicas: {t['replicas_asked']} asked, the final variances imply {t['replicas_implied']}: {ratio:.3f}x; verdict {t['verdict']}")
ok = t["verdict"] == "met" and all(r["met"] for r in t["rows"]) and ratio <= 1.3
sys.exit(0 if ok else 1)
PY

"$BIN" run "$JOB" --out "$OUT/b" --threads 2 --quiet 2>"$OUT/b.log"
same "$OUT/a" "$OUT/b" "second campaign from scratch"
"$BIN" run "$JOB" --out "$OUT/c" --threads 1 --quiet 2>"$OUT/c.log"
same "$OUT/a" "$OUT/c" "--threads 1"

# Two shards side by side: the first creates the campaign, the second starts once it exists;
# each waits for the other at a round's end, and the last to finish decides.
"$BIN" run "$JOB" --out "$OUT/d" --shard 1/2 --threads 1 --quiet 2>"$OUT/d1.log" & p1=$!
while [ ! -e "$OUT/d/campaign.json" ]; do sleep 0.05; done
"$BIN" run "$JOB" --out "$OUT/d" --shard 2/2 --threads 1 --quiet 2>"$OUT/d2.log" & p2=$!
wait $p1 || fail "shard 1/2 exited $?"
wait $p2 || fail "shard 2/2 exited $?"
# A shard that found the other gone leaves the round to it: finish what is left.
for i in 1 2 3 4 5 6; do
  v=$("$BIN" status "$OUT/d" --json | "$PY" -c 'import json,sys; print(json.load(sys.stdin)["targets"]["verdict"])')
  [ "$v" = met ] && break
  "$BIN" resume "$OUT/d" --shard $(( (i % 2) + 1 ))/2 --quiet 2>>"$OUT/d1.log"
done
same "$OUT/a" "$OUT/d" "2 shards side by side"

# 5 kill -9 at random moments (uniform in [5 %, 95 %] of the uninterrupted wall time left),
# each followed by resume.
RANDOM=24
kills=0; first=1
while [ $kills -lt 5 ]; do
  if [ $first = 1 ]; then
    "$BIN" run "$JOB" --out "$OUT/e" --threads 2 --checkpoint-every 0.2 --quiet 2>>"$OUT/e.log" & p=$!; first=0
  else
    "$BIN" resume "$OUT/e" --threads 2 --checkpoint-every 0.2 --quiet 2>>"$OUT/e.log" & p=$!
  fi
  pct=$(( 5 + RANDOM % 90 ))  # in bash: bc's % with a scale is not the integer remainder
  delay=$(echo "scale=3; $secs * $pct / 100 / 4" | bc)
  sleep "$delay"
  if kill -9 $p 2>/dev/null; then wait $p 2>/dev/null || true; kills=$((kills + 1)); echo "  kill -9 after ${delay} s"
  else wait $p || fail "the run exited $? before its kill"; break; fi
done
"$BIN" resume "$OUT/e" --threads 2 --quiet 2>>"$OUT/e.log" || fail "the last resume exited $?"
[ $kills -eq 5 ] || fail "only $kills kill(s) landed before the campaign finished"
same "$OUT/a" "$OUT/e" "5 kill -9 + resume"
echo "target-drill: passed ($OUT)"
