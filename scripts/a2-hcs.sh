#!/usr/bin/env bash
# Validation of the observable `velocity_distribution` (issue 16): the Sonine coefficient a2 of
# a one-species gas with constant restitution alpha in its homogeneous cooling state, against
# van Noije & Ernst (1998): a2 = 16 (1 - a)(1 - 2 a^2) / (81 - 17 a + 30 a^2 (1 - a)).
# Each run starts Maxwellian (a2 = 0) at T = 1 and runs to t_end = 1e5 (60 collisions per
# particle at alpha = 0.3, ~250 at 0.9) with 20 outputs per decade; a replica's a2 is its mean
# over the outputs after the transient (collisions per particle >= C0 = 20), and the error is
# the standard error over replicas (which accounts for the correlation between outputs).
# Measured (N = 20000, 20 replicas, 8 s on 2 cores): the sem is 0.00015-0.0006. The first
# Sonine approximation (vNE, the theory column dsmc_theory.a2) is within 0.0021 of the
# measured a2 at alpha 0.7-0.9 (the issue's aim: 0.002) but 8-10 sem above it; the third-order linear Sonine
# approximation (a2, a3, a4; scripts/sonine_orders.py, derived exactly with sympy) is within
# 1 sem at 0.7-0.9 and 0.001 at 0.5; at 0.3 the Sonine expansion fails (orders 1, 2, 3 give
# 0.118, 0.089, 0.112). The same gap was found with Bird's method, refresh_every 0.05, a later
# transient cut (>= 40 collisions per particle), N = 5000 and 80000, and an independent
# simulation written from scratch (issue 16), so it is the physics, not a bias:
#  alpha   measured      sem   order 1  diff/sem   order 3  diff/sem
#   0.30    0.10241  0.00061   0.11806    -25.83   0.11177    -15.44
#   0.50    0.04761  0.00043   0.05246    -11.16   0.04865     -2.40
#   0.70   -0.00077  0.00024   0.00131     -8.80  -0.00052     -1.04
#   0.80   -0.01438  0.00019  -0.01258     -9.58  -0.01428     -0.52
#   0.90   -0.01570  0.00015  -0.01456     -7.67  -0.01578      0.52
# (finite-N bias of the estimator: -2/(3N+2) for a Maxwellian, -3e-5 here.)
#   scripts/a2-hcs.sh [N] [REPLICAS]     (default 20000 particles, 20 replicas).
#   PY: a Python with duckdb (default .venv/bin/python).
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:-20000}
reps=${2:-20}
py=${PY:-.venv/bin/python}
tgt=${CARGO_TARGET_DIR:-target}
cargo build --release --quiet
out=runs/a2-hcs
rm -rf "$out"
mkdir -p runs
cat > runs/a2-hcs.json <<JSON
{"name": "a2-hcs", "model": "dsmc", "seed": 16, "replicas": $reps,
 "params": {"method": "low_rank",
   "species": {"list": [{"mass": 1, "diameter": 1, "count": $n}]},
   "number_density": 0.1, "restitution": {"constant": 0.5}, "t_end": 1e5,
   "output_times": {"log": {"from": 1, "to": 1e5, "per_decade": 20}},
   "observables": ["velocity_distribution"]},
 "sweep": {"restitution.constant": [0.3, 0.5, 0.7, 0.8, 0.9]}}
JSON
"$tgt/release/granular" run runs/a2-hcs.json --out "$out" --quiet 2>/dev/null
"$py" - "$out" <<'PY'
import math, sys, duckdb
d = f"{sys.argv[1]}/tables"
C0 = 20.0
rows = duckdb.sql(f"""
    select p.restitution_constant a, s.run_id, avg(s.a2) a2, count(*) n
    from read_parquet('{d}/dsmc_species/*.parquet') s
    join read_parquet('{d}/points/*.parquet') p using (point_id)
    where s.collisions / s."count" >= {C0}
    group by 1, 2 order by 1, 2""").fetchall()
by = {}
for a, _, a2, n in rows:
    by.setdefault(a, []).append((a2, n))
# Third-order linear Sonine a2 (a2, a3, a4), from scripts/sonine_orders.py.
ORDER3 = {0.3: 0.11177, 0.5: 0.04865, 0.7: -0.00052, 0.8: -0.01428, 0.9: -0.01578}
print(f"a2 in the HCS (late outputs: collisions per particle >= {C0:g}; sem over replicas)")
print(f"{'alpha':>6} {'measured':>10} {'sem':>8} {'order 1':>9} {'diff/sem':>9} {'order 3':>9} {'diff/sem':>9} {'reps':>5} {'outputs/run':>11}")
for a, v in sorted(by.items()):
    xs = [x for x, _ in v]
    m = sum(xs) / len(xs)
    s = math.sqrt(sum((x - m) ** 2 for x in xs) / (len(xs) - 1) / len(xs))
    th = 16 * (1 - a) * (1 - 2 * a * a) / (81 - 17 * a + 30 * a * a * (1 - a))
    o3 = ORDER3.get(round(a, 2), float("nan"))
    print(f"{a:6.2f} {m:10.5f} {s:8.5f} {th:9.5f} {(m - th) / s:9.2f} {o3:9.5f} {(m - o3) / s:9.2f} {len(xs):5d} {v[0][1]:11d}")
PY
