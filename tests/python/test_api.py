"""The Python API against the files: every table read through `Campaign.table`, `.arrow` and
`.duckdb` holds exactly the rows DuckDB reads from the table's Parquet files, plus the point's
sweep columns; the refusals raise exceptions that say what to do. The campaign is tiny and
deterministic (fixed seed), so no test here is statistical."""

import json
import os
import shutil
import subprocess

import duckdb
import polars as pl
import pytest

import granular
from granular import CampaignDamaged, CampaignError, ManifestError, TableNotWritten


def direct(campaign_dir, name):
    """The table as DuckDB reads its files directly, through the table's link."""
    glob = str(campaign_dir / "tables" / name / "*.parquet").replace("'", "''")
    return duckdb.sql(f"select * from read_parquet('{glob}')").pl()


def canonical(df):
    """Rows in one order (every column a sort key), for comparing row sets."""
    return df.sort(df.columns, nulls_last=True)


def test_every_table_has_the_files_rows_and_the_sweep_columns(finished):
    c = granular.open(finished)
    listing = c.tables()
    written = listing.filter(pl.col("written"))["name"].to_list()
    # The tiny dsmc campaign has these (a table missing from the listing would not be read).
    for t in ["runs", "points", "registered_runs", "dsmc_species", "dsmc_species_summary", "dsmc_theory"]:
        assert t in written, (t, written)
    assert all(d for d in listing["description"]), listing
    points = c.points
    assert c.sweep_columns == ["method"]
    method_of = dict(zip(points["point_id"].to_list(), points["method"].to_list()))
    views = c.duckdb()
    for name in written:
        got = c.table(name).collect()
        files = direct(finished, name)
        assert got.height == files.height > 0, name
        assert listing.filter(pl.col("name") == name)["rows"][0] == files.height, name
        own = files.columns
        added = [col for col in got.columns if col not in own]
        if name != "points" and "point_id" in own:
            # Every table with a point gets the sweep columns, right after point_id.
            assert set(added) | set(own) >= {"method"}, name
            i = got.columns.index("point_id")
            assert got.columns[i + 1 : i + 1 + len(added)] == added, (name, got.columns)
            assert [method_of[p] for p in got["point_id"]] == got["method"].to_list(), name
        else:
            assert added == [], name
        # Exactly the files' rows, no row lost, doubled or changed.
        assert canonical(got.select(own)).equals(canonical(files), null_equal=True), name
        # The same through pyarrow and through the DuckDB view.
        arrow = pl.from_arrow(c.arrow(name).to_table())
        assert arrow.columns == got.columns, name
        assert canonical(arrow).equals(canonical(got), null_equal=True), name
        view = views.sql(f'select * from "{name}"').pl()
        assert view.columns == got.columns, name
        assert canonical(view).equals(canonical(got), null_equal=True), name


def test_a_raw_table_is_queried_by_its_swept_parameter(finished):
    c = granular.open(finished)
    bird = c.table("dsmc_species").filter(pl.col("method") == "bird").collect()
    runs = c.table("runs").filter(pl.col("method") == "bird").collect()
    assert runs.height == 2  # 2 replicas of the bird point
    assert set(bird["run_id"].unique().to_list()) == set(runs["run_id"].to_list())
    # The view, filtered by the swept parameter in SQL, has the frame's rows.
    n = c.duckdb().sql("select count(*) from dsmc_species where method = 'bird'").fetchall()[0][0]
    assert n == bird.height > 0
    summary = c.table("dsmc_species_summary").filter(pl.col("method") == "bird").collect()
    assert summary["n_replicas"].unique().to_list() == [2]


def test_the_acceptance_line(finished):
    # The acceptance: `c.table('dsmc_species_summary').collect().shape`.
    shape = granular.open(finished).table("dsmc_species_summary").collect().shape
    assert shape[0] == direct(finished, "dsmc_species_summary").height
    assert shape[1] == len(direct(finished, "dsmc_species_summary").columns)  # summaries carry the sweep


