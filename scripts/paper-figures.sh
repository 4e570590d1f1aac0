#!/usr/bin/env bash
# Run the paper's reproduction jobs (jobs/paper-fig*.json; pass figure numbers to choose, e.g.
# `scripts/paper-figures.sh 2 3`), draw their figures, and print per species the range of the
# relative deviation of DSMC from kinetic theory (temperature, MSD, time-averaged MSD).
set -euo pipefail
cd "$(dirname "$0")/.."
figs=${*:-1 2 3 4 5 6 7 8}
cargo build --release --quiet
for f in $figs; do
    out=runs/paper-fig$f
    rm -rf "$out"
    start=$(date +%s%N)
    target/release/granular run "jobs/paper-fig$f.json" --out "$out" --quiet 2>/dev/null
    end=$(date +%s%N)
    target/release/granular plot "$out" >/dev/null
    echo "== paper-fig$f: $(( (end - start) / 1000000 )) ms"
    .venv/bin/python - "$out" <<'PY'
import sys, duckdb
out = sys.argv[1]
q = f"""
select species, count(*) as times,
       min(temperature_dev_rel), max(temperature_dev_rel),
       min(msd_dev_rel), max(msd_dev_rel)
from read_parquet('{out}/tables/dsmc_species_summary/*.parquet')
where t > 0 group by species order by species"""
rows = duckdb.sql(q).fetchall()
shown = rows if len(rows) <= 6 else [r for r in rows if r[0] in (1, 2, 3, 5, 10, 20)]
for s, n, t0, t1, m0, m1 in shown:
    msd = f"MSD {m0:+.3f} .. {m1:+.3f}" if m0 is not None else ""
    print(f"   species {s:>3}: T {t0:+.3f} .. {t1:+.3f}  {msd}")
try:
    for s, l0, l1 in duckdb.sql(f"select species, min(tamsd_mean/tamsd_theory-1), max(tamsd_mean/tamsd_theory-1) from read_parquet('{out}/tables/dsmc_tamsd_summary/*.parquet') group by species order by species").fetchall():
        print(f"   species {s:>3}: TAMSD vs (27) {l0:+.3f} .. {l1:+.3f}")
except duckdb.Error:
    pass
PY
done
