"""Where an engine's error comes from (issue 17 item 2) and the "C vs Warp" columns (issue 19).

Each engine row splits its error per metric into structure (the engine's structure model vs the
scene's continuum: the adapter's model_error_* diagnostics) + numerics (err - structure), carries the
scene's theory gap (the other beam theory's reference vs the scene's) and, for MuJoCo Warp, its
difference to MuJoCo C on the identical model. Stores and results written before these columns
existed (tests/data/store_v1, written by main at 7e03104) still open, their rows reading NaN.
"""
import dataclasses
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import impactval
from conftest import importorskip_mark, requires_exudyn, requires_mujoco
from pg_server import postgres_server, postgres_url  # noqa: F401 - fixtures
from impactval.store import SCHEMA_VERSION, STORE_SCHEMA_VERSION, Store, export

DATA = Path(__file__).parent / "data" / "store_v1"
METRICS = ("t_m", "f_m", "delta_m")
has_mjw, requires_mjw = importorskip_mark("mujoco_warp")
ORACLE = "split_fakes:TimoshenkoOracle"
FAKE = "impactval.engines.fake_:HertzSpringAdapter"


def stubby_eb():
    """The catalogue's stubby beam (L/h = 3.75) in Euler-Bernoulli theory: a large theory gap."""
    s = impactval.load_scene("beam_ss_stubby_timoshenko")
    return dataclasses.replace(s, name="stubby_euler_bernoulli",
                               target=dataclasses.replace(s.target, theory="euler-bernoulli"))


def rel(a, b):
    return a / b - 1.0


# ---------------------------------------------------------------------------- plumbing (no engine needed)
@pytest.fixture(scope="module")
def oracle_run(tmp_path_factory):
    """A 'perfect Timoshenko engine' (exact numerics, Timoshenko structure) on an Euler-Bernoulli beam,
    next to the analytic fake on the plate."""
    from impactval.runner import run

    out = tmp_path_factory.mktemp("oracle")
    df = run([stubby_eb(), "plate_steel"], [ORACLE, FAKE], dt=1e-6, out=out)
    return df, out


def test_perfect_timoshenko_engine_splits_into_structure_and_no_numerics(oracle_run):
    df, _ = oracle_run
    r = df[(df["engine"] == "timoshenko-oracle") & (df["scene"] == "stubby_euler_bernoulli")].iloc[0]
    assert r["status"] == "ok" and r["beam_theory"] == "euler-bernoulli"
    scene = stubby_eb()
    tim = impactval.solve(dataclasses.replace(scene, target=dataclasses.replace(scene.target, theory="timoshenko")),
                          tol=1e-8)
    ref = impactval.solve(scene, tol=1e-8)
    for m in METRICS:
        gap = rel(getattr(tim, m), getattr(ref, m))          # independent of the runner: tighter tolerance
        assert abs(r[f"theory_gap_{m}"] - gap) <= 1e-5, m
        # the engine is the Timoshenko beam: its whole error is structure, and that is the theory gap
        assert abs(r[f"structure_err_{m}"] - gap) <= 2e-5, m
        assert abs(r[f"numerics_err_{m}"]) <= 1e-5, m
        assert r[f"err_{m}"] == pytest.approx(r[f"structure_err_{m}"] + r[f"numerics_err_{m}"], abs=1e-15)
    assert r["theory_gap_t_m"] < -0.01            # the stubby beam: Timoshenko is 1.5 % shorter in t_m
    # the C-vs-Warp diagnostics become columns, a measured 0 stays 0
    assert (r["vs_mujoco_c_t_m"], r["vs_mujoco_c_f_m"], r["vs_mujoco_c_delta_m"]) == (1.5e-4, -2.5e-4, 0.0)