def test_an_invalid_manifest_raises_every_error_with_its_path_and_writes_nothing(tmp_path, tiny_manifest):
    m = tiny_manifest
    m["params"]["initial_temperature"] = -1
    m["params"]["observables"] = ["temperature", "bogus"]
    m["sweep"] = {"method": ["low_rank", "nope"]}
    out = tmp_path / "never"
    with pytest.raises(ManifestError) as e:
        granular.run(m, out=out, progress=False)
    # All three at once, each at its JSON path.
    paths = {p.path for p in e.value.errors}
    assert paths == {"/params/initial_temperature", "/params/observables/1", "/sweep/method/1"}, e.value.errors
    assert any("bogus" in p.message for p in e.value.errors), e.value.errors
    assert e.value.file == "<manifest dict>"
    assert "granular-manifest-" not in str(e.value)  # the temporary file is not named
    assert not out.exists()
    with pytest.raises(ManifestError) as v:
        granular.validate(m)
    assert {p.path for p in v.value.errors} == paths


def test_validate_a_path_and_a_dict(tmp_path, tiny_manifest):
    v = granular.validate(tiny_manifest)
    assert v["campaign"]["runs"] == 4 and v["campaign"]["points"] == 2
    f = tmp_path / "m.json"
    f.write_text(json.dumps(tiny_manifest))
    assert granular.validate(f)["campaign"]["name"] == "py-tiny"
    with pytest.raises(ManifestError) as e:
        granular.validate(tmp_path / "missing.json")
    assert e.value.errors[0].path == "/"


def test_a_damaged_campaign_raises_naming_resume_and_resume_heals_it(finished, fresh_copy):
    c = granular.open(fresh_copy)
    before = canonical(c.table("dsmc_species").collect())
    part = sorted((fresh_copy / "tables" / "dsmc_species").glob("*.parquet"))[0]
    with open(part, "r+b") as f:
        f.truncate(100)
    for read in (lambda: c.table("dsmc_species"), lambda: c.table("dsmc_species_summary"), c.duckdb, c.status):
        with pytest.raises(CampaignDamaged) as e:
            read()
        assert f"granular resume {fresh_copy}" in str(e.value)
        assert e.value.exit_code == 3
    # Healing runs the damaged runs again, bit-identically.
    c.resume(progress=False)
    assert canonical(c.table("dsmc_species").collect()).equals(before)


def test_a_link_out_of_the_campaign_is_not_followed(fresh_copy, tmp_path):
    outside = tmp_path / "outside"
    shutil.copytree(fresh_copy / "tables" / "runs", outside)
    link = fresh_copy / "tables" / "runs"
    link.unlink()
    link.symlink_to(outside)
    with pytest.raises(CampaignError):
        granular.open(fresh_copy).table("runs").collect()


def test_a_listing_two_compactions_overtook_is_made_again(fresh_copy, monkeypatch):
    """`granular compact` removes a generation once the second one after it is published, so a
    listing during which the link moved on that far may lack files: it is made again, never
    used (a listing that lost a file stands for one racing the removal)."""
    c = granular.open(fresh_copy)
    expect = canonical(c.table("runs").collect())
    tables = fresh_copy / "tables"
    digits = os.readlink(tables / "runs").rsplit(".", 1)[1]  # .gen/runs.00000000
    n = int(digits)
    real = type(c)._list_generation
    overtaken = []

    def list_while_two_compactions_publish(self, name):
        files = real(self, name)
        if name == "runs" and not overtaken:
            overtaken.append(files)
            for g in (n + 1, n + 2):
                gen_dir = f"runs.{g:0{len(digits)}}"
                shutil.copytree(tables / ".gen" / f"runs.{digits}", tables / ".gen" / gen_dir)
                tmp = tables / ".runs.new"
                tmp.symlink_to(f".gen/{gen_dir}")
                os.replace(tmp, tables / "runs")
            return files[:-1]
        return files

    monkeypatch.setattr(type(c), "_list_generation", list_while_two_compactions_publish)
    got = canonical(c.table("runs").collect())
    assert len(overtaken) == 1 and len(overtaken[0]) >= 1
    assert got.equals(expect)


def test_not_a_campaign_and_unknown_tables(finished, tmp_path):
    with pytest.raises(CampaignError) as e:
        granular.open(tmp_path / "nothing")
    assert "not a campaign directory" in str(e.value)
    with pytest.raises(TableNotWritten) as e:
        granular.open(finished).table("dsmc_nope")
    assert "dsmc_species" in str(e.value)  # the tables there are named
    with pytest.raises(ValueError):
        granular.open(finished).table("../runs")


