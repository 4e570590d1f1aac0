#!/usr/bin/env bash
# Prove that a change which is not meant to change any output does not: run every job under a
# minute with two granular binaries, then `plot`, `report` and (for the models that have one)
# `analyze` each campaign, and compare
#   - every table (tables/<t>/*.parquet) with scripts/compare_tables.py ("all tables identical"),
#   - the analysis tables (analysis/*.parquet) the same way, as one-table campaigns,
#   - the figures (figures/, analysis/figures/) byte for byte (diff -r),
#   - the report page with its clock readings (wall seconds, dates, versions) and each shard's
#     number of commits (the flushes follow the clock) taken out.
#
# Usage: scripts/jobs-identical.sh OLD_BIN NEW_BIN OUT_DIR [JOB ...]
#   OUT_DIR/old/<job> and OUT_DIR/new/<job> are kept (an existing OUT_DIR/old/<job> with a
#   finished marker is reused, so the old side is run once for several new builds; the new
#   side is run again at every call).
#   NEW_BIN "-" prepares the old side only.
#   Default jobs: those that finish in about a minute on 2 cores.
# Exits 1 if anything differs. Needs the venv of scripts/setup.sh (duckdb, pyarrow).
set -euo pipefail

old_bin=$1 new_bin=$2 out=$3
shift 3
jobs=("$@")
if [ ${#jobs[@]} -eq 0 ]; then
    jobs=(table1-small hcs-velocity paper-fig1 paper-fig2 paper-fig3 paper-fig5 paper-fig6
          rfm1d-xi2-small rfm2d-steady aux-bisection aux-cascade aux-cascade-placement aux-spm)
fi
here=$(cd "$(dirname "$0")/.." && pwd)
py=${PYTHON:-$here/.venv/bin/python}
[ -x "$py" ] || py=python3

side() { # side BIN DIR JOB REUSE (1: keep a finished DIR)
    local bin=$1 dir=$2 job=$3 reuse=$4
    [ "$reuse" = 1 ] && [ -f "$dir.done" ] && return 0
    rm -rf "$dir" "$dir.done"
    "$bin" run "$here/jobs/$job.json" --out "$dir" >"$dir.log" 2>&1
    "$bin" plot "$dir" >>"$dir.log" 2>&1
    "$bin" report "$dir" >>"$dir.log" 2>&1
    local model
    model=$("$py" -c "import json,sys;print(json.load(open(sys.argv[1]))['model'])" "$here/jobs/$job.json")
    case $model in
        rfm | cascade) "$bin" analyze "$dir" >>"$dir.log" 2>&1 ;;
    esac
    touch "$dir.done"
}

# The report's clock readings and versions: lines that differ between any two runs (the
# finished runs' measured core-hours in the cost line are a clock reading too).
scrub() {
    sed -E -e "s#$2#<dir>#g" -e 's/([0-9]+(\.[0-9]+)? ?(h|min|ms|s)\b ?)+/<time>/g' \
        -e 's/20[0-9]{2}-[0-9]{2}-[0-9]{2}[T ][0-9:.Z+-]+/<date>/g' \
        -e 's/granular [0-9]+\.[0-9]+\.[0-9]+[^ <"]*/granular <version>/g' \
        -e 's/took [0-9.eE+-]+ \(ratio [0-9.]+\)/took <core-hours>/g' \
        -e 's#(<td>s[0-9]+of[0-9]+</td>[[:space:]]*<td class="n">)[0-9]+#\1<commits>#g' "$1"
}

mkdir -p "$out/old" "$out/new"
fail=0
for job in "${jobs[@]}"; do
    a=$out/old/$job b=$out/new/$job
    start=$(date +%s)
    side "$old_bin" "$a" "$job" 1
    if [ "$new_bin" = - ]; then
        echo "$job: old side ready"
        continue
    fi
    # The new side always runs: a finished one from an earlier call came from another build.
    side "$new_bin" "$b" "$job" 0
    verdict=ok
    if ! "$py" "$here/scripts/compare_tables.py" "$a" "$b" >"$b.compare" 2>&1; then
        verdict="TABLES DIFFER (see $b.compare)"
    fi
    if [ -d "$a/analysis" ] || [ -d "$b/analysis" ]; then
        # Row for row, not byte for byte (how a file is compressed is not its content): each
        # analysis table copied into a one-table campaign on each side.
        for t in "$a"/analysis/*.parquet; do
            n=$(basename "$t")
            one=$out/analysis-compare/$job/${n%.parquet}
            rm -rf "$one"
            mkdir -p "$one/a/tables/t" "$one/b/tables/t"
            cp "$t" "$one/a/tables/t/"
            if [ -f "$b/analysis/$n" ]; then cp "$b/analysis/$n" "$one/b/tables/t/"; fi
            "$py" "$here/scripts/compare_tables.py" "$one/a" "$one/b" >"$one.compare" 2>&1 ||
                verdict="${verdict#ok}; analysis/$n differs (see $one.compare)"
        done
    fi
    for f in figures analysis/figures; do
        if [ -d "$a/$f" ] || [ -d "$b/$f" ]; then
            diff -r -q "$a/$f" "$b/$f" >"$b.figdiff" 2>&1 || verdict="${verdict#ok}; $f differ (see $b.figdiff)"
        fi
    done
    if ! diff -q <(scrub "$a/report.html" "$a") <(scrub "$b/report.html" "$b") >/dev/null; then
        verdict="${verdict#ok}; report.html differs beyond clock readings"
    fi
    nf=$(find "$b/figures" "$b/analysis/figures" -type f 2>/dev/null | wc -l || true)
    nt=$(find "$b/tables" -name '*.parquet' 2>/dev/null | wc -l || true)
    printf '%-24s %-60s (%d table files, %d figure files, %ds)\n' "$job" "$verdict" "$nt" "$nf" $(($(date +%s) - start))
    [ "$verdict" = ok ] || fail=1
done
exit $fail
