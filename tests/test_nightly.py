"""`impactval nightly` and `impactval report` against the bars of issue 16, on real engines and stores."""
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from chromium import load_page, requires_chromium
from conftest import requires_exudyn, requires_mujoco, requires_pybullet as requires_pybullet_installed
from impactval.engines.base import EngineSettings
from pg_server import postgres_server, postgres_url  # noqa: F401 - fixtures

#: a deliberately worse engine setting: generalized-alpha with strong numerical damping (spectral
#: radius 0.3 instead of 1) more than doubles Exudyn's plate errors (t_m 0.021 % -> 0.049 %)
WORSE = (("exudyn.spectral_radius", 0.3),)
ERRORS = ["err_t_m", "err_f_m", "err_delta_m", "err_curve"]


def night(store, out, options=(), **kw):
    from impactval.nightly import nightly

    return nightly(["plate_steel"], "exudyn", EngineSettings(dt=1e-6, options=options), store=store, out=out, **kw)


def three_nights(store, tmp_path):
    """Two unchanged nights, then one with the worse setting."""
    return [night(store, tmp_path / f"n{i}", opts) for i, opts in enumerate(((), (), WORSE))]


def red_pixels(png) -> int:
    """Pixels in the regression marker's colour (#C00000) in a PNG."""
    import matplotlib.image as mpimg

    img = mpimg.imread(png)[..., :3]
    return int((np.abs(img - np.array([0xC0, 0, 0]) / 255).max(axis=-1) < 0.06).sum())


@requires_exudyn
def test_unchanged_nights_pass_and_a_worse_setting_fails(tmp_path):
    store = tmp_path / "history.sqlite"
    first, second, worse = three_nights(store, tmp_path)
    assert first.exit_code == 0 and first.baseline_run_id is None and "first night" in first.message
    # unchanged: exit 0, identical rows (errors are deterministic), nothing marked, nothing changed
    assert second.exit_code == 0 and second.baseline_run_id == first.run_id
    assert second.night != first.night
    pd.testing.assert_frame_equal(first.rows[["scene", "engine", "status", *ERRORS]],
                                  second.rows[["scene", "engine", "status", *ERRORS]])
    assert list(second.cmp["mark"]) == [""] and not second.cmp["changed"].any()
    # worse setting: exit 1, the row marked + with its numbers, in the summary and the trend plot
    assert worse.exit_code == 1 and worse.baseline_run_id == second.run_id
    r = worse.cmp.iloc[0]
    assert r["mark"] == "+"
    assert abs(r["err_t_m"]) > 2 * abs(r["old_err_t_m"]) > 0
    assert f"t_m {100 * r['old_err_t_m']:+.4g} % -> {100 * r['err_t_m']:+.4g} %" in r["why"]
    md = worse.report.read_text()
    summary = md[md.index("## Summary"):md.index("## Against the baseline")]
    worst = max(("t_m", "f_m", "delta_m", "curve"), key=lambda m: r[f"change_{m}"])
    part = next(p.strip() for p in r["why"].split(";") if p.strip().startswith(worst + " "))
    assert f"+ plate_steel: {part}" in summary                    # the worst metric with its numbers
    assert "- **verdict**: exit 1: regression against the baseline run" in md
    assert any("+ plate_steel / exudyn" in line for line in worse.flagged)
    trend = tmp_path / "n2" / "trend_plate_steel.png"
    assert "trend_plate_steel.png" in md and red_pixels(trend) > 20
    assert red_pixels(tmp_path / "n1" / "trend_plate_steel.png") == 0       # no regression, no marker
    # the regression stays red: the next night is compared with the last good one, not the bad one
    again = night(store, tmp_path / "n3", WORSE)
    assert again.exit_code == 1 and again.baseline_run_id == second.run_id


