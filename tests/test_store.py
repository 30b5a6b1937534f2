"""The result store and its exports (issue 12)."""
import math

import numpy as np
import pandas as pd
import pytest

from conftest import requires_mujoco
from pg_server import postgres_server, postgres_url  # noqa: F401 - fixtures
from impactval.errors import ImpactvalError
from impactval.store import EXPORT_COLUMNS, PERCENT_COLUMNS, Store, export, export_frame, frequencies_frame


def _row(key="k1", **kw):
    from impactval.store import COLUMN_TYPES

    row = {c: (math.nan if t == "float" else "" if t == "text" else 0) for c, t in COLUMN_TYPES.items()}
    row.update(job_key=key, run_id="r", scene="plate_steel", engine="mujoco", status="ok", dt=1e-6,
               err_f_m=1.2345678901234567e-4, t_m=6.893400589390127e-05, n_steps=69,
               structure_frequencies="[1.5, 2.5]", continuum_frequencies="[1.0, 2.0]")
    row.update(kw)
    return row


def test_rows_round_trip_exactly_nan_included(tmp_path):
    db = Store(tmp_path / "s.sqlite")
    db.begin_run("r", "test", tmp_path, {"mujoco": "4.0.0"}, "refhash")
    got = db.put(_row(), run_id="r", position=0, reused=False)
    assert got["err_f_m"] == 1.2345678901234567e-4 and got["t_m"] == 6.893400589390127e-05     # bit for bit
    assert math.isnan(got["err_t_m"]) and got["n_steps"] == 69
    # the key is stored once: a second put without force keeps the first row, with force replaces it
    assert db.put(_row(err_f_m=9.0), run_id="r", position=0, reused=False)["err_f_m"] == 1.2345678901234567e-4
    assert db.put(_row(err_f_m=9.0), run_id="r", position=0, reused=False, force=True)["err_f_m"] == 9.0
    assert set(db.find(["k1", "other"], ["ok"])) == {"k1"} and db.find(["k1"], ["crashed"]) == {}
    db.end_run("r", __import__("impactval.store").store.RunStatus.FINISHED, 0, 0)
    info = db.run_info("r")
    assert info["status"] == "finished" and info["engines"] == {"mujoco": "4.0.0"} and info["ended_at"]


def test_export_columns_are_percent_and_flat(tmp_path):
    df = pd.DataFrame([_row(), _row("k2", err_f_m=-0.02, structure_frequencies="")])
    flat = export_frame(df)
    assert tuple(flat.columns) == EXPORT_COLUMNS
    assert flat["err_f_m_pct"].tolist() == [100 * 1.2345678901234567e-4, -2.0]
    assert not any(c in flat for c in PERCENT_COLUMNS)
    assert not flat.map(lambda v: isinstance(v, str) and v.startswith("[")).any().any()   # no lists in cells
    freq = frequencies_frame(df)
    assert freq[freq["job_key"] == "k1"]["omega_rad_s"].tolist() == [1.5, 2.5, 1.0, 2.0]
    assert list(freq[freq["job_key"] == "k2"]["model"]) == ["continuum", "continuum"]


def test_store_path_that_is_a_directory_is_bad_input(tmp_path):
    with pytest.raises(ImpactvalError, match="is a directory"):
        Store(tmp_path)
    with pytest.raises(ImpactvalError, match="not a usable database URL"):
        Store("nosuchdb://x/y")


def test_export_selects_the_runs_into_that_out(tmp_path):
    db = Store(tmp_path / "s.sqlite")
    for run, out, key in (("a", tmp_path / "x", "k1"), ("b", tmp_path / "y", "k2"), ("c", tmp_path / "x", "k1")):
        db.begin_run(run, "test", out, {}, "ref")
        db.put(_row(key), run_id=run, position=0, reused=run == "c")
    export(db, tmp_path / "x")
    assert pd.read_csv(tmp_path / "x" / "results.csv")["job_key"].tolist() == ["k1"]


@requires_mujoco
def test_run_twice_reuses_and_force_recomputes_with_series(tmp_path):
    from impactval.runner import run

    a = run(["plate_steel"], ["mujoco"], dt=[1e-6, 5e-7], out=tmp_path, keep_series=True)
    b = run(["plate_steel"], ["mujoco"], dt=[1e-6, 5e-7], out=tmp_path)
    c = run(["plate_steel"], ["mujoco"], dt=[1e-6, 5e-7], out=tmp_path, force=True)
    assert (a.attrs["n_reused"], b.attrs["n_reused"], c.attrs["n_reused"]) == (0, 2, 0)
    assert list(b["run_id"]) == [a.attrs["run_id"]] * 2            # reused rows name the run that computed them
    assert list(c["run_id"]) == [c.attrs["run_id"]] * 2
    assert list(a["err_f_m"]) == list(b["err_f_m"]) == list(c["err_f_m"])   # deterministic engine
    db = Store(tmp_path / "impactval.sqlite")
    s = db.load_series(a["job_key"][0])
    assert s is None                                   # --force replaced it with a row without series
    csv = pd.read_csv(tmp_path / "results.csv")
    assert len(csv) == 2 and np.allclose(csv["err_f_m_pct"], 100 * c["err_f_m"], rtol=1e-15, atol=0)


