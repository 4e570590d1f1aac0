"""Work-precision analysis of a `work-precision` campaign (see scripts/work-precision.sh).

For each (method, N1): mean wall seconds per run; for species 1 at t = 10 and 100 the relative
deviation of the replica mean from kinetic theory, (mean - theory)/theory, and its noise,
sem/theory. The statistical error of ONE run is sem * sqrt(replicas) / theory: that is the
"precision" a run buys for its time. Writes work_precision.parquet and work_precision.png.
"""
import sys

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq

out = sys.argv[1]
con = duckdb.connect()
rows = con.sql(f"""
with r as (
  select point_id, p.method, p.species_power_law_N1 as n1, avg(wall_seconds) as wall, count(*) as reps,
         avg(collisions) as collisions, avg(trials) as trials
  from read_parquet('{out}/tables/runs/*.parquet')
  join read_parquet('{out}/tables/points/*.parquet') p using (point_id)
  where status = 'done'
  group by point_id, p.method, p.species_power_law_N1
)
select r.method, r.n1, r.reps, r.wall, r.collisions, r.trials, s.t,
       s.temperature_dev_rel, s.temperature_sem / s.temperature_theory as t_noise,
       s.msd_dev_rel, s.msd_sem / s.msd_theory as m_noise
from r join read_parquet('{out}/tables/dsmc_species_summary/*.parquet') s using (point_id)
where s.species = 1 and s.t in (10, 100)
order by r.method, r.n1, s.t
""").fetchall()
cols = ["method", "n1", "replicas", "wall_seconds", "collisions", "trials", "t",
        "temperature_dev_rel", "temperature_noise_rel", "msd_dev_rel", "msd_noise_rel"]
table = pa.table({c: [r[i] for r in rows] for i, c in enumerate(cols)})
pq.write_table(table, f"{out}/work_precision.parquet")
print(f"{'method':<9} {'N1':>8} {'wall/run s':>10} {'t':>5} {'T dev':>8} {'T noise':>8} {'MSD dev':>8} {'MSD noise':>9} {'1-run err':>9}")
for r in rows:
    one_run = r[8] * r[2] ** 0.5
    print(f"{r[0]:<9} {r[1]:>8} {r[3]:>10.3f} {r[6]:>5.0f} {r[7]:>+8.4f} {r[8]:>8.4f} {r[9]:>+8.4f} {r[10]:>9.4f} {one_run:>9.4f}")

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
for ax, (dev, noise, what) in zip(axes, [(7, 8, "temperature $T_1$"), (9, 10, "MSD $\\langle R_1^2\\rangle$")]):
    for method, marker in [("low_rank", "o"), ("bird", "s")]:
        pts = sorted((r[3], r[noise] * r[2] ** 0.5, abs(r[dev]), r[1]) for r in rows if r[0] == method and r[6] == 100)
        ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker + "-", label=f"{method}: statistical error of one run")
        ax.loglog([p[0] for p in pts], [p[2] for p in pts], marker + "--", alpha=0.6, label=f"{method}: |replica mean - theory|")
        for p in pts:
            ax.annotate(f"N1={p[3]:.0e}", (p[0], p[1]), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel("wall time per run [s] (1 thread)")
    ax.set_ylabel(f"relative error of {what} at t = 100")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
fig.suptitle("DSMC work-precision: Table I power law (theta = 3, eps = 0.5)")
fig.tight_layout()
fig.savefig(f"{out}/work_precision.png", dpi=120)
print(f"wrote {out}/work_precision.parquet and {out}/work_precision.png")
