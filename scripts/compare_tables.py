#!/usr/bin/env python3
"""Compare the tables of two granular campaign directories row for row with DuckDB.

Usage: python scripts/compare_tables.py DIR_A DIR_B [--current] [--ignore table.column ...]

Every table (tables/<t>/*.parquet) must exist in both and hold the same multiset of rows
(EXCEPT ALL in both directions, so order, file layout and compaction do not matter; doubled
rows do). `runs.wall_seconds` (a clock reading) is always ignored. Exits 1 on any difference.

--current compares only what each directory's latest manifest asks for (points with
`in_manifest`), with rows keyed by their point's params and their run's replica instead of
`point_id` and `run_id` (which depend on the order in which a campaign grew), and without
`runs.continued_from`: a grown campaign against one started from its final manifest.
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


def current(d: Path, t: str, keep: list[str], src) -> str:
    """The rows of table t of the points the latest manifest asks for, keyed by params and
    replica instead of point_id and run_id."""
    points = f"read_parquet('{d}/tables/points/*.parquet')"
    runs = f"read_parquet('{d}/tables/runs/*.parquet')"
    cols = [c for c in keep if c not in ("run_id", "point_id")]
    if t == "points":
        return f"SELECT {quoted(cols)} FROM {points} WHERE in_manifest"
    has_point = "point_id" in keep
    has_run = "run_id" in keep and t != "runs"
    if not has_point:
        return f"SELECT {quoted(cols, 'x.')} FROM {src(d)} x"
    sel = f"SELECT {quoted(cols, 'x.')}, p.params AS point_params"
    frm = f" FROM {src(d)} x JOIN {points} p ON p.point_id = x.point_id"
    if has_run:
        sel += ", r.replica AS run_replica"
        frm += f" JOIN {runs} r ON r.run_id = x.run_id"
    return sel + frm + " WHERE p.in_manifest"


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--ignore", nargs="*", default=[])
    ap.add_argument("--current", action="store_true")
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
    for t in ta:
        src = lambda d, t=t: f"read_parquet('{d}/tables/{t}/*.parquet')"
        cols = [r[0] for r in con.execute(f"DESCRIBE SELECT * FROM {src(args.a)}").fetchall()]
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
        print(f"  {'ok  ' if same else 'FAIL'}  {t}: {na} vs {nb} rows, {d1} only in A, {d2} only in B")
        bad += not same
    if bad:
        print(f"{bad} table(s) differ")
        return 1
    print("all tables identical")
    return 0


if __name__ == "__main__":
    sys.exit(main())