def test_rows_without_a_structure_model_or_c_comparison_are_nan(oracle_run):
    df, _ = oracle_run
    plate = df[df["scene"] == "plate_steel"]
    fake = plate[plate["engine"] == "fake"].iloc[0]
    for m in METRICS:
        for part in ("structure_err", "numerics_err", "theory_gap", "vs_mujoco_c"):
            assert math.isnan(fake[f"{part}_{m}"]), (part, m)
    assert fake["beam_theory"] == "" and fake["timoshenko_frequencies"] == ""
    beam_fake = df[(df["scene"] == "stubby_euler_bernoulli") & (df["engine"] == "fake")].iloc[0]
    assert beam_fake["status"] == "skipped" and math.isfinite(beam_fake["theory_gap_t_m"])  # a scene property


def test_exports_and_report_carry_the_split_and_the_c_vs_warp_column(oracle_run):
    df, out = oracle_run
    csv = pd.read_csv(out / "results.csv")
    assert set(csv["schema_version"]) == {SCHEMA_VERSION} == {4}
    row = csv[(csv["engine"] == "timoshenko-oracle") & (csv["scene"] == "stubby_euler_bernoulli")].iloc[0]
    src = df[(df["engine"] == "timoshenko-oracle") & (df["scene"] == "stubby_euler_bernoulli")].iloc[0]
    for m in METRICS:
        for part in ("structure_err", "numerics_err", "theory_gap", "vs_mujoco_c"):
            assert row[f"{part}_{m}_pct"] == pytest.approx(100 * src[f"{part}_{m}"], rel=1e-12, abs=1e-15)
    pq = pd.read_parquet(out / "results.parquet")
    assert list(pq.columns) == list(csv.columns)
    md = (out / "report.md").read_text()
    header = next(line for line in md.splitlines() if line.startswith("| scene | engine"))
    assert "C vs Warp t_m %" in header and "C vs Warp delta_m %" in header
    assert "## Where the error comes from" in md
    line = next(x for x in md.splitlines() if x.startswith("- stubby_euler_bernoulli / timoshenko-oracle"))
    s, n = 100 * src["structure_err_t_m"], 100 * src["numerics_err_t_m"]
    assert f"t_m {100 * src['err_t_m']:+.3f} % = structure {s:+.3f} % + numerics {n:+.3f} %" in line
    assert "Theory gap EB -> Timoshenko" in line and "behaves like Timoshenko's" in line
    page = (out / "report.html").read_text()
    assert "<th>C vs Warp t_m %</th>" in page and "Where the error comes from" in page


