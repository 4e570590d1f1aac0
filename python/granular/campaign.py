"""A campaign directory read from Python: its tables as Polars LazyFrames, pyarrow datasets and
DuckDB views, every one with the point's swept parameters joined, and its status, report and
verification through the `granular` binary.

Reading follows the campaign directory's rules (docs/tables.md, docs/operations.md): the only
symbolic links followed are the generation links `tables/<table>` -> `.gen/<table>.<n>`; a link
anywhere else, or a table file that is a link, is refused, never followed out of the campaign.
Every read first makes the binary's quick check (`granular tables DIR --json`): a damaged
campaign raises `CampaignDamaged`, naming `granular resume DIR`, and returns no rows.
"""

from __future__ import annotations

import html
import json
import os
import re
import stat
from pathlib import Path
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Union

from . import _binary
from ._progress import run_with_progress
from .errors import CampaignError, GranularError, Interrupted, RunsFailed, TableNotWritten

if TYPE_CHECKING:  # pragma: no cover
    import duckdb
    import polars as pl
    import pyarrow.dataset

PathLike = Union[str, "os.PathLike[str]"]

#: Columns of `points` that are not sweep columns.
POINT_COLUMNS_NOT_SWEPT = ("point_id", "params", "in_manifest")

_TABLE_NAME = re.compile(r"[a-z][a-z0-9_]*")


