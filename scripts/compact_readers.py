#!/usr/bin/env python3
"""`granular compact` while DuckDB, Polars and pyarrow read the same tables in a loop.

Usage: python scripts/compact_readers.py GRANULAR_BIN MANIFEST WORKDIR

Runs MANIFEST into WORKDIR/runs with one commit per finished run (many small parts), then
compacts it several times with growing target sizes (each compaction that merges something
publishes a new generation of the table) while three reader threads count the rows of every
table as docs/operations.md tells users to read beside a compaction: resolve the link
`tables/<t>` once (it must read `.gen/<t>.<n>`) and read that generation's directory,
`tables/.gen/<t>.<n>/*.parquet`, whose files never change and which stays until the second
compaction after it. Every read that succeeds must see exactly the table's row count: no
missing and no doubled rows. A read may fail with "file not found" when its generation was
removed before it opened it, and a read during which the link moved on twice (so that its
generation may have been removed while it was listed) is treated as failed too, as the docs
tell users; the query is then simply rerun. Such failures are counted and reported, never
accepted as data.

Not the glob through the link, `tables/<t>/*.parquet`: DuckDB and pyarrow list a directory
and then stat each entry by its path, silently skipping entries that vanished in between, so
a listing of the old generation finished against the new one misses the merged-away files
with no error (seen in CI: pyarrow read 1 of 4 rows once in ~1800 reads).
Exits 1 if any read saw a wrong row count or no compaction switched a generation.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import duckdb
import polars as pl
import pyarrow.dataset as ds


def main() -> int:
    binary, manifest, work = sys.argv[1], sys.argv[2], Path(sys.argv[3])
    runs = work / "runs"
    subprocess.run([binary, "run", manifest, "--out", str(runs), "--quiet", "--flush-every", "0"], check=True)
    tables = sorted(p.name for p in (runs / "tables").iterdir() if not p.name.startswith("."))
    con = duckdb.connect()
    expected = {
        t: con.execute(f"SELECT count(*) FROM read_parquet('{runs}/tables/{t}/*.parquet')").fetchone()[0]
        for t in tables
    }
    stop = threading.Event()
    stats = {lib: {"ok": 0, "wrong": 0, "error": 0, "errors": set()} for lib in ["duckdb", "polars", "pyarrow"]}

    def generation(t: str) -> tuple[Path, int]:
        """The directory of the generation `tables/<t>` names now (resolved once), and its number."""
        link = runs / "tables" / t
        target = os.readlink(link)
        m = re.fullmatch(r"\.gen/" + re.escape(t) + r"\.([0-9]+)", target)
        if not m:
            raise RuntimeError(f"{link} -> {target!r}, not a generation")
        return runs / "tables" / target, int(m.group(1))

    def count(lib: str, t: str) -> int:
        path, gen = generation(t)
        n = count_in(lib, path)
        # A generation is removed only after the second one after it is published: if that
        # happened, the removal may have overlapped the read (files skipped as vanished).
        if generation(t)[1] >= gen + 2:
            raise RuntimeError(f"generation {gen} of {t} superseded twice while read")
        return n

    def count_in(lib: str, path: Path) -> int:
        if lib == "duckdb":
            c = duckdb.connect()
            return c.execute(f"SELECT count(*) FROM read_parquet('{path}/*.parquet')").fetchone()[0]
        if lib == "polars":
            return pl.scan_parquet(f"{path}/*.parquet").select(pl.len()).collect().item()
        return ds.dataset(str(path), format="parquet").count_rows()

    def reader(lib: str) -> None:
        s = stats[lib]
        while not stop.is_set():
            for t in tables:
                try:
                    n = count(lib, t)
                except Exception as e:  # its generation removed before or while it was read
                    s["error"] += 1
                    s["errors"].add(type(e).__name__ + ": " + str(e).splitlines()[0][:120])
                    continue
                if n == expected[t]:
                    s["ok"] += 1
                else:
                    s["wrong"] += 1
                    print(f"  FAIL  {lib} read {n} rows of {t}, expected {expected[t]}")

    threads = [threading.Thread(target=reader, args=(lib,)) for lib in stats]
    for th in threads:
        th.start()
    switches = 0
    time.sleep(0.3)
    for size in ["8kB", "16kB", "32kB", "64kB", "128kB", "100MB"]:
        out = subprocess.run([binary, "compact", str(runs), "--target-size", size],
                             check=True, capture_output=True, text=True).stdout
        switched = [l.split()[0] for l in out.splitlines() if "generation" in l and "->" in l
                    and l.split()[1] != l.split()[3]]
        switches += len(switched)
        time.sleep(0.3)
    stop.set()
    for th in threads:
        th.join()
    bad = 0
    for lib, s in stats.items():
        print(f"  {lib:8s} {s['ok']:6d} reads with the right row count, {s['wrong']} wrong, {s['error']} failed")
        for e in sorted(s["errors"])[:3]:
            print(f"           e.g. {e}")
        bad += s["wrong"]
    print(f"  {switches} generation switches while reading")
    if bad or switches == 0:
        print("compact_readers: FAILED")
        return 1
    print("compact_readers: passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