def test_an_unfinished_campaign_has_no_summary_yet(tmp_path, tiny_manifest):
    f = tmp_path / "m.json"
    f.write_text(json.dumps(tiny_manifest))
    out = tmp_path / "half"
    # Shard 1 of 2 runs half the runs: the campaign is unfinished.
    subprocess.run([granular.binary(), "run", str(f), "--out", str(out), "--shard", "1/2", "--quiet"], check=True)
    c = granular.open(out)
    assert c.table("runs").collect().height == 2
    with pytest.raises(TableNotWritten) as e:
        c.table("dsmc_species_summary")
    assert "granular resume" in str(e.value)
    assert "2/4 runs finished" in c._repr_html_()
    c.resume(progress=False)
    assert c.table("dsmc_species_summary").collect().height > 0
    assert "4/4 runs finished (complete)" in c._repr_html_()


def test_run_shows_progress_and_returns_the_campaign(tmp_path, tiny_manifest, capsys):
    c = granular.run(tiny_manifest, out=tmp_path / "p", threads=1, progress=True)
    err = capsys.readouterr().err
    assert "4/4 runs" in err and "100%" in err, err
    assert c.name == "py-tiny" and c.model == "dsmc"
    # The same manifest again adds nothing and returns the same campaign.
    again = granular.run(tiny_manifest, out=tmp_path / "p", progress=False)
    assert again.table("runs").collect().height == 4


def test_report_and_repr(finished, tmp_path):
    c = granular.open(finished)
    page = c.report(out=tmp_path / "r.html")
    assert page.read_text().lstrip().lower().startswith("<!doctype html")
    h = c._repr_html_()
    assert "py-tiny" in h and "4/4 runs finished (complete)" in h
    assert "py-tiny" in repr(c)


def test_the_binary_is_the_one_installed_with_the_package():
    b = granular.binary()
    out = subprocess.run([b, "--version"], capture_output=True, text=True, check=True).stdout
    assert out.startswith("granular ")
    if "GRANULAR_BIN" not in os.environ:
        # The wheel put it beside the interpreter of this environment, not a system one.
        import sysconfig

        assert os.path.dirname(b) == sysconfig.get_path("scripts")


def test_ctrl_c_checkpoints_raises_interrupted_and_resume_finishes(tmp_path, tiny_manifest):
    # Runs long enough (N1 = 100 000 to t_end = 300: ~9 s on one thread here) that the
    # interrupt, raised in this process 1.5 s after the start as Ctrl-C or a notebook's
    # interrupt button would, comes while the binary runs; it must be passed on, checkpointed
    # and reported. (N1 = 30 000, "several seconds" when written, now takes 2.2 s: too
    # little margin as the engine gets faster.)
    import signal
    import threading

    m = tiny_manifest
    m["params"]["species"]["power_law"]["N1"] = 100000
    m["params"]["t_end"] = 300.0
    m["params"]["output_times"] = {"log": {"from": 0.01, "to": 300.0, "per_decade": 2}}
    out = tmp_path / "int"
    # Python turns SIGINT into KeyboardInterrupt only if it was not ignored when the
    # interpreter started; a shell without job control starts background commands (`cmd &`)
    # with SIGINT ignored. Install the default handler so that the test does not depend on
    # how it was launched (as a terminal's Ctrl-C or a notebook's interrupt would find it).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(1.5, lambda: signal.raise_signal(signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(granular.Interrupted) as e:
            granular.run(m, out=out, threads=1, progress=False)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert e.value.exit_code == 130
    assert f"granular resume {out}" in str(e.value)
    c = e.value.campaign
    s = c.status()
    assert s["done"] < 4, s
    c.resume(threads=2, progress=False)
    assert c.status()["done"] == 4
    assert c.table("runs").collect().height == 4


def test_progress_in_a_notebook_updates_one_html_display(tmp_path, tiny_manifest, monkeypatch):
    # A stand-in for IPython.display: the notebook mode must create one display and update
    # it in place, ending at 100 %.
    import sys
    import types

    from granular import _progress

    shown = []

    class Handle:
        def update(self, obj):
            shown.append(obj.data)

    display_mod = types.ModuleType("IPython.display")
    display_mod.HTML = type("HTML", (), {"__init__": lambda self, data: setattr(self, "data", data)})
    display_mod.display = lambda obj, display_id=False: (shown.append(obj.data), Handle())[1]
    monkeypatch.setitem(sys.modules, "IPython", types.ModuleType("IPython"))
    monkeypatch.setitem(sys.modules, "IPython.display", display_mod)
    monkeypatch.setattr(_progress, "_in_notebook", lambda: True)
    granular.run(tiny_manifest, out=tmp_path / "nb", threads=1)
    assert "starting" in shown[0]
    assert len(shown) >= 3, shown
    assert "<progress value='1.0000'" in shown[-1] and "4/4 runs finished" in shown[-1], shown[-1]


