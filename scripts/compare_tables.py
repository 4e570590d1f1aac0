#!/usr/bin/env python3
"""Compare the tables of two granular campaign directories row for row with DuckDB.

Usage: python scripts/compare_tables.py DIR_A DIR_B [--current] [--ignore table.column ...]
       [--rtol X] [--allow-extra-columns]

Every table (tables/<t>/*.parquet) must exist in both and hold the same multiset of rows
(EXCEPT ALL in both directions, so order, file layout and compaction do not matter; doubled
rows do). `runs.wall_seconds` (a clock reading) is always ignored. Exits 1 on any difference.

--rtol X compares, in a table that differs, every pair of rows (ordered by their non-float
columns, then the floats) with a relative tolerance X on floats (exact on everything else),
and prints each float column's largest relative difference: for a change that reorders sums.

--current compares only what each directory's latest manifest asks for (points and
`registered_runs` with `in_manifest`), with rows keyed by their point's params and their run's
replica in the latest manifest (`registered_runs.manifest_replica`) instead of `point_id` and
`run_id` (which depend on the order in which a campaign grew), and without
`runs.continued_from` and the registry's own numbering (`runs.replica`,
`registered_runs.replica`, `registered_runs.continues`): a grown campaign against one started
from its final manifest. (A directory without `registered_runs`, written by an earlier
granular, is keyed by `runs.replica` and filtered by points only.)

A table whose columns differ between A and B (by name) fails, naming the columns present on
one side only; with --allow-extra-columns those columns are left out and the shared ones
compared (e.g. summaries written before and after they gained the sweep columns).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import duckdb


def tables(d: Path) -> list[str]:
    return sorted(p.name for p in (d / "tables").iterdir() if not p.name.startswith("."))


def quoted(cols: list[str], prefix: str = "") -> str:
    return ", ".join(f'{prefix}"{c}"' for c in cols)


def parquet(d, t: str) -> str:
    """read_parquet of table t of campaign d, the path as an SQL string literal (' doubled)."""
    glob = f"{d}/tables/{t}/*.parquet".replace("'", "''")
    return f"read_parquet('{glob}')"


def current(d: Path, t: str, keep: list[str], src) -> str:
    """The rows of table t of the runs and points the latest manifest asks for, keyed by
    params and replica (the run's replica in the latest manifest, from `registered_runs`)
    instead of point_id and run_id."""
    points = parquet(d, "points")
    runs = parquet(d, "runs")
    has_reg = any((d / "tables" / "registered_runs").glob("*.parquet"))
    reg = parquet(d, "registered_runs")
    cols = [c for c in keep if c not in ("run_id", "point_id")]
    if t == "points":
        return f"SELECT {quoted(cols)} FROM {points} WHERE in_manifest"
    if t == "registered_runs":
        # The registry's own numbering (replica, continues) depends on how the campaign grew.
        cols = [c for c in cols if c not in ("replica", "continues")]
        return (
            f"SELECT {quoted(cols, 'x.')}, p.params AS point_params FROM {reg} x"
            f" JOIN {points} p ON p.point_id = x.point_id WHERE x.in_manifest"
        )
    has_point = "point_id" in keep
    has_run = "run_id" in keep and (t != "runs" or has_reg)
    if t == "runs" and has_reg:
        # `replica` is the registry's; the latest manifest's is compared instead.
        cols = [c for c in cols if c != "replica"]
    if not has_point:
        return f"SELECT {quoted(cols, 'x.')} FROM {src(d)} x"
    sel = f"SELECT {quoted(cols, 'x.')}, p.params AS point_params"
    frm = f" FROM {src(d)} x JOIN {points} p ON p.point_id = x.point_id"
    where = " WHERE p.in_manifest"
    if has_run and has_reg:
        sel += ", r.manifest_replica AS run_replica"
        frm += f" JOIN {reg} r ON r.run_id = x.run_id"
        where += " AND r.in_manifest"
    elif has_run:
        sel += ", r.replica AS run_replica"
        frm += f" JOIN {runs} r ON r.run_id = x.run_id"
    return sel + frm + where


def within(con, qa: str, qb: str, rtol: float) -> tuple[bool, str]:
    """Rows of qa and qb paired in order (non-float columns first, then floats), floats within
    rtol (relative to the larger magnitude; equal non-finite values match), the rest exact."""
    desc = con.execute(f"DESCRIBE {qa}").fetchall()
    names = [r[0] for r in desc]
    floats = {r[0] for r in desc if r[1] in ("DOUBLE", "FLOAT")}
    order = ", ".join(f'"{c}"' for c in [c for c in names if c not in floats] + [c for c in names if c in floats])
    ra = con.execute(f"SELECT * FROM ({qa}) ORDER BY {order}").fetchall()
    rb = con.execute(f"SELECT * FROM ({qb}) ORDER BY {order}").fetchall()
    worst = {c: 0.0 for c in floats}
    for x, y in zip(ra, rb):
        for c, u, v in zip(names, x, y):
            if c in floats and u is not None and v is not None:
                if u == v or (u != u and v != v):
                    continue
                scale = max(abs(u), abs(v))
                rel = abs(u - v) / scale if scale > 0 else float("inf")
                worst[c] = max(worst[c], rel)
            elif u != v:
                return False, f"column {c}: {u!r} vs {v!r} (not a float)"
    big = {c: w for c, w in worst.items() if w > 0}
    ok = all(w <= rtol for w in worst.values())
    detail = ", ".join(f"{c} {w:.1e}" for c, w in sorted(big.items())) or "no float differs"
    return ok, f"largest relative differences: {detail}"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--ignore", nargs="*", default=[])
    ap.add_argument("--current", action="store_true")
    ap.add_argument("--rtol", type=float, default=None)
    ap.add_argument("--allow-extra-columns", action="store_true")
    args = ap.parse_args()
    ignore = {"runs.wall_seconds", *args.ignore}
    if args.current:
        ignore |= {"runs.continued_from"}
    ta, tb = tables(args.a), tables(args.b)
    if ta != tb:
        print(f"FAIL different tables: {ta} vs {tb}")
        return 1
    con = duckdb.connect()
    bad = 0
    approx = 0
    for t in ta:
        src = lambda d, t=t: parquet(d, t)
        cols = [r[0] for r in con.execute(f"DESCRIBE SELECT * FROM {src(args.a)}").fetchall()]
        cols_b = [r[0] for r in con.execute(f"DESCRIBE SELECT * FROM {src(args.b)}").fetchall()]
        only_a = [c for c in cols if c not in cols_b]
        only_b = [c for c in cols_b if c not in cols]
        if only_a or only_b:
            what = f"columns only in A: {only_a}, only in B: {only_b}"
            if not args.allow_extra_columns:
                print(f"  FAIL  {t}: {what}")
                bad += 1
                continue
            print(f"  note  {t}: {what} (left out, --allow-extra-columns)")
            cols = [c for c in cols if c in cols_b]
        keep = [c for c in cols if f"{t}.{c}" not in ignore]
        if args.current:
            qa, qb = (current(d, t, keep, src) for d in (args.a, args.b))
        else:
            qa = f"SELECT {quoted(keep)} FROM {src(args.a)}"
            qb = f"SELECT {quoted(keep)} FROM {src(args.b)}"
        na = con.execute(f"SELECT count(*) FROM ({qa})").fetchone()[0]
        nb = con.execute(f"SELECT count(*) FROM ({qb})").fetchone()[0]
        d1 = con.execute(f"SELECT count(*) FROM ({qa} EXCEPT ALL {qb})").fetchone()[0]
        d2 = con.execute(f"SELECT count(*) FROM ({qb} EXCEPT ALL {qa})").fetchone()[0]
        same = na == nb and d1 == 0 and d2 == 0
        if not same and args.rtol is not None and na == nb:
            ok, detail = within(con, qa, qb, args.rtol)
            print(f"  {'~ok ' if ok else 'FAIL'}  {t}: {na} rows, {d1} differ exactly; {detail}")
            bad += not ok
            approx += ok
            continue
        print(f"  {'ok  ' if same else 'FAIL'}  {t}: {na} vs {nb} rows, {d1} only in A, {d2} only in B")
        bad += not same
    if bad:
        print(f"{bad} table(s) differ")
        return 1
    if approx:
        print(f"all tables identical but {approx}, which agree within --rtol {args.rtol}")
    else:
        print("all tables identical")
    return 0


if __name__ == "__main__":
    sys.exit(main())