@requires_mujoco
def test_a_drifted_setup_is_exit_2_naming_the_keys(tmp_path):
    cmd = [sys.executable, "-m", "impactval.cli", "nightly", "plate_steel", "--engines", "mujoco",
           "--store", str(tmp_path / "h.sqlite")]
    first = subprocess.run(cmd + ["--dt", "1e-6", "--out", str(tmp_path / "a")], capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    drift = subprocess.run(cmd + ["--dt", "5e-7", "--out", str(tmp_path / "b")], capture_output=True, text=True)
    assert drift.returncode == 2, drift.stdout + drift.stderr
    err = [line for line in drift.stderr.splitlines() if line.startswith("impactval: error:")]
    assert len(err) == 1 and "nothing comparable with the baseline run" in err[0]
    assert "dt: baseline 1e-06; now 5e-07" in err[0] and "Traceback" not in drift.stderr
    assert "exit 2: nothing comparable" in (tmp_path / "b" / "report.md").read_text()
    bad = subprocess.run(cmd + ["--fail-on", "fm:+20%", "--out", str(tmp_path / "c")], capture_output=True, text=True)
    assert bad.returncode == 2 and "unknown metric 'fm'" in bad.stderr and not (tmp_path / "c").exists()


def _stored_jobs(db) -> int:
    if not os.path.exists(db):
        return 0
    try:
        with sqlite3.connect(db, timeout=1) as c:
            return c.execute("SELECT count(*) FROM jobs WHERE status = 'ok'").fetchone()[0]
    except sqlite3.Error:
        return 0


@requires_mujoco
def test_a_killed_night_resumes_without_duplicates_or_recomputation(tmp_path):
    db = tmp_path / "h.sqlite"
    cmd = [sys.executable, "-m", "impactval.cli", "nightly", "plate_steel", "beam_ss_midspan", "--engines", "mujoco",
           "--dt", "5e-7", "-j", "1", "--store", str(db), "--out", str(tmp_path / "out")]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    end = time.monotonic() + 240
    while _stored_jobs(db) < 1 and time.monotonic() < end and proc.poll() is None:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)                  # the whole process group, as a CI runner would
    proc.wait()
    with sqlite3.connect(db) as c:
        before = dict(c.execute("SELECT job_key, created_at FROM jobs").fetchall())
    assert len(before) == 1, "the kill should land after the first job and before the second"
    rerun = subprocess.run(cmd, capture_output=True, text=True)
    assert rerun.returncode == 0, rerun.stdout + rerun.stderr
    with sqlite3.connect(db) as c:
        runs = c.execute("SELECT id, tag, status, n_reused FROM runs ORDER BY started_at").fetchall()
        jobs = dict(c.execute("SELECT job_key, created_at FROM jobs").fetchall())
        linked = c.execute("SELECT count(*), count(DISTINCT job_key) FROM run_jobs WHERE run_id = ?",
                           (runs[-1][0],)).fetchone()
    assert [r[2] for r in runs] == ["interrupted", "finished"] and runs[0][1] == runs[1][1]  # same night resumed
    assert runs[1][3] == 1                                   # the finished job was reused ...
    assert {k: jobs[k] for k in before} == before            # ... not recomputed
    assert len(jobs) == 2 and linked == (2, 2)               # every job of the night once
    # the next night's history holds one entry per night
    from impactval.nightly import history_rows, nightly_runs
    from impactval.store import Store

    s = Store(db)
    try:
        nr = nightly_runs(s, "nightly")
        hist = history_rows(s, nr, nr["id"].iloc[-1])
    finally:
        s.close()
    assert hist["run_index"].nunique() == 1 and len(hist) == 2