def test_verify_and_plot(finished, fresh_copy, tmp_path):
    c = granular.open(finished)
    assert "check out" in c.verify() and "check out" in c.verify(quick=True)
    pngs = c.plot(out=tmp_path / "figs")
    assert pngs and all(p.suffix == ".png" and p.stat().st_size > 0 for p in pngs)
    # A flipped byte (same size) escapes the quick check, not the full one.
    part = sorted((fresh_copy / "tables" / "runs").glob("*.parquet"))[0]
    data = bytearray(part.read_bytes())
    data[len(data) // 2] ^= 0xFF
    part.write_bytes(bytes(data))
    d = granular.open(fresh_copy)
    assert "check out" in d.verify(quick=True)
    with pytest.raises(CampaignDamaged) as e:
        d.verify()
    assert "SHA-256" in str(e.value) and f"granular resume {fresh_copy}" in str(e.value)


def long_manifest(m):
    """The tiny manifest made to run for several seconds on one thread (N1 = 100 000 to
    t_end = 300), so that an interrupt comes while runs run."""
    m["params"]["species"]["power_law"]["N1"] = 100000
    m["params"]["t_end"] = 300.0
    m["params"]["output_times"] = {"log": {"from": 0.01, "to": 300.0, "per_decade": 2}}
    return m


def test_hostile_directory_names_read_only_the_campaigns_files(finished, tmp_path, monkeypatch):
    # `method=foo` would be taken for a hive partition (overwriting the method column), and
    # `c[1]*` for a glob matching the sibling `c1x` (doubling every table's rows).
    parent = tmp_path / "method=foo"
    parent.mkdir()
    d = parent / "c[1]*"
    shutil.copytree(finished, d, symlinks=True)
    shutil.copytree(finished, parent / "c1x", symlinks=True)
    monkeypatch.chdir(parent)
    c = granular.open("c[1]*")  # relative, then the working directory changes
    monkeypatch.chdir(tmp_path)
    assert c.points.height == 2
    runs = c.table("runs").collect()
    assert runs.height == 4 and sorted(set(runs["method"])) == ["bird", "low_rank"]
    con = c.duckdb()
    assert con.sql("select count(*) from runs").fetchall()[0][0] == 4
    assert sorted(r[0] for r in con.sql("select distinct method from dsmc_species").fetchall()) == ["bird", "low_rank"]
    assert con.sql("select count(*) from dsmc_species").fetchall()[0][0] == direct(finished, "dsmc_species").height


def test_ctrl_c_while_progress_is_drawn_is_passed_on(tmp_path, tiny_manifest, monkeypatch):
    # An interrupt that lands while a progress line is being drawn (not while waiting for one)
    # must be passed on to the binary too: it checkpoints and `run` raises Interrupted.
    from granular import _progress

    calls = []
    real = _progress._Display.update

    def update(self, p):
        calls.append(p)
        if len(calls) == 3:
            raise KeyboardInterrupt
        real(self, p)

    monkeypatch.setattr(_progress._Display, "update", update)
    out = tmp_path / "int2"
    with pytest.raises(granular.Interrupted):
        granular.run(long_manifest(tiny_manifest), out=out, threads=1, progress=False)
    c = granular.open(out)
    assert c.status()["done"] < 4
    assert c.status()["live_shards"] == []


def test_the_binary_stops_when_python_dies(tmp_path, tiny_manifest):
    # A notebook kernel killed mid-run: the binary gets SIGTERM (parent death), checkpoints and
    # lets the campaign go, instead of running on holding its lock.
    import sys
    import time

    if not sys.platform.startswith("linux"):
        pytest.skip("parent-death signal: Linux only")
    f = tmp_path / "m.json"
    f.write_text(json.dumps(long_manifest(tiny_manifest)))
    out = tmp_path / "orphan"
    code = f"import granular; granular.run({str(f)!r}, out={str(out)!r}, threads=1, progress=False)"
    py = subprocess.Popen([sys.executable, "-c", code])
    deadline = time.monotonic() + 20
    while not (out / "locks").exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(1.0)
    py.kill()
    py.wait()
    c = granular.open(out)
    while c.status()["live_shards"] and time.monotonic() < deadline:
        time.sleep(0.2)
    s = c.status()
    assert s["live_shards"] == [] and s["done"] < 4, s
    c.resume(threads=2, progress=False)
    assert c.status()["done"] == 4
