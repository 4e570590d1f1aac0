#!/usr/bin/env bash
# The sizes of the README's "Limits" table, timed: validation, planning and growth must stay
# linear (or n log n) in points and species. Measures, with the release binary (wall time and
# peak RSS from /usr/bin/time; one process, nothing else should run):
#   1. validate of a sweep of POINTS dsmc points (default 10^5, the limit);
#   2. plan of the same into a new directory (nothing written);
#   3. validate of a species list of SPECIES species (default 10^4; refused by the estimated
#      cost of its kinetic theory, after every check) and of 10 x SPECIES;
#   4. growth: a campaign of POINTS/2 tiny bisection runs made by `run`, then `plan` and `run`
#      of a manifest of POINTS points (POINTS/2 new, interleaved with the old ones: the
#      nearest registered point of each new one is searched);
#   5. the kinetic-theory estimate against its measurement for a few sizes (`granular theory`).
# Usage: scripts/bench-limits.sh [POINTS (100000)] [SPECIES (10000)]
#        BIN=path/to/granular (default: this checkout's release build),
#        BASE=path/to/another/granular to time the same commands with it too (e.g. an older
#        build; each of its commands is cut off after LIMIT seconds, default 600).
set -euo pipefail
cd "$(dirname "$0")/.."
points=${1:-100000}
species=${2:-10000}
if [ -z "${BIN:-}" ]; then cargo build --release -q; fi
bin=${BIN:-$PWD/target/release/granular}
limit=${LIMIT:-600}
work=$(mktemp -d /tmp/granular-bench-limits.XXXXXX)
trap 'rm -rf "$work"' EXIT

python3 - "$work" "$points" "$species" <<'PY'
import json, sys
work, points, species = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
def dump(name, m):
    json.dump(m, open(f"{work}/{name}.json", "w"))
# 1-2: one sweep key, `points` distinct restitution values.
dump("points", {"name": "bench-points", "model": "dsmc", "seed": 1,
    "params": {"method": "low_rank",
               "species": {"list": [{"mass": 1, "diameter": 1, "count": 2}]},
               "number_density": 0.1, "restitution": {"constant": 0.5}, "t_end": 0.001},
    "sweep": {"restitution.constant": [round(0.1 + 0.8 * i / points, 9) for i in range(points)]}})
# 3: species lists.
for n, name in [(species, "species"), (10 * species, "species10")]:
    dump(name, {"name": "bench-species", "model": "dsmc", "seed": 1,
        "params": {"method": "low_rank",
                   "species": {"list": [{"mass": 1 + 1e-3 * i, "diameter": 1, "count": 2}
                                        for i in range(n)]},
                   "number_density": 0.1, "restitution": {"constant": 0.9}, "t_end": 1.0}})
# 4: growth of a campaign of tiny bisection runs: points/2 x_min values, then points (the
# old ones and as many new ones in between).
def bis(n):
    return {"name": "bench-growth", "model": "bisection", "seed": 1,
        "params": {"level": 1, "realisations": 2, "split": "uniform",
                   "histogram": {"bins_per_decade": 1, "x_min": 1e-6}, "moment_orders": 1},
        "sweep": {"histogram.x_min": [round(1e-6 * (1 + i / n), 15) for i in range(n)]}}
dump("grow-small", bis(points // 2))
dump("grow-big", bis(points))
# 5: theory sizes (list species k = 1..M of the paper's power law, log outputs).
for m, msd in [(50, False), (200, False), (50, True), (100, True)]:
    sp = [{"mass": float(k), "diameter": k ** (1 / 3), "count": max(2, int(1e6 * k ** -3))}
          for k in range(1, m + 1)]
    dump(f"theory-{m}-{int(msd)}", {"name": "bench-theory", "model": "dsmc", "seed": 1,
        "params": {"method": "low_rank", "species": {"list": sp}, "number_density": 0.1,
                   "restitution": {"constant": 0.5}, "t_end": 1e9,
                   "output_times": {"log": {"from": 0.01, "to": 1e9, "per_decade": 2}},
                   "observables": ["msd"] if msd else []}})
PY

# `timed LABEL BIN ARGS...`: wall seconds and peak RSS of one command (its exit code too).
timed() {
    local label=$1 b=$2
    shift 2
    local rc=0
    /usr/bin/time -f '%e %M' -o "$work/t" timeout "$limit" "$b" "$@" > "$work/out" 2> "$work/err" || rc=$?
    if [ "$rc" = 124 ]; then
        echo "$label: more than $limit s (cut off)"
    else
        read -r wall rss < <(tail -1 "$work/t")
        echo "$label: $wall s, $((rss / 1024)) MB (exit $rc)"
    fi
}

for b in "$bin" ${BASE:+"$BASE"}; do
    echo "== $b"
    timed "validate, $points points" "$b" validate "$work/points.json"
    rm -rf "$work/p"
    timed "plan, $points new points (new campaign)" "$b" plan "$work/points.json" --out "$work/p"
    timed "validate, $species species" "$b" validate "$work/species.json"
    timed "validate, $((10 * species)) species" "$b" validate "$work/species10.json"
    rm -rf "$work/g"
    timed "run, $((points / 2)) tiny bisection runs (the campaign to grow)" "$b" run "$work/grow-small.json" --out "$work/g" --threads 2 --quiet
    cp -a "$work/g" "$work/g2"
    timed "plan of the growth to $points points ($((points / 2)) new)" "$b" plan "$work/grow-big.json" --out "$work/g"
    timed "run of the growth to $points points ($((points / 2)) new runs)" "$b" run "$work/grow-big.json" --out "$work/g2" --threads 2 --quiet
    rm -rf "$work/g" "$work/g2"
done

echo "== kinetic theory: estimate (validate/plan) against measurement (granular theory, one point)"
for f in "$work"/theory-*.json; do
    est=$("$bin" plan "$f" --out "$work/none" 2>/dev/null | sed -n 's/.*kinetic theory of the new points (before the runs): ~\([0-9.]*\) CPU s.*/\1/p')
    rm -rf "$work/th"
    /usr/bin/time -f '%U %M' -o "$work/t" "$bin" theory "$f" --out "$work/th" > /dev/null 2>&1
    read -r cpu rss < "$work/t"
    echo "$(basename "$f" .json) (species, msd): estimated ~$est CPU s, measured $cpu CPU s, $((rss / 1024)) MB"
done