class Campaign:
    """A campaign directory (`granular.open(DIR)`, or what `granular.run` returns).

    Reading never writes into the directory. Tables are read as they are when `table()`,
    `arrow()` or `duckdb()` is called: rows committed later need another call.
    """

    def __init__(self, path: PathLike) -> None:
        # Absolute: the frames and views open their files when queried, whatever the working
        # directory is then (a notebook's %cd).
        p = Path(os.path.abspath(os.fspath(path)))
        cj = p / "campaign.json"
        if not cj.exists():
            why = "does not exist" if not p.exists() else "holds no campaign.json"
            raise CampaignError(
                f"{p}: not a campaign directory ({why}); give the --out directory of a "
                "`granular run` (or `granular.run(..., out=DIR)`)",
                exit_code=3,
            )
        if cj.is_symlink():
            raise CampaignError(f"{cj}: a symbolic link; refused (a campaign's files are never links)", exit_code=3)
        self.path = p
        self._info: Optional[Dict[str, Any]] = None

    # --- what the campaign is -------------------------------------------------------------

    @property
    def manifest(self) -> Dict[str, Any]:
        """The campaign's latest manifest (`DIR/manifest.json`), as a dict."""
        f = self.path / "manifest.json"
        if f.is_symlink():
            raise CampaignError(f"{f}: a symbolic link; refused", exit_code=3)
        try:
            return json.loads(f.read_text())
        except (OSError, ValueError) as e:
            raise CampaignError(
                f"{f}: cannot be read ({e}); `granular resume {self.path}` heals a campaign "
                "whose files are damaged",
                exit_code=3,
            ) from None

    @property
    def name(self) -> str:
        return str(self.manifest.get("name", ""))

    @property
    def model(self) -> str:
        return str(self.manifest.get("model", ""))

    @property
    def description(self) -> str:
        return str(self.manifest.get("description", ""))

    def status(self) -> Dict[str, Any]:
        """`granular status DIR --json`: done / failed / running / pending runs, in all and
        per point (makes the quick check: a damaged campaign raises `CampaignDamaged`)."""
        return json.loads(_binary.run(["status", self.path, "--json"]).stdout)

    def verify(self, quick: bool = False) -> str:
        """`granular verify DIR` (`quick`: sizes only): every table file against the ledger.
        Returns the binary's verdict; damage raises `CampaignDamaged` naming every problem."""
        args = ["verify", self.path] + (["--quick"] if quick else [])
        return _binary.run(args).stdout.strip()

    def tables(self) -> "pl.DataFrame":
        """The campaign's tables: name, whether written, rows, files and a one-line
        description (`granular tables DIR --json`)."""
        import polars as pl

        info = self._tables_info()
        return pl.DataFrame(
            {
                "name": [t["name"] for t in info["tables"]],
                "written": [bool(t.get("written")) for t in info["tables"]],
                "rows": [t.get("rows") for t in info["tables"]],
                "files": [t.get("files") for t in info["tables"]],
                "description": [t.get("description", "") for t in info["tables"]],
            },
            schema={"name": pl.String, "written": pl.Boolean, "rows": pl.Int64, "files": pl.Int64, "description": pl.String},
        )

    # --- reading ------------------------------------------------------------------------------

    @property
    def points(self) -> "pl.DataFrame":
        """One row per point the campaign has ever had: `point_id`, the sweep columns (one per
        sweep key of the latest manifest), `params` (the point's complete parameters as JSON)
        and `in_manifest`."""
        import polars as pl

        self._tables_info(refresh=True)
        return pl.read_parquet(self._files("points"), glob=False, hive_partitioning=False)

    @property
    def sweep_columns(self) -> List[str]:
        """The names of the sweep columns (the latest manifest's sweep keys, `.` as `_`)."""
        self._tables_info(refresh=True)
        return self._sweep_of_points()

    def table(self, name: str) -> "pl.LazyFrame":
        """The table `name` as a Polars LazyFrame, with the point's sweep columns joined right
        after `point_id` (those the table does not carry already: summaries carry them, raw
        and theory tables get them here), so `c.table("dsmc_species").filter(pl.col("method")
        == "bird")` needs no join. The rows are exactly those of the table's Parquet files."""
        return self._table(name, refresh=True)

    def arrow(self, name: str) -> "pyarrow.dataset.Dataset":
        """The table `name` as a pyarrow dataset, the sweep columns joined as in `table()`
        (read into memory; for tables larger than memory use `table()` or `duckdb()`)."""
        import pyarrow.dataset as ds

        return ds.dataset(self._table(name, refresh=True).collect().to_arrow())

    def duckdb(self, connection: "Optional[duckdb.DuckDBPyConnection]" = None) -> "duckdb.DuckDBPyConnection":
        """A DuckDB connection (a new in-memory one, or `connection`) with one view per written
        table, named like the table, the sweep columns joined as in `table()`:
        `c.duckdb().sql("select * from dsmc_species_summary where species_list_1_mass = 8")`."""
        import duckdb

        con = connection if connection is not None else duckdb.connect()
        info = self._tables_info(refresh=True)
        sweep = self._sweep_of_points()
        points_files = self._files("points")
        for t in info["tables"]:
            if not t.get("written"):
                continue
            name = t["name"]
            files = self._files(name)
            cols = self._schema_names(files)
            add = self._added(name, cols, sweep)
            select = [f"t.{_ident(c)}" for c in cols]
            if add:
                i = cols.index("point_id") + 1
                select = select[:i] + [f"p.{_ident(c)}" for c in add] + select[i:]
                src = (
                    f"{_parquet_sql(files)} AS t LEFT JOIN (SELECT point_id, "
                    + ", ".join(_ident(c) for c in add)
                    + f" FROM {_parquet_sql(points_files)}) AS p ON t.point_id = p.point_id"
                )
            else:
                src = f"{_parquet_sql(files)} AS t"
            con.execute(f"CREATE OR REPLACE VIEW {_ident(name)} AS SELECT {', '.join(select)} FROM {src}")
        return con

    # --- commands -----------------------------------------------------------------------------

    def report(self, out: Optional[PathLike] = None) -> Path:
        """Write the HTML report (`granular report DIR`, default `DIR/report.html`) and return
        its path."""
        target = Path(os.fspath(out)) if out is not None else self.path / "report.html"
        _binary.run(["report", self.path, "--out", target])
        return target

    def plot(self, out: Optional[PathLike] = None) -> List[Path]:
        """Draw the figures (`granular plot DIR`, default into `DIR/figures`); returns the PNG
        files."""
        d = Path(os.fspath(out)) if out is not None else self.path / "figures"
        _binary.run(["plot", self.path] + (["--out", d] if out is not None else []))
        return sorted(d.glob("*.png"))

    def resume(self, *, threads: Optional[int] = None, progress: Optional[bool] = None, check: bool = True) -> "Campaign":
        """Continue the campaign (`granular resume DIR`) with its progress shown; see
        `granular.run` for `threads`, `progress` and `check`."""
        return execute(["resume", self.path], self.path, threads=threads, progress=progress, check=check, label=self._label())

    # --- display ------------------------------------------------------------------------------

    def _label(self) -> str:
        # A damaged manifest.json (which `resume` heals) must not stop `resume` or `repr`.
        try:
            return self.name or str(self.path)
        except GranularError:
            return str(self.path)

    def __repr__(self) -> str:
        try:
            return f"granular.Campaign({str(self.path)!r}, name={self.name!r}, model={self.model!r})"
        except GranularError:
            return f"granular.Campaign({str(self.path)!r})"

    def _repr_html_(self) -> str:
        esc = html.escape
        try:
            m = self.manifest
            s = self.status()
        except GranularError as e:
            return f"<div><b>granular campaign</b> <code>{esc(str(self.path))}</code>: <span style='color:#b00'>{esc(e.message)}</span></div>"
        cur = s.get("current", s)
        asked = int(s.get("current_runs", s.get("runs", 0)))
        done, failed = int(cur.get("done", 0)), int(cur.get("failed", 0))
        running, pending = int(cur.get("running", 0)), int(cur.get("pending", 0))
        frac = (done + failed) / asked if asked else 1.0
        state = "complete" if done + failed == asked else ("running" if running or s.get("live_shards") else "unfinished")
        rows = []
        for p in s.get("points", [])[:20]:
            n = sum(int(p.get(k, 0)) for k in ("done", "failed", "running", "pending"))
            rows.append(
                f"<tr><td>{int(p['point_id'])}</td><td><code>{esc(str(p.get('point', '')))}</code></td>"
                f"<td>{int(p.get('done', 0))}/{n}</td><td>{int(p.get('failed', 0)) or ''}</td></tr>"
            )
        more = len(s.get("points", [])) - 20
        desc = f"<div>{esc(str(m.get('description', '')))}</div>" if m.get("description") else ""
        fail = f", <b style='color:#b00'>{failed} failed</b>" if failed else ""
        return (
            f"<div><b>{esc(str(m.get('name', '')))}</b> ({esc(str(m.get('model', '')))}, seed {esc(str(m.get('seed', '')))}) "
            f"<code>{esc(str(self.path))}</code>{desc}"
            f"<div><progress value='{frac:.4f}' max='1' style='width:40%'></progress> "
            f"{done + failed}/{asked} runs finished ({state}): {done} done{fail}, {running} running, {pending} pending</div>"
            "<table><tr><th>point</th><th>parameters</th><th>done</th><th>failed</th></tr>"
            + "".join(rows)
            + "</table>"
            + (f"<div>... and {more} more points (<code>status()</code>)</div>" if more > 0 else "")
            + "</div>"
        )

    # --- internals ----------------------------------------------------------------------------

    def _tables_info(self, refresh: bool = False) -> Dict[str, Any]:
        if self._info is None or refresh:
            self._info = json.loads(_binary.run(["tables", self.path, "--json"]).stdout)
        return self._info

    def _entry(self, name: str) -> Dict[str, Any]:
        if not isinstance(name, str) or not _TABLE_NAME.fullmatch(name):
            raise ValueError(f"{name!r} is not a table name (lower-case letters, digits and _)")
        info = self._tables_info()
        for t in info["tables"]:
            if t["name"] == name:
                if t.get("error"):
                    raise CampaignError(f"{self.path}: table {name}: {t['error']}", exit_code=3)
                if not t.get("written"):
                    raise TableNotWritten(
                        f"{self.path}: table {name} is not written yet"
                        + (
                            " (summaries are written once every run the manifest asks for has finished: "
                            f"`granular resume {self.path}` or `Campaign.resume()`)"
                            if name.endswith("_summary")
                            else ""
                        )
                    )
                return t
        names = ", ".join(t["name"] for t in info["tables"])
        raise TableNotWritten(f"{self.path}: no table {name!r} in this campaign; its tables: {names}")

    def _table_dir(self, name: str) -> Path:
        """The directory of `name`'s files: the generation its link names, checked to be
        `tables/.gen/<name>.<n>` with no link on the way, or a plain directory."""
        tables = self.path / "tables"
        if tables.is_symlink() or not tables.is_dir():
            raise CampaignError(f"{tables}: not a directory (or a symbolic link); refused", exit_code=3)
        d = tables / name
        if d.is_symlink():
            target = os.readlink(d)
            if _generation_of(name, target) is None:
                raise CampaignError(f"{d}: a link to {target!r}, not to its generation .gen/{name}.<n>; not followed", exit_code=3)
            gen = tables / ".gen"
            if gen.is_symlink():
                raise CampaignError(f"{gen}: a symbolic link; not followed", exit_code=3)
            d = gen / target[len(".gen/") :]
            if d.is_symlink():
                raise CampaignError(f"{d}: a symbolic link; not followed", exit_code=3)
        if not d.is_dir():
            raise TableNotWritten(f"{self.path}: table {name} is not written yet")
        return d

    def _generation(self, name: str) -> Optional[int]:
        """The number of the generation `tables/<name>` links to now (None: not a link)."""
        try:
            return _generation_of(name, os.readlink(self.path / "tables" / name))
        except OSError:
            return None

    def _files(self, name: str) -> List[str]:
        """The files of `name`'s current generation. A generation's files never change, and
        `granular compact` removes one only after publishing the second one after it: if the
        link moved on that far while the directory was listed, the listing may lack files
        removed meanwhile, so it is made again. A file removed after the listing fails its
        read (never a silently shorter table)."""
        self._entry(name)
        for _ in range(3):
            before = self._generation(name)
            try:
                files = self._list_generation(name)
            except FileNotFoundError:
                if self._generation(name) == before:
                    raise
                continue  # its generation went while it was listed
            after = self._generation(name)
            if before is None or after is None or after < before + 2:
                return files
        raise CampaignError(
            f"{self.path}: table {name} changed generation twice while it was listed, three times "
            "(compactions running one after another); try again"
        )

    def _list_generation(self, name: str) -> List[str]:
        d = self._table_dir(name)
        files = []
        for e in sorted(os.scandir(d), key=lambda e: e.name):
            if e.name.startswith(".") or not e.name.endswith(".parquet"):
                continue
            st = os.lstat(e.path)
            if not stat.S_ISREG(st.st_mode):
                raise CampaignError(f"{e.path}: not a regular file (a link?); not followed", exit_code=3)
            files.append(e.path)
        if not files:
            raise TableNotWritten(f"{self.path}: table {name} has no files yet")
        return files

    def _sweep_of_points(self) -> List[str]:
        names = _column_names(self._files("points")[0])
        return [c for c in names if c not in POINT_COLUMNS_NOT_SWEPT]

    @staticmethod
    def _schema_names(files: List[str]) -> List[str]:
        return _column_names(files[0])

    @staticmethod
    def _added(name: str, cols: List[str], sweep: List[str]) -> List[str]:
        if name == "points" or "point_id" not in cols:
            return []
        return [c for c in sweep if c not in cols]

    def _table(self, name: str, refresh: bool) -> "pl.LazyFrame":
        import polars as pl

        self._tables_info(refresh=refresh)
        files = self._files(name)
        lf = pl.scan_parquet(files, glob=False, hive_partitioning=False)
        cols = self._schema_names(files)
        add = self._added(name, cols, self._sweep_of_points())
        if not add:
            return lf
        pts = pl.scan_parquet(self._files("points"), glob=False, hive_partitioning=False).select(["point_id", *add])
        kw: Dict[str, Any] = {}
        try:
            import inspect

            if "maintain_order" in inspect.signature(pl.LazyFrame.join).parameters:
                kw["maintain_order"] = "left"
        except (TypeError, ValueError):  # pragma: no cover
            pass
        i = cols.index("point_id") + 1
        return lf.join(pts, on="point_id", how="left", **kw).select(cols[:i] + add + cols[i:])


