#!/usr/bin/env bash
# The cost model's acceptance check (issue 24, item 4): for each job, `granular plan` into a
# new directory (never run; the calibration is then a probe run of about a second) gives the
# estimated wall time at --threads; `granular run` of the same job into that directory, timed
# with /usr/bin/time, gives the measured one. Prints job, estimated s, measured s, factor
# (the larger over the smaller) and the calibration used.
#
#   scripts/cost-estimate-check.sh [JOB.json ...]    (default: table1-small, paper-fig2, aux-spm)
#   GRANULAR=path/to/granular THREADS=2 PLAN_FLAGS=--no-probe scripts/cost-estimate-check.sh
#
# The machine's load is printed first (`uptime`): other processes on the cores slow the runs
# (and the probe, which measures that).
set -euo pipefail
cd "$(dirname "$0")/.."
G=${GRANULAR:-target/release/granular}
THREADS=${THREADS:-0}
PLAN_FLAGS=${PLAN_FLAGS:-}
if [ $# -eq 0 ]; then
    set -- jobs/table1-small.json jobs/paper-fig2.json jobs/aux-spm.json
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo "# $(uptime)"
echo "# $(nproc) cores, --threads $THREADS, $G"
printf '%-16s %12s %12s %8s  %s\n' job estimated_s measured_s factor calibration
for job in "$@"; do
    name=$(basename "$job" .json)
    dir=$tmp/$name
    # shellcheck disable=SC2086
    "$G" plan "$job" --out "$dir" --json --threads "$THREADS" $PLAN_FLAGS >"$tmp/plan.json"
    read -r est cal < <(python3 -c '
import json, sys
e = json.load(open(sys.argv[1]))["estimate"]
c = e["calibration"]
print("%.1f %s(%.3f)" % (e["wall_seconds"], c["source"].replace(" ", "_"), c["factor"]))
' "$tmp/plan.json")
    /usr/bin/time -f '%e' -o "$tmp/time" "$G" run "$job" --out "$dir" --quiet \
        --threads "$THREADS" 2>"$tmp/run.log" || { cat "$tmp/run.log" >&2; exit 1; }
    measured=$(tail -n 1 "$tmp/time")
    factor=$(python3 -c 'import sys; a, b = float(sys.argv[1]), float(sys.argv[2]); print("%.2f" % (max(a, b) / min(a, b)))' "$est" "$measured")
    printf '%-16s %12s %12s %8s  %s\n' "$name" "$est" "$measured" "$factor" "$cal"
done
echo "# $(uptime)"
