#!/usr/bin/env python3
"""Read the tables of a finished granular campaign with DuckDB, pyarrow and Polars.

Usage: python scripts/check_tables.py RUNS_DIR [--allow-failed]

RUNS_DIR is a campaign directory written by `granular run` (it holds campaign.json and
tables/<table>/*.parquet). Every table is read as a hive-style dataset by each of the three
libraries, the way the README tells users to read them:

    duckdb.read_parquet("RUNS_DIR/tables/<t>/*.parquet", hive_partitioning=True)
    pyarrow.dataset.dataset("RUNS_DIR/tables/<t>", format="parquet", partitioning="hive")
    polars.scan_parquet("RUNS_DIR/tables/<t>/*.parquet", hive_partitioning=True)

Checks:
  * the row counts of runs, points, registered_runs, dsmc_species, dsmc_species_summary are the same in all
    three libraries and equal to what campaign.json implies (for a campaign that never grew,
    runs = product of the sweep list lengths x replicas (or seeds); for a grown one, the
    registry's points and runs; dsmc_species = done runs x species x output times, the latter
    two counted per point in the table itself; dsmc_species_summary = the latest manifest's
    points x species x output times; registered_runs = every registered run);
  * no (run_id, t, species) row is doubled;
  * every file carries the `granular.manifest` key-value metadata (pyarrow schema.metadata,
    DuckDB parquet_kv_metadata, Polars read_parquet_metadata) and it equals the manifest of
    campaign.json (for a grown campaign: it is a manifest of the same name, model and seed,
    files written before the latest manifest carrying an earlier one);
  * at t = 0 every species with count >= 2 has exactly its initial temperature (relative
    tolerance 1e-9), read through each library;
  * dsmc_species_summary.temperature_mean equals the mean over the latest manifest's replicas of
    dsmc_species.temperature for one (point, t, species) through each library, and for every
    (point, t, species) through DuckDB (relative tolerance 1e-12).

Prints a short report; exits 1 if any check fails, 2 on bad usage.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import duckdb
import polars as pl
import pyarrow.compute as pc
import pyarrow.dataset as ds

TABLES = ["runs", "points", "registered_runs", "dsmc_species", "dsmc_species_summary"]
LIBS = ["duckdb", "pyarrow", "polars"]
T0_RTOL = 1e-9
MEAN_RTOL = 1e-12


class Report:
    def __init__(self) -> None:
        self.failures: list[str] = []

    def ok(self, msg: str) -> None:
        print(f"  ok    {msg}")

    def fail(self, msg: str) -> None:
        print(f"  FAIL  {msg}")
        self.failures.append(msg)

    def check(self, cond: bool, msg: str) -> bool:
        (self.ok if cond else self.fail)(msg)
        return cond


def rel_close(a: float, b: float, rtol: float) -> bool:
    return a == b or abs(a - b) <= rtol * max(abs(a), abs(b))


# --- readers -----------------------------------------------------------------------------


class Readers:
    """The three libraries' views of the campaign's tables."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.con = duckdb.connect()

    def dir(self, table: str) -> Path:
        return self.root / "tables" / table

    def glob(self, table: str) -> str:
        return str(self.dir(table) / "*.parquet")

    def duck(self, table: str) -> duckdb.DuckDBPyRelation:
        return self.con.read_parquet(self.glob(table), hive_partitioning=True)

    def arrow(self, table: str) -> ds.Dataset:
        return ds.dataset(str(self.dir(table)), format="parquet", partitioning="hive")

    def polars(self, table: str) -> pl.LazyFrame:
        return pl.scan_parquet(self.glob(table), hive_partitioning=True)

    def count(self, lib: str, table: str) -> int:
        if lib == "duckdb":
            return int(self.duck(table).aggregate("count(*)").fetchall()[0][0])
        if lib == "pyarrow":
            return int(self.arrow(table).count_rows())
        return int(self.polars(table).select(pl.len()).collect().item())

    def t0_rows(self, lib: str) -> list[tuple[int, int, int, float]]:
        """(point_id, species, count, temperature) of every dsmc_species row at t = 0."""
        cols = ["point_id", "species", "count", "temperature"]
        if lib == "duckdb":
            rel = self.duck("dsmc_species").filter("t = 0").project(", ".join(f'"{c}"' for c in cols))
            return [tuple(r) for r in rel.fetchall()]
        if lib == "pyarrow":
            tab = self.arrow("dsmc_species").to_table(columns=cols, filter=ds.field("t") == 0.0)
            return list(zip(*(tab.column(c).to_pylist() for c in cols)))
        df = self.polars("dsmc_species").filter(pl.col("t") == 0.0).select(cols).collect()
        return list(df.iter_rows())

    def replica_temperatures(self, lib: str, point: int, t: float, species: int) -> list[float]:
        if lib == "duckdb":
            rel = self.duck("dsmc_species").filter(f"point_id = {point} AND species = {species} AND t = {t!r}::DOUBLE")
            return [r[0] for r in rel.order("run_id").project("temperature").fetchall()]
        if lib == "pyarrow":
            f = (ds.field("point_id") == point) & (ds.field("species") == species) & (ds.field("t") == t)
            tab = self.arrow("dsmc_species").to_table(columns=["run_id", "temperature"], filter=f).sort_by("run_id")
            return tab.column("temperature").to_pylist()
        df = (
            self.polars("dsmc_species")
            .filter((pl.col("point_id") == point) & (pl.col("species") == species) & (pl.col("t") == t))
            .sort("run_id")
            .select("temperature")
            .collect()
        )
        return df["temperature"].to_list()

    def summary_mean(self, lib: str, point: int, t: float, species: int) -> list[float]:
        if lib == "duckdb":
            rel = self.duck("dsmc_species_summary").filter(f"point_id = {point} AND species = {species} AND t = {t!r}::DOUBLE")
            return [r[0] for r in rel.project("temperature_mean").fetchall()]
        if lib == "pyarrow":
            f = (ds.field("point_id") == point) & (ds.field("species") == species) & (ds.field("t") == t)
            return self.arrow("dsmc_species_summary").to_table(columns=["temperature_mean"], filter=f).column(0).to_pylist()
        df = (
            self.polars("dsmc_species_summary")
            .filter((pl.col("point_id") == point) & (pl.col("species") == species) & (pl.col("t") == t))
            .select("temperature_mean")
            .collect()
        )
        return df["temperature_mean"].to_list()

    def manifests(self, lib: str, table: str) -> dict[str, str | None]:
        """file name -> its granular.manifest metadata (None when absent)."""
        files = sorted(p for p in self.dir(table).glob("*.parquet") if not p.name.startswith("."))
        if lib == "pyarrow":
            # The dataset's schema carries the first file's metadata; check each fragment too.
            dset = self.arrow(table)
            out = {}
            for frag in dset.get_fragments():
                md = frag.physical_schema.metadata or {}
                v = md.get(b"granular.manifest")
                out[Path(frag.path).name] = v.decode() if v is not None else None
            if b"granular.manifest" not in (dset.schema.metadata or {}):
                out["<dataset schema>"] = None
            return out
        if lib == "duckdb":
            rows = self.con.execute(
                f"SELECT file_name, key, value FROM parquet_kv_metadata('{self.glob(table)}')"
            ).fetchall()
            out = {Path(f).name: None for f, _, _ in rows}
            for f, k, v in rows:
                if bytes(k) == b"granular.manifest":
                    out[Path(f).name] = bytes(v).decode()
            return out
        return {p.name: pl.read_parquet_metadata(str(p)).get("granular.manifest") for p in files}