@requires_mujoco
def test_series_are_kept_on_request(tmp_path, plate_scene):
    from impactval.runner import run

    df = run([plate_scene], ["mujoco"], out=tmp_path, keep_series=True)
    s = Store(tmp_path / "impactval.sqlite").load_series(df["job_key"][0])
    assert set(s) == {"t", "f", "delta", "x_ball", "x_structure", "energy"}
    assert len(s["t"]) == df["n_steps"][0] + 1 or len(s["t"]) == df["n_steps"][0]
    assert s["f"].max() == pytest.approx(df["f_m"][0], rel=1e-2)    # sampled peak vs parabola-refined
    phases = Store(tmp_path / "impactval.sqlite").contact_phases(df["job_key"][0])
    assert len(phases) == df["n_contacts"][0] == 1
    assert phases["t_end"][0] - phases["t_start"][0] == df["t_m"][0] and phases["f_max"][0] == df["f_m"][0]


@requires_mujoco
def test_postgresql_store_same_rows_as_sqlite_and_resume(postgres_url, tmp_path):
    """--store postgresql://...: a real server; rows bit-identical to the SQLite store's, a rerun
    reuses them, the export is the same, and two processes writing at once lose nothing."""
    import subprocess
    import sys
    from pathlib import Path

    from impactval.runner import run

    kw = dict(dt=[1e-6, 5e-7], tol=1e-6)
    lite = run(["plate_steel"], ["mujoco"], out=tmp_path / "lite", **kw)
    pg = run(["plate_steel"], ["mujoco"], out=tmp_path / "pg", store=postgres_url, **kw)
    again = run(["plate_steel"], ["mujoco"], out=tmp_path / "pg", store=postgres_url, **kw)
    assert again.attrs["n_reused"] == 2 and list(again["run_id"]) == [pg.attrs["run_id"]] * 2
    for col in ("err_t_m", "err_f_m", "err_delta_m", "err_curve", "t_m", "f_m", "delta_m", "ref_f_m", "job_key"):
        assert list(lite[col]) == list(pg[col]) == list(again[col]), col
    a, b = pd.read_csv(tmp_path / "lite" / "results.csv"), pd.read_csv(tmp_path / "pg" / "results.csv")
    assert a["err_f_m_pct"].tolist() == b["err_f_m_pct"].tolist()
    tests = str(Path(__file__).parent)
    cmd = [sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines", "mujoco", "--jobs", "1",
           "--store", postgres_url, "--out", str(tmp_path / "both")]
    procs = [subprocess.Popen(cmd + ["--dt", d], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              env={**__import__("os").environ, "PYTHONPATH": tests})
             for d in ("4e-7,3e-7,2e-7", "3e-7,2e-7,1.5e-7")]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    db = Store(postgres_url)
    both = db.rows(out=tmp_path / "both")
    assert len(both) == 4 and both["job_key"].is_unique and sorted(both["dt"]) == [1.5e-7, 2e-7, 3e-7, 4e-7]
    db.close()


def test_job_key_changes_with_what_decides_the_row_only(plate_scene):
    from dataclasses import replace

    import impactval
    from impactval.engines.base import EngineSettings
    from impactval.jobs import Job

    base = Job(plate_scene, "mujoco", EngineSettings(dt=1e-6), 1e-6)
    assert base.key == Job(impactval.load_scene("plate_steel"), "mujoco", EngineSettings(dt=1e-6), 1e-6).key
    assert base.key == replace(base, settings=EngineSettings(dt=1e-6, timeout_s=5)).key     # timeout: no
    others = [replace(base, settings=EngineSettings(dt=5e-7)), replace(base, tol=1e-7), replace(base, spec="pybullet"),
              replace(base, settings=EngineSettings(dt=1e-6, options=(("x", 1),))),
              replace(base, scene=impactval.load_scene("beam_ss_midspan"))]
    keys = {base.key} | {j.key for j in others}
    assert len(keys) == 1 + len(others) and all(len(k) == 32 for k in keys)


def test_an_older_results_csv_is_moved_aside_with_a_note(tmp_path):
    (tmp_path / "results.csv").write_text("schema_version,run_id,err_t_m\n2,x,0.1\n")
    db = Store(tmp_path / "impactval.sqlite")
    db.begin_run("r", "test", tmp_path, {}, "ref")
    db.put(_row(), run_id="r", position=0, reused=False)
    notes = export(db, tmp_path)
    aside = list(tmp_path.glob("results-old-*.csv"))
    assert len(aside) == 1 and aside[0].read_text().startswith("schema_version,run_id,err_t_m\n2,x,0.1")
    assert any("moved to results-old-" in n for n in notes)
    assert pd.read_csv(tmp_path / "results.csv")["job_key"].tolist() == ["k1"]
    assert export(db, tmp_path) == [] and len(list(tmp_path.glob("results-old-*.csv"))) == 1   # ours: kept


def test_unreachable_store_is_a_one_line_input_error():
    """Issue 18: a database that cannot be opened is exit 2 naming --store, not an internal error."""
    import pytest

    from impactval.errors import ImpactvalError
    from impactval.store import Store

    with pytest.raises(ImpactvalError, match="--store .*cannot open the store"):
        Store("postgresql://nobody@127.0.0.1:1/impactval")


def test_run_refuses_engines_that_are_not_names():
    import pytest

    from impactval.errors import ImpactvalError
    from impactval.runner import run

    with pytest.raises(ImpactvalError, match="engines must be engine names"):
        run(["plate_steel"], engines=5)
