#!/usr/bin/env python3
"""Compare the tables of two granular campaign directories row for row with DuckDB.

Usage: python scripts/compare_tables.py DIR_A DIR_B [--ignore table.column ...]

Every table (tables/<t>/*.parquet) must exist in both and hold the same multiset of rows
(EXCEPT ALL in both directions, so order, file layout and compaction do not matter; doubled
rows do). `runs.wall_seconds` (a clock reading) is always ignored. Exits 1 on any difference.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import duckdb


def tables(d: Path) -> list[str]:
    return sorted(p.name for p in (d / "tables").iterdir() if not p.name.startswith("."))


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--ignore", nargs="*", default=[])
    args = ap.parse_args()
    ignore = {"runs.wall_seconds", *args.ignore}
    ta, tb = tables(args.a), tables(args.b)
    if ta != tb:
        print(f"FAIL different tables: {ta} vs {tb}")
        return 1
    con = duckdb.connect()
    bad = 0
    for t in ta:
        src = lambda d: f"read_parquet('{d}/tables/{t}/*.parquet')"
        cols = [r[0] for r in con.execute(f"DESCRIBE SELECT * FROM {src(args.a)}").fetchall()]
        keep = ", ".join(f'"{c}"' for c in cols if f"{t}.{c}" not in ignore)
        qa = f"SELECT {keep} FROM {src(args.a)}"
        qb = f"SELECT {keep} FROM {src(args.b)}"
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
