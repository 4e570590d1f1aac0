#!/usr/bin/env bash
# Validation of the first Sonine theory in the paper's mixtures (issue 16): jobs/paper-fig1,
# 2, 3 and 5 as committed, with the observable "velocity_distribution" added and 16 replicas
# (the observable draws no random numbers, but a run's seed derives from the campaign's name
# and the point's params, so these are other samples than the jobs'). Per job and species, over the
# output times t >= t_end/10: the worst |relative deviation| of T_k and MSD_k from the
# Maxwellian theory (the paper's) and from the first Sonine approximation, and the measured
# a2_k (mean over those times of the replica mean, with the sem at t_end) against a2_theory.
# Measured with 16 replicas (20 s on 2 cores); the README's Validation discusses it:
# job    k   T Maxw  T Sonine  MSD Maxw  MSD Sonine   a2 DSMC     sem  a2 theory coll/part
# fig1   1    2.57%     0.42%     2.49%     1.56%    0.0510  0.0024     0.0524     101.9
# fig1   2    1.62%     0.43%     3.26%     1.87%    0.0442  0.0034     0.0460      79.1
# fig2   1    0.96%     0.48%     1.89%     1.74%    0.1105  0.0012     0.1232      67.7
# fig2   2    8.36%     0.70%     1.57%     3.38%   -0.1014  0.0036    -0.0866     499.9
# fig3   1    1.42%     2.39%     7.30%     4.78%    0.0145  0.0028     0.0395      39.3
# fig3   2    1.52%     0.80%     5.41%     3.84%    0.0244  0.0017     0.0324      57.4
# fig3   3    1.60%     0.15%     3.36%     1.85%    0.0527  0.0021     0.0571      85.1
# fig5   1    1.07%     3.11%     3.90%     0.16%    0.0956  0.0024     0.1337      55.0
# fig5   2   51.09%    25.72%    30.75%    12.65%   -0.3787  0.0034    -0.2097     809.6
#   scripts/sonine-mixtures.sh [REPLICAS]   (default 16)   PY: a Python with duckdb (default .venv/bin/python).
set -euo pipefail
cd "$(dirname "$0")/.."
py=${PY:-.venv/bin/python}
tgt=${CARGO_TARGET_DIR:-target}
reps=${1:-16}
cargo build --release --quiet
mkdir -p runs
for j in 1 2 3 5; do
  out=runs/sonine-fig$j
  rm -rf "$out"
  "$py" - "$j" "$reps" <<'PY'
import json, sys
j = sys.argv[1]
m = json.load(open(f"jobs/paper-fig{j}.json"))
m["name"] = f"sonine-fig{j}"
m["replicas"] = int(sys.argv[2])
m["params"]["observables"] = m["params"]["observables"] + ["velocity_distribution"]
json.dump(m, open(f"runs/sonine-fig{j}.json", "w"), indent=1)
PY
  "$tgt/release/granular" run "runs/sonine-fig$j.json" --out "$out" --quiet 2>/dev/null
done
"$py" - <<'PY'
import duckdb
print(f"{'job':5} {'k':>2} {'T Maxw':>8} {'T Sonine':>9} {'MSD Maxw':>9} {'MSD Sonine':>11} {'a2 DSMC':>9} {'sem':>7} {'a2 theory':>10} {'coll/part':>9}")
for j in (1, 2, 3, 5):
    d = f"runs/sonine-fig{j}/tables"
    rows = duckdb.sql(f"""
        with s as (select * from read_parquet('{d}/dsmc_species_summary/*.parquet')),
             e as (select max(t) te from s)
        select species,
               max(abs(temperature_dev_rel)), max(abs(temperature_sonine_dev_rel)),
               max(abs(msd_dev_rel)), max(abs(msd_sonine_dev_rel)),
               avg(a2_mean), arg_max(a2_sem, t), avg(a2_theory)
        from s, e where t >= te / 10 group by species order by species""").fetchall()
    coll = dict(duckdb.sql(f"""
        with r as (select * from read_parquet('{d}/dsmc_species/*.parquet'))
        select species, avg(collisions / "count") from r
        where t = (select max(t) from r) group by species""").fetchall())
    for k, tm, ts, mm, ms, am, asem, ath in rows:
        f = lambda x: f"{100 * x:8.2f}%" if x is not None else f"{'-':>9}"
        g = lambda x, w=9: f"{x:{w}.4f}" if x is not None else f"{'-':>{w}}"
        print(f"fig{j:<2} {k:>2} {f(tm)} {f(ts)} {f(mm)} {f(ms)} {g(am)} {g(asem, 7)} {g(ath, 10)} {coll.get(k, 0):9.1f}")
PY