def _generation_of(table: str, target: str) -> Optional[int]:
    """The generation a link of `table` names: its target must read exactly
    `.gen/<table>.<digits>` (as `store::layout::generation_of` decides); None otherwise."""
    m = re.fullmatch(r"\.gen/" + re.escape(table) + r"\.([0-9]+)", target)
    return int(m.group(1)) if m else None


def _ident(name: str) -> str:
    """A DuckDB identifier, quoted."""
    return '"' + name.replace('"', '""') + '"'


def _column_names(file: str) -> List[str]:
    """The columns of one Parquet file, from its footer (the path is a path, not a pattern)."""
    import pyarrow.parquet as pq

    return list(pq.read_schema(file).names)


def _glob_escaped(path: str) -> str:
    """`path` as a DuckDB glob that matches only itself: `*`, `?` and `[` each as a one-character
    class (a campaign in `runs/x*` must not read `runs/xy`)."""
    return "".join("[" + ch + "]" if ch in "*?[" else ch for ch in path)


def _parquet_sql(files: List[str]) -> str:
    """`read_parquet([...])` of exactly these files: each path glob-escaped and a quoted SQL
    string literal, and no hive partitioning (a campaign under `runs/method=foo/` must not
    have its `method` column overwritten by the directory's name)."""
    lits = ", ".join("'" + _glob_escaped(f).replace("'", "''") + "'" for f in files)
    return f"read_parquet([{lits}], hive_partitioning = false)"