def test_no_c_vs_warp_column_when_no_row_has_it(tmp_path):
    from impactval.runner import run

    run(["plate_steel"], [FAKE], dt=1e-6, out=tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert "C vs Warp" not in md.split("## Results", 1)[1].split("\n\n", 2)[2]      # the table itself
    assert "## Where the error comes from" not in md


def test_linear_contact_rows_keep_structure_but_do_not_split_numerics():
    """The structure part is measured with Hertz: against a linear law err - structure would also hold
    the contact law's model-form error, so it is not called numerics."""
    from impactval.engines.base import EngineSettings
    from impactval.reference.hertz import ContactLaw
    from impactval.reference.result import ImpactResult, Status
    from impactval.runner import make_row

    scene = impactval.load_scene("beam_ss_midspan")
    ref = ImpactResult(scene=scene.name, source="ref", model="", t_m=1.0, f_m=2.0, delta_m=3.0, status=Status.OK)
    diag = {"model_error_t_m": 0.01, "model_error_f_m": -0.02, "model_error_delta_m": 0.0}
    for law, split in ((ContactLaw.hertz(scene.alpha), True), (ContactLaw.linear(1e8), False)):
        res = ImpactResult(scene=scene.name, source="x", model="", t_m=1.05, f_m=1.9, delta_m=3.0, status=Status.OK,
                           diagnostics=diag, contact_law=law)
        row = make_row("r", scene, "x", EngineSettings(), res, ref, None)
        assert (row["structure_err_t_m"], row["structure_err_f_m"], row["structure_err_delta_m"]) == (0.01, -0.02, 0.0)
        if split:
            assert row["numerics_err_t_m"] == pytest.approx(0.04) and row["numerics_err_f_m"] == pytest.approx(-0.03)
            assert row["numerics_err_delta_m"] == 0.0
        else:
            assert all(math.isnan(row[f"numerics_err_{m}"]) for m in METRICS)
    bad = ImpactResult(scene=scene.name, source="x", model="", t_m=1.0, f_m=2.0, delta_m=3.0, status=Status.OK,
                       diagnostics={"model_error_t_m": "n/a", "vs_mujoco_c": {"status": "crashed"}})
    row = make_row("r", scene, "x", EngineSettings(), bad, ref, None)
    assert math.isnan(row["structure_err_t_m"]) and math.isnan(row["vs_mujoco_c_t_m"])


# ---------------------------------------------------------------------------- stores and results from before
def test_store_written_by_main_before_the_columns_opens_and_old_rows_read_nan(tmp_path):
    import sqlite3

    path = tmp_path / "impactval.sqlite"
    shutil.copy(DATA / "impactval.sqlite", path)
    old_csv = pd.read_csv(DATA / "results.csv")
    def job_columns():
        return [r[1] for r in sqlite3.connect(path).execute("pragma table_info(jobs)")]

    assert "structure_err_t_m" not in job_columns()
    db = Store(path)                                   # the new columns are added in place
    rows = db.rows()
    assert len(rows) == len(old_csv) == 4
    assert {"structure_err_t_m", "vs_mujoco_c_delta_m", "timoshenko_frequencies"} <= set(job_columns())
    assert sqlite3.connect(path).execute("select version from schema_version").fetchall() == [(STORE_SCHEMA_VERSION,)]
    merged = rows.merge(old_csv, on="job_key", suffixes=("", "_old"))
    ok = merged[merged["status"] == "ok"]
    assert len(ok) == 3
    assert np.allclose(100 * ok["err_f_m"], ok["err_f_m_pct"], rtol=1e-12, atol=0)   # old numbers unchanged
    for m in METRICS:
        for part in ("structure_err", "numerics_err", "theory_gap", "vs_mujoco_c"):
            assert rows[f"{part}_{m}"].isna().all()
    assert (rows["timoshenko_frequencies"] == "").all() and (rows["beam_theory"] == "").all()
    db.close()
    db = Store(path)                                   # opening again: nothing left to migrate
    # a new run goes into the same store next to the old rows; the exports hold both
    from impactval.runner import run

    out = tmp_path / "out"
    run([stubby_eb()], [ORACLE, FAKE], dt=1e-6, store=db, out=out)
    both = db.rows()
    assert len(both) == 6 and both["run_id"].nunique() == 2
    export(db, out)
    csv = pd.read_csv(out / "results.csv")
    assert len(csv) == 2 and "vs_mujoco_c_t_m_pct" in csv
    assert csv.loc[csv["engine"] == "timoshenko-oracle", "vs_mujoco_c_f_m_pct"].iloc[0] == pytest.approx(-0.025)
    db.close()


def test_schema_3_results_csv_is_still_a_baseline(tmp_path):
    from impactval.runner import run

    df = run(["plate_steel"], [FAKE], dt=1e-6, baseline=DATA / "results.csv", out=tmp_path, segments=41)
    cmp = df.attrs["baseline"]
    row = cmp[cmp["engine"] == "fake"].iloc[0]
    assert row["mark"] not in ("!", "+") and math.isfinite(row["old_score"])


def test_newer_store_schema_is_refused(tmp_path):
    import sqlite3

    from impactval.errors import ImpactvalError

    path = tmp_path / "s.sqlite"
    Store(path).close()
    with sqlite3.connect(path) as c:
        c.execute("update schema_version set version = 99")
    with pytest.raises(ImpactvalError, match="store schema 99"):
        Store(path)


# ---------------------------------------------------------------------------- real engines
@requires_mujoco
def test_mujoco_chain_numerics_shrink_with_dt_structure_stays(tmp_path):
    """MuJoCo Hencky chain (N = 41, injected Hertz, Euler) on the worked beam at three steps: the
    structure part is the same model each time, the numerics part shrinks with dt (about 4x per
    halving), and the Richardson extrapolation of the engine's own error to dt = 0, from the runs
    alone, lands on the structure part the reference solver computed on the chain's modes."""
    from impactval.runner import run

    df = run(["beam_ss_midspan"], ["mujoco"], dt=[2e-6, 1e-6, 5e-7], segments=41, contact="hertz", out=tmp_path)
    df = df.sort_values("dt", ascending=False)
    assert list(df["status"]) == ["ok"] * 3
    for m in METRICS:
        s = df[f"structure_err_{m}"].to_numpy()
        assert np.all(np.isfinite(s)) and np.ptp(s) == 0.0, m
        n = np.abs(df[f"numerics_err_{m}"].to_numpy())
        assert n[0] > 2 * n[1] > 0 and n[1] > 2 * n[2], (m, n)
        assert n[2] < 5e-5, (m, n)
        e = df[f"err_{m}"].to_numpy()
        if m != "t_m":       # t_m is read off sampled series: not a smooth function of dt
            extrapolated = e[2] + (e[2] - e[1]) / 3.0          # second order (the measured ratio ~4)
            assert abs(extrapolated - s[0]) < 5e-6, (m, extrapolated, s[0])
    gap = df["theory_gap_t_m"].iloc[0]
    assert 0.02 < gap < 0.025               # slender worked beam: Timoshenko 2.3 % longer in t_m
    md = (tmp_path / "report.md").read_text()
    assert md.count("- beam_ss_midspan / mujoco (hertz") == 3
    freq = next(x for x in md.splitlines() if x.startswith("- beam_ss_midspan / mujoco (N = 41)"))
    assert "EB -0.00 %" in freq and "Timoshenko +1.06 %" in freq      # the chain is an Euler-Bernoulli model


@pytest.mark.slow
@requires_exudyn
def test_exudyn_fe_beam_is_timoshenko_in_frequency_and_its_numerics_shrink(tmp_path):
    """Exudyn's solid FE beam (beam_model solid; the default on an Euler-Bernoulli scene is the
    Euler-Bernoulli fe-beam) on the worked beam: its frequencies follow Timoshenko's, not
    Euler-Bernoulli's; its structure part stays while the numerics part shrinks with dt."""
    from impactval.engines.base import EngineSettings
    from impactval.runner import run

    solid = EngineSettings(contact="hertz", options=(("exudyn.beam_model", "solid"),))
    df = run(["beam_ss_midspan"], ["exudyn"], solid, dt=[1e-6, 2.5e-7], out=tmp_path)
    df = df.sort_values("dt", ascending=False)
    assert list(df["status"]) == ["ok"] * 2
    r = df.iloc[0]
    s, eb, tim = (np.array(json.loads(r[k])[:4]) for k in ("structure_frequencies", "continuum_frequencies",
                                                             "timoshenko_frequencies"))
    assert np.max(np.abs(s / tim - 1)) < 0.002 < 0.005 < np.max(np.abs(s / eb - 1))
    for m in METRICS:
        st = df[f"structure_err_{m}"].to_numpy()
        n = np.abs(df[f"numerics_err_{m}"].to_numpy())
        assert np.ptp(st) == 0.0 and n[1] < n[0] / 4, (m, n)
    # its structure part has the sign of the theory gap on every metric (shear and rotary inertia)
    assert all(np.sign(r[f"structure_err_{m}"]) == np.sign(r[f"theory_gap_{m}"]) for m in METRICS)


def test_exudyn_default_fe_beam_is_euler_bernoulli_in_frequency_and_structure(tmp_path):
    """The default Exudyn beam on an Euler-Bernoulli scene (the fe-beam, Exudyn's ANCF cable elements):
    its first frequencies follow Euler-Bernoulli's, not Timoshenko's, and its structure part is far
    below the scene's theory gap."""
    from impactval.runner import run

    df = run(["beam_ss_midspan"], ["exudyn"], dt=1e-6, contact="hertz", out=tmp_path)
    r = df.iloc[0]
    assert r["status"] == "ok", r["message"]
    s, eb, tim = (np.array(json.loads(r[k])[:4]) for k in ("structure_frequencies", "continuum_frequencies",
                                                             "timoshenko_frequencies"))
    assert np.max(np.abs(s / eb - 1)) < 0.002 < 0.005 < np.max(np.abs(s / tim - 1))
    for m in METRICS:
        assert abs(r[f"structure_err_{m}"]) < abs(r[f"theory_gap_{m}"]) / 10, m


@requires_mjw
def test_mujoco_warp_rows_carry_c_vs_warp(tmp_path):
    """The real MuJoCo Warp adapter on the plate: the C-vs-Warp columns equal its diagnostics, are
    small (float32 vs float64 on the identical model) and show in the report's table."""
    from impactval.runner import run

    df = run(["plate_steel"], ["mujoco-warp"], dt=1e-6, contact="native", out=tmp_path)
    r = df.iloc[0]
    assert r["status"] == "ok", r["message"]
    diag = json.loads(pd.read_sql("select diagnostics from jobs", Store(tmp_path / "impactval.sqlite").engine)
                      ["diagnostics"].iloc[0])["vs_mujoco_c"]
    for m in METRICS:
        assert r[f"vs_mujoco_c_{m}"] == diag[m] and abs(diag[m]) < 1e-3, m
    md = (tmp_path / "report.md").read_text()
    assert "C vs Warp f_m %" in md and f"{100 * r['vs_mujoco_c_f_m']:+.3f}" in md


@pytest.mark.slow
@requires_mjw
def test_mujoco_warp_chain_c_vs_warp_and_split(tmp_path):
    from impactval.runner import run

    df = run(["beam_ss_midspan"], ["mujoco-warp"], dt=1e-6, contact="hertz", out=tmp_path)
    r = df.iloc[0]
    assert r["status"] == "ok", r["message"]
    for m in METRICS:
        assert abs(r[f"vs_mujoco_c_{m}"]) < 5e-3, m
        assert math.isfinite(r[f"structure_err_{m}"]) and abs(r[f"numerics_err_{m}"]) < 5e-3, m


def test_old_store_on_postgresql_gets_the_columns(postgres_url, tmp_path):
    """The same old store on a real PostgreSQL server: its tables and rows copied from main's
    SQLite file (reflected, so exactly main's schema), then opened by this impactval."""
    import sqlalchemy as sa

    import shutil

    copy = tmp_path / "v1.sqlite"              # a copy: reading the checked-in file left -shm/-wal files beside it
    shutil.copy(DATA / "impactval.sqlite", copy)
    lite = sa.create_engine(f"sqlite:///{copy}")
    md = sa.MetaData()
    md.reflect(lite)
    pg = sa.create_engine(postgres_url.replace("postgresql://", "postgresql+psycopg://", 1))
    for table in md.sorted_tables:
        for col in table.columns:                   # SQLite's reflected types -> portable ones
            if isinstance(col.type, sa.Float):
                col.type = sa.Double()
            elif isinstance(col.type, sa.LargeBinary):     # BLOB -> BYTEA
                col.type = sa.LargeBinary()
    md.create_all(pg)
    with lite.connect() as src, pg.begin() as dst:
        for table in md.sorted_tables:
            rows = [dict(r) for r in src.execute(table.select()).mappings()]
            if rows:
                dst.execute(table.insert(), rows)
    pg.dispose()
    db = Store(postgres_url)
    rows = db.rows()
    assert len(rows) == 4 and rows["structure_err_t_m"].isna().all() and rows["err_f_m"].notna().sum() == 3
    from impactval.runner import run

    df = run([stubby_eb()], [ORACLE], dt=1e-6, store=db)
    assert df["status"].tolist() == ["ok"] and math.isfinite(df["structure_err_f_m"].iloc[0])
    assert len(db.rows()) == 5
    db.close()


@pytest.mark.parametrize("factor, verdict", [
    (1.1, "behaves like Timoshenko's"), (0.1, "behaves like Euler-Bernoulli's"),
    (0.7, "closer to Timoshenko's than to Euler-Bernoulli's"),
    (-0.7, "closer to Euler-Bernoulli's than to Timoshenko's"),
    ("mixed", "neither theory alone"), ("tiny gap", "the two theories agree here")])
def test_theory_verdict_says_only_what_every_metric_supports(factor, verdict):
    from impactval.reports.run_report import error_source_section
    from impactval.store import COLUMN_TYPES

    gap = {"t_m": 0.02, "f_m": -0.03, "delta_m": -0.02}
    if factor == "mixed":
        structure = {"t_m": 0.016, "f_m": 0.01, "delta_m": -0.018}
    elif factor == "tiny gap":
        gap = {m: v / 100 for m, v in gap.items()}
        structure = {m: -0.01 for m in METRICS}
    else:
        structure = {m: factor * g for m, g in gap.items()}
    row = {c: (math.nan if t == "float" else "") for c, t in COLUMN_TYPES.items()}
    row.update(scene="b", engine="e", contact="hertz", dt=1e-6, segments="", status="ok", beam_theory="euler-bernoulli")
    for m in METRICS:
        row.update({f"err_{m}": structure[m] + 1e-4, f"structure_err_{m}": structure[m], f"numerics_err_{m}": 1e-4,
                    f"theory_gap_{m}": gap[m]})
    text = "\n".join(error_source_section(pd.DataFrame([row])))
    assert verdict in text and text.count("Theory gap EB -> Timoshenko") == 1


def test_two_processes_opening_one_old_store_at_once(tmp_path):
    """Each adds the columns or finds them added; none fails, every column exists once."""
    import sqlite3
    import subprocess
    import sys

    path = tmp_path / "impactval.sqlite"
    shutil.copy(DATA / "impactval.sqlite", path)
    code = f"from impactval.store import Store; print(len(Store({str(path)!r}).rows()))"
    procs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(3)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0], [o[1][-500:] for o in outs]
    assert [o[0].strip() for o in outs] == ["4"] * 3
    cols = [r[1] for r in sqlite3.connect(path).execute("pragma table_info(jobs)")]
    assert cols.count("structure_err_t_m") == 1 and len(cols) == len(set(cols))