# --- checks ------------------------------------------------------------------------------


def expected_counts(info: dict) -> tuple[int, int]:
    """(points, runs): those the manifest's sweep and replicas (or seeds) imply for a campaign
    that never grew, else those of the registry."""
    if len(info.get("history", [])) > 1:
        reg = info["registry"]
        return len(reg["points"]), sum(b["count"] for b in reg["blocks"])
    manifest = info["manifest"]
    n_points = 1
    for values in (manifest.get("sweep") or {}).values():
        n_points *= len(values)
    per_point = len(manifest["seeds"]) if manifest.get("seeds") else int(manifest.get("replicas") or 1)
    return n_points, n_points * per_point


def initial_temperatures(params: dict) -> dict[int, float] | float:
    """Expected t = 0 temperature: a number for every species, or species -> T for a list."""
    t0 = float(params.get("initial_temperature", 1.0))
    species = params["species"]
    if "list" in species:
        return {k + 1: float(s.get("temperature", t0)) for k, s in enumerate(species["list"])}
    return t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs_dir", type=Path, help="campaign directory (holds campaign.json and tables/)")
    ap.add_argument("--allow-failed", action="store_true", help="do not count failed runs as a check failure")
    args = ap.parse_args()
    root: Path = args.runs_dir
    info_path = root / "campaign.json"
    if not info_path.is_file():
        print(f"error: {info_path} not found: not a granular campaign directory", file=sys.stderr)
        return 2
    info = json.loads(info_path.read_text())
    manifest = info["manifest"]
    n_points, n_runs = expected_counts(info)
    grown = len(info.get("history", [])) > 1
    rep = Report()
    rd = Readers(root)
    print(f"campaign {info['name']!r} in {root}: {n_points} points, {n_runs} runs" + (" (grown)" if grown else ""))
    print(f"duckdb {duckdb.__version__}, pyarrow {ds.pa.__version__}, polars {pl.__version__}")

    print("files")
    for t in TABLES:
        d = rd.dir(t)
        visible = [p for p in d.glob("*.parquet") if not p.name.startswith(".")] if d.is_dir() else []
        rep.check(len(visible) > 0, f"{t}: {len(visible)} part file(s)")
        # granular's temporary names (.NAME.pending, .NAME.PID.tmp) never end in .parquet; a
        # hidden *.parquet would be read by the DuckDB and Polars globs.
        hidden = [p.name for p in d.glob(".*.parquet")] if d.is_dir() else []
        if hidden:
            rep.fail(f"{t}: hidden *.parquet files the globs would read: {hidden}")
    rep.check(info.get("n_runs") == n_runs, f"campaign.json n_runs = {info.get('n_runs')} (manifest implies {n_runs})")
    if rep.failures:
        return finish(rep)

    print("row counts")
    counts = {t: {lib: rd.count(lib, t) for lib in LIBS} for t in TABLES}
    for t in TABLES:
        same = len(set(counts[t].values())) == 1
        rep.check(same, f"{t}: " + ", ".join(f"{lib} {n}" for lib, n in counts[t].items()))

    status = dict(rd.duck("runs").aggregate("status, count(*)", "status").fetchall())
    n_done, n_failed = status.get("done", 0), status.get("failed", 0)
    rep.check(counts["runs"]["duckdb"] == n_runs, f"runs: {counts['runs']['duckdb']} rows, expected {n_runs}")
    rep.check(
        n_done + n_failed == n_runs,
        f"runs: {n_done} done + {n_failed} failed = {n_done + n_failed}, expected {n_runs}",
    )
    if n_failed and not args.allow_failed:
        rep.fail(f"runs: {n_failed} failed run(s) (use --allow-failed to accept)")
    distinct_runs = rd.duck("runs").aggregate("count(DISTINCT run_id)").fetchall()[0][0]
    rep.check(distinct_runs == counts["runs"]["duckdb"], f"runs: run_id unique ({distinct_runs} distinct)")
    rep.check(counts["points"]["duckdb"] == n_points, f"points: {counts['points']['duckdb']} rows, expected {n_points}")
    rep.check(
        counts["registered_runs"]["duckdb"] == n_runs,
        f"registered_runs: {counts['registered_runs']['duckdb']} rows, expected {n_runs}",
    )
    in_manifest = {p for (p,) in rd.duck("points").filter("in_manifest").project("point_id").fetchall()}
    reg_points = {
        p for (p,) in rd.duck("registered_runs").filter("in_manifest").project("point_id").distinct().fetchall()
    }
    rep.check(
        reg_points == in_manifest,
        f"registered_runs: runs in the latest manifest belong to exactly its {len(in_manifest)} points",
    )
    cols = set(rd.duck("points").columns)
    for key in manifest.get("sweep") or {}:
        col = key.replace(".", "_")
        rep.check(col in cols, f"sweep column {col!r} in points")

    # Species and output times per point, from the table itself.
    per_point = dict(
        (p, (s, n_t))
        for p, s, n_t in rd.duck("dsmc_species")
        .aggregate("point_id, count(DISTINCT species), count(DISTINCT t)", "point_id")
        .fetchall()
    )
    done_per_point = dict(rd.duck("runs").filter("status = 'done'").aggregate("point_id, count(*)", "point_id").fetchall())
    exp_species = sum(done_per_point.get(p, 0) * s * n_t for p, (s, n_t) in per_point.items())
    shapes = sorted(set(per_point.values()))
    desc = ", ".join(f"{s} species x {n_t} times" for s, n_t in shapes)
    rep.check(
        set(per_point) == set(done_per_point),
        f"dsmc_species: rows for exactly the points with done runs ({len(per_point)} points)",
    )
    for lib in LIBS:
        rep.check(
            counts["dsmc_species"][lib] == exp_species,
            f"dsmc_species via {lib}: {counts['dsmc_species'][lib]} rows = {n_done} done runs x ({desc})",
        )
    distinct = rd.duck("dsmc_species").aggregate("count(DISTINCT (run_id, t, species))").fetchall()[0][0]
    rep.check(distinct == counts["dsmc_species"]["duckdb"], f"dsmc_species: no (run_id, t, species) doubled ({distinct} distinct)")
    # Summaries are of the latest manifest's points only.
    exp_summary = sum(s * n_t for p, (s, n_t) in per_point.items() if p in in_manifest)
    for lib in LIBS:
        rep.check(
            counts["dsmc_species_summary"][lib] == exp_summary,
            f"dsmc_species_summary via {lib}: {counts['dsmc_species_summary'][lib]} rows = points x species x times = {exp_summary}",
        )

    print("metadata")
    want = manifest
    for t in TABLES:
        for lib in LIBS:
            found = rd.manifests(lib, t)
            missing = [f for f, v in found.items() if v is None]
            same = lambda m: all(m.get(k) == want.get(k) for k in ("name", "model", "seed"))
            wrong = [
                f
                for f, v in found.items()
                if v is not None and (json.loads(v) != want if not grown else not same(json.loads(v)))
            ]
            ok = bool(found) and not missing and not wrong
            detail = f"{len(found)} file(s)"
            if missing:
                detail += f", missing in {missing}"
            if wrong:
                detail += f", differs from campaign.json in {wrong}"
            rep.check(ok, f"{t} via {lib}: granular.manifest present and equal to campaign.json ({detail})")
    md = rd.arrow("runs").schema.metadata or {}
    rep.check(b"granular.manifest" in md, "pyarrow dataset schema.metadata has b'granular.manifest'")

    print("values")
    params = {
        p: json.loads(s)
        for p, s in rd.duck("points").project("point_id, params").fetchall()
    }
    for lib in LIBS:
        rows = rd.t0_rows(lib)
        worst, n_checked, bad = 0.0, 0, []
        for point, species, count, temp in rows:
            if count < 2:
                continue
            exp = initial_temperatures(params[point])
            t0 = exp[species] if isinstance(exp, dict) else exp
            dev = abs(temp - t0) / abs(t0)
            worst = max(worst, dev)
            n_checked += 1
            if not dev <= T0_RTOL:
                bad.append((point, species, temp, t0))
        rep.check(
            n_checked > 0 and not bad,
            f"t = 0 temperature via {lib}: {n_checked} rows (count >= 2) at their initial temperature, "
            f"max rel. dev. {worst:.1e}" + (f"; off: {bad[:3]}" if bad else ""),
        )

    # One (point, t, species): the first point of the latest manifest all of whose runs it asks
    # for, t_end, species 1 (its replicas read back through each library).
    current_runs = dict(
        rd.duck("registered_runs").filter("in_manifest").aggregate("point_id, count(*)", "point_id").fetchall()
    )
    whole = [p for p in per_point if p in in_manifest and current_runs.get(p) == done_per_point.get(p)]
    rep.check(bool(whole), "a point of the latest manifest with every run in it")
    point, species = min(whole or per_point), 1
    t_end = rd.duck("dsmc_species").filter(f"point_id = {point}").aggregate("max(t)").fetchall()[0][0]
    for lib in LIBS:
        temps = rd.replica_temperatures(lib, point, t_end, species)
        means = rd.summary_mean(lib, point, t_end, species)
        mean = math.fsum(temps) / len(temps) if temps else float("nan")
        ok = len(means) == 1 and len(temps) == done_per_point.get(point, 0) and rel_close(means[0], mean, MEAN_RTOL)
        rep.check(
            ok,
            f"summary via {lib}: temperature_mean(point {point}, t {t_end:g}, species {species}) = "
            f"{means[0] if means else None!r}, mean of {len(temps)} replicas = {mean!r}",
        )
    # Every (point, t, species), in DuckDB.
    row = rd.con.execute(
        f"""
        WITH m AS (
            SELECT point_id, t, species, avg(temperature) AS mean, count(*) AS n
            FROM read_parquet('{rd.glob("dsmc_species")}', hive_partitioning = true) x
            SEMI JOIN read_parquet('{rd.glob("registered_runs")}', hive_partitioning = true) r
            ON r.run_id = x.run_id AND r.in_manifest
            GROUP BY ALL
        )
        SELECT count(*),
               max(abs(s.temperature_mean - m.mean) / greatest(abs(m.mean), 1e-300)),
               count(*) FILTER (WHERE s.n_replicas <> m.n)
        FROM m JOIN read_parquet('{rd.glob("dsmc_species_summary")}', hive_partitioning = true) s
        USING (point_id, t, species)
        """
    ).fetchall()[0]
    n_joined, worst, n_bad_n = row
    rep.check(
        n_joined == exp_summary and worst is not None and worst <= MEAN_RTOL and n_bad_n == 0,
        f"summary via duckdb: all {n_joined} (point, t, species) means match, max rel. dev. {worst:.1e}, "
        f"{n_bad_n} with a wrong n_replicas",
    )
    return finish(rep)


def finish(rep: Report) -> int:
    if rep.failures:
        print(f"FAILED: {len(rep.failures)} check(s)")
        for f in rep.failures:
            print(f"  - {f}")
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