def execute(
    args: List[Any], out: Path, *, threads: Optional[int], progress: Optional[bool], check: bool, label: str
) -> Campaign:
    """Run `granular run ...` or `granular resume ...` (`args`) for the campaign in `out` with
    its progress shown, and return the campaign; each exit code but 0 (and 1 with
    `check=False`) raises its exception."""
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 0):
        raise ValueError(f"threads: expected a whole number >= 0 (0 = all cores), got {threads!r}")
    threads_args = [] if threads is None else ["--threads", str(threads)]
    cmd = _binary.command([*args, *threads_args, "--progress-json"])
    code, _stdout, stderr = run_with_progress(cmd, progress=progress, label=label)
    if code not in (0, 1, 130):
        raise _binary.error_of(code, stderr, cmd)
    campaign = Campaign(out)
    text = _binary._strip_log_prefixes(stderr).strip()
    said = text + "\n" if text else ""
    if code == 1 and check:
        raise RunsFailed(
            said + f"{campaign.path}: some runs failed; their reasons are in the runs table "
            "(`status = 'failed'`); pass check=False to get the campaign without this exception",
            campaign,
            command=cmd,
        )
    if code == 130:
        raise Interrupted(
            said + f"{campaign.path}: stopped after checkpointing; `Campaign.resume()` or "
            f"`granular resume {campaign.path}` continues it",
            campaign,
            command=cmd,
        )
    return campaign