@requires_mujoco
@requires_chromium
def test_report_rerenders_from_the_store_and_the_page_loads(tmp_path):
    out = tmp_path / "night"
    cmd = [sys.executable, "-m", "impactval.cli"]
    for _ in range(2):
        r = subprocess.run(cmd + ["nightly", "plate_steel", "--engines", "mujoco", "--dt", "1e-6", "--out", str(out),
                                  "--fail-on", "f_m:+15%"], capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
    original = (out / "report.md").read_text()
    listing = subprocess.run(cmd + ["report", str(out), "--list"], capture_output=True, text=True)
    assert listing.returncode == 0 and len(listing.stdout.splitlines()) == 2
    again = subprocess.run(cmd + ["report", str(out), "--out", str(tmp_path / "again")], capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    redone = (tmp_path / "again" / "report.md").read_text()

    def section(md, title):
        start = md.index(title)
        return md[start:md.index("\n## ", start + 1)]

    for title in ("## Summary", "## Against the baseline", "## Results", "## Reference values"):
        assert section(redone, title) == section(original, title)
    assert "- **verdict**: exit 0: no regression" in redone and "t_m:+20%, f_m:+15%" in redone
    page = load_page(tmp_path / "again" / "report.html")
    n_figures = redone.count("\n![")
    assert n_figures == 2                                     # force curves and trend
    assert page["images_total"] == n_figures and page["images_loaded"] == n_figures
    assert page["console_errors"] == [] and page["external_refs"] == 0
    assert "Reference values" in page["text"] and "closed form" in page["text"]
    missing = subprocess.run(cmd + ["report", str(tmp_path / "nowhere")], capture_output=True, text=True)
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1 and "no such store" in missing.stderr


def _al_beam(where) -> str:
    """A scene outside the catalogue: a simply supported aluminium beam 0.3 x 0.02 x 0.01 m hit at 0.37 L by a 5 mm
    steel ball at 0.5 m/s (its reference and theory gap take 0.02 s, the clamped one's 2 s). Returns the TOML path."""
    path = where / "al_ss_037.toml"
    path.write_text('name = "al_ss_037"\n[ball]\nradius = 0.005\nvelocity = 0.5\nmaterial = "steel"\n'
                    '[target]\nkind = "beam"\nmaterial = "aluminium"\nsupport = "simply-supported"\nlength = 0.3\n'
                    'width = 0.02\nheight = 0.01\nimpact_at = 0.37\n')
    return str(path)


def _header(md: str) -> list[str]:
    return md[:md.index("## Summary")].splitlines()


@requires_mujoco
def test_a_re_rendered_night_has_the_live_header_with_its_settings_line(tmp_path):
    """`impactval report` of a stored night printed no settings line (and a shorter suite line): the store holds
    each job's settings, and the re-rendered header is now the live one, line for line."""
    from impactval.nightly import nightly, render_stored

    scene = _al_beam(tmp_path)
    live = nightly([scene], "mujoco", EngineSettings(dt="auto", timeout_s=300.0), out=tmp_path / "live")
    assert live.exit_code == 0, live.message
    _, paths = render_stored(str(tmp_path / "live"), out=tmp_path / "again")
    original, redone = live.report.read_text(), paths[0].read_text()
    dt = f"{live.rows['dt'].iloc[0]:g}"
    line = (f"- **settings**: dt = {dt} s, contact = hertz, integrator = engine default, segments = engine default, "
            f"timeout = 300 s (--dt auto: the engines chose these steps)")
    assert line in _header(original)
    assert line in _header(redone)
    assert _header(redone) == _header(original)                 # the suite line too ("nightly, night ..." before)


def test_a_store_written_before_the_fix_re_renders_with_its_settings_line(tmp_path):
    """Nothing was added to the store: a schema-1 store (tests/data/store_v1, main at 7e03104) has its jobs'
    settings, and its re-rendered run report gets the settings line the live report had."""
    import shutil

    from impactval.nightly import render_stored

    data = Path(__file__).parent / "data" / "store_v1"
    shutil.copy(data / "impactval.sqlite", tmp_path / "impactval.sqlite")
    _, paths = render_stored(str(tmp_path), out=tmp_path / "again")
    assert ("- **settings**: dt = 1e-06 s, contact = hertz, integrator = engine default, segments = 41, "
            "timeout = 600 s") in _header(paths[0].read_text())


@requires_mujoco
@requires_pybullet_installed
def test_an_interrupted_night_lists_the_engine_that_never_ran(tmp_path):
    """SIGINT after MuJoCo's job (-j 1: PyBullet's queued behind it): PyBullet's job never ran. The night's report
    (live, and re-rendered from the store) lists PyBullet with status `interrupted`, says the night is incomplete
    with no verdict, and the command exits 130 (it listed MuJoCo alone, as if PyBullet were not part of the night)."""
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "impactval.cli", "nightly", _al_beam(tmp_path), "--engines", "mujoco,pybullet",
           "--dt", "auto", "-j", "1", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 240
    while _stored_jobs(out / "impactval.sqlite") < 1 and time.monotonic() < end and proc.poll() is None:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "1 of 2 jobs finished" in err, "the interrupt should land after MuJoCo's job and before PyBullet's"
    again = subprocess.run([sys.executable, "-m", "impactval.cli", "report", str(out), "--out", str(tmp_path / "re")],
                           capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    for md in ((out / "report.md").read_text(), (tmp_path / "re" / "report.md").read_text()):
        summary = md[md.index("## Summary"):md.index("\n## ", md.index("## Summary") + 1)]
        assert "| pybullet | 3." in summary and "| 1 interrupted |" in summary, summary
        assert ("**Incomplete**: 1 of 2 jobs did not run (status `interrupted`: the run was stopped before they "
                "finished): pybullet (none of its 1 job ran)") in summary
        results = md[md.index("## Results"):]
        assert "| al_ss_037 | pybullet | hertz |" in results and "| interrupted |" in results
        assert "- al_ss_037 / pybullet: **interrupted**: did not run: the night was interrupted" in md
        assert "- **verdict**: none: the night was interrupted" in md
        assert "1 of 2 jobs finished (no job of pybullet finished), so it is incomplete" in md
        assert "No verdict: the night was interrupted" in md and "Exit code **0**" not in md
        assert md.startswith("# impactval nightly (nightly): interrupted\n")
        assert "- **suite**: nightly (1 scenes x 2 engines), night " in md and "- **settings**: dt = " in md


@pytest.mark.slow
@requires_exudyn
def test_sqlite_and_postgresql_give_the_same_comparison(tmp_path, postgres_url):  # noqa: F811
    lite = three_nights(tmp_path / "h.sqlite", tmp_path / "lite")
    pg = three_nights(postgres_url.replace("postgresql+psycopg://", "postgresql://"), tmp_path / "pg")   # as a user types it
    assert [o.exit_code for o in lite] == [o.exit_code for o in pg] == [0, 0, 1]
    cols = ["scene", "engine", "mark", "why", "old_err_t_m", *ERRORS, "change_t_m", "change_f_m"]
    for a, b in zip(lite[1:], pg[1:]):
        pd.testing.assert_frame_equal(a.cmp[cols], b.cmp[cols])
        pd.testing.assert_frame_equal(a.rows[ERRORS], b.rows[ERRORS])


@requires_pybullet_installed
def test_nothing_could_run_is_exit_2(tmp_path):
    """PyBullet has no modal (FFRF) body: every job of this night is skipped, so nothing ran."""
    r = subprocess.run([sys.executable, "-m", "impactval.cli", "nightly", "modal_two_mode", "--engines", "pybullet",
                        "--dt", "1e-6", "--out", str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "impactval: error: nothing could run: every job is not-installed or skipped" in r.stderr


@requires_mujoco
def test_run_report_and_run_baseline_follow_the_nightly_rules(tmp_path):
    cmd = [sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines", "mujoco", "--dt", "1e-6"]
    first = subprocess.run(cmd + ["--out", str(tmp_path / "a")], capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    md = (tmp_path / "a" / "report.md").read_text()
    assert md.index("## Summary") < md.index("## Results") < md.index("## Reference values")
    assert "closed form (Hertz, paper eq. 31-33)" in md and " contacts |" in md
    assert "lin t_m" not in md                                  # empty columns left out
    assert "![plate_steel: contact force" in md and (tmp_path / "a" / "curves_plate_steel.png").is_file()
    assert (tmp_path / "a" / "report.html").is_file()
    drift = subprocess.run([*cmd[:-1], "5e-7", "--out", str(tmp_path / "b"), "--baseline",
                            str(tmp_path / "a" / "results.csv")], capture_output=True, text=True)
    assert drift.returncode == 2, drift.stdout + drift.stderr
    assert "nothing comparable with" in drift.stderr and "dt: baseline 1e-06; now 5e-07" in drift.stderr
    again = subprocess.run([sys.executable, "-m", "impactval.cli", "report", str(tmp_path / "a"), "--run",
                            first.stdout.split("run ")[-1].split(":")[0][:8], "--out", str(tmp_path / "c")],
                           capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    redone = (tmp_path / "c" / "report.md").read_text()
    assert redone[redone.index("## Summary"):] == md[md.index("## Summary"):]


@requires_mujoco
def test_sigterm_writes_the_partial_report_and_exits_143(tmp_path):
    db = tmp_path / "h.sqlite"
    proc = subprocess.Popen([sys.executable, "-m", "impactval.cli", "nightly", "plate_steel", "beam_ss_midspan",
                             "--engines", "mujoco", "--dt", "5e-7", "-j", "1", "--store", str(db), "--out",
                             str(tmp_path / "out")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + 240
    while _stored_jobs(db) < 1 and time.monotonic() < end and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "rerun to resume the night" in err
    md = (tmp_path / "out" / "report.md").read_text()
    assert "interrupted" in md and "plate_steel" in md


@requires_mujoco
def test_a_job_failing_from_the_first_night_is_not_new(tmp_path):
    """A job that fails on the first night (exit 1) is the starting point: the next unchanged night is
    compared with it and passes (a job that starts failing later is '!': test_history.test_marks)."""
    from impactval.nightly import nightly

    def go():
        return nightly(["plate_steel", "beam_ss_midspan"], "mujoco", EngineSettings(dt=1e-6),
                       store=tmp_path / "h.sqlite", out=tmp_path / "out")

    first = go()
    st = dict(zip(first.rows["scene"], first.rows["status"]))
    if st["beam_ss_midspan"] == "ok":
        pytest.skip("MuJoCo's default beam chain is stable at dt = 1e-6 s in this version")
    assert first.exit_code == 1 and "jobs failed" in first.message
    second = go()
    assert second.exit_code == 0 and second.baseline_run_id == first.run_id, second.message
    assert list(second.cmp["mark"]) == ["", ""]


@requires_mujoco
def test_rows_skipped_in_both_nights_are_counted_apart(tmp_path):
    """A night's verdict said "2 of 2 rows compared" where one row was an engine skipping an unsupported scene in both
    nights (nothing in it could change): the count of those is now part of the line."""
    from impactval.nightly import nightly

    store = tmp_path / "n.sqlite"
    for out in ("a", "b"):
        res = nightly(["plate_steel", "plate_ss_rectangular"], "mujoco", EngineSettings(dt="auto"), store=store,
                      out=tmp_path / out)
        assert res.exit_code == 0, res.message
    assert set(res.rows["status"]) == {"ok", "skipped"}
    assert "(2 of 2 rows compared (1 of them skipped in both nights), 0 changed" in res.message, res.message


@requires_mujoco
def test_a_re_rendered_report_says_when_the_reference_moved_since_the_run(tmp_path):
    """Round 20: a report re-rendered after the reference solver changed showed today's reference values next to
    errors computed against the run's, without a word. The store's rows hold the run's reference values: a re-render
    whose reference differs from them by more than history.REFERENCE_MOVE_LIMIT says so, naming the move; an
    unchanged one says nothing."""
    import sqlite3

    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "impactval.cli"]
    r = subprocess.run(cmd + ["run", "plate_steel", "--engines", "mujoco", "--dt", "1e-6", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    same = subprocess.run(cmd + ["report", str(out), "--out", str(tmp_path / "same")], capture_output=True, text=True)
    assert same.returncode == 0, same.stderr
    assert "moved since this run" not in (tmp_path / "same" / "report.md").read_text()
    with sqlite3.connect(out / "impactval.sqlite") as db:          # the run's reference, as an older solver gave it
        db.execute("UPDATE jobs SET ref_f_m = ref_f_m * 1.001")
    moved = subprocess.run(cmd + ["report", str(out), "--out", str(tmp_path / "moved")], capture_output=True, text=True)
    assert moved.returncode == 0, moved.stderr
    text = (tmp_path / "moved" / "report.md").read_text()
    assert "plate_steel: the reference's values moved since this run (f_m -0.001, relative)" in text