def test_theory_gap_is_solved_once_per_scene_and_can_be_left_out(monkeypatch, tmp_path):
    """Two settings on one beam scene: one extra solve (the other theory); theory_gap=False: none."""
    from impactval.engines.base import EngineSettings
    from impactval.jobs import Job
    from impactval.runner import execute

    calls = []
    real = impactval.solve

    def counting(scene, **kw):
        calls.append(scene.target.theory)
        return real(scene, **kw)

    monkeypatch.setattr(impactval, "solve", counting)
    scene = stubby_eb()
    jobs = [Job(scene, ORACLE, EngineSettings(dt=dt), 1e-6) for dt in (1e-6, 2e-6)]
    rows = execute(jobs, store=tmp_path / "a.sqlite", workers=1)
    assert sorted(calls) == ["euler-bernoulli", "timoshenko"]
    assert all(math.isfinite(r["theory_gap_f_m"]) for r in rows)
    calls.clear()
    rows = execute(jobs, store=tmp_path / "b.sqlite", workers=1, theory_gap=False)
    assert calls == ["euler-bernoulli"]
    assert all(math.isnan(r["theory_gap_f_m"]) and r["timoshenko_frequencies"] == "" for r in rows)
    assert all(math.isfinite(r["structure_err_f_m"]) for r in rows)       # the split does not need the gap
