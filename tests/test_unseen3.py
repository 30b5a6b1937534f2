"""Red-team scenes, round 3 (tests/unseen3/*.toml: unlike the catalogue, tests/unseen and tests/unseen2), run
through every command at its defaults. What broke, each check on the scene that showed it:

- `impactval SUBCOMMAND --help` exited 3 with "internal error: Exit: 0" for every subcommand (click's Exit is
  not a ClickException; the bug guard caught it).
- A row without a result (`unstable` refused before stepping, `skipped`) showed only its status on the terminal:
  its limit and fix were in report.md alone. A refused row also had no N and no integrator, so a sweep's
  stability table split it from its series (ss_glass_wc_fast, Euler: "largest stable dt" empty, RK4 missing).
- `reference --explain` on a Kirchhoff plate said "modes the solve used: None (the scene's)" (it used 4096), and
  on a ball target "rigid plate: no structure modes".
- The report of a scene given as a file had no reference values, provenance or force curves ("not in the
  catalogue here"); `impactval report` of a dt = auto run added a "Speed against accuracy" section (each engine
  picks its own dt, so the run has several), which the run's own report does not have.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from click.testing import CliRunner
from scipy.integrate import quad

import impactval
from unseen_rows import rows_at_defaults
from impactval.engines.base import EngineSettings, execute_job

UNSEEN3 = Path(__file__).parent / "unseen3"
SCENES = sorted(UNSEEN3.glob("*.toml"))
BAR = 0.015
BAR_EXUDYN = 0.02
METRICS = ("t_m", "f_m", "delta_m")


def _path(name: str) -> str:
    return str(UNSEEN3 / f"{name}.toml")


def _scene(name: str):
    return impactval.load_scene(_path(name))


def test_every_unseen3_scene_says_why_it_is_there():
    assert len(SCENES) >= 8
    kinds = set()
    for path in SCENES:
        assert path.read_text().splitlines()[0].startswith("# why:"), path.name
        kinds.add(impactval.load_scene(str(path)).target.kind)
    assert kinds == {"beam", "plate", "rigid-plate", "ball", "modal"}


def _hertz_closed_form(ball, other_young, other_poisson, other_radius, other_mass, v):
    """Two-body Hertz impact (Johnson, Contact Mechanics, 11.4): t_m [s], f_m [N], delta_m [m]."""
    e_star = 1.0 / ((1 - ball.poisson ** 2) / ball.young + (1 - other_poisson ** 2) / other_young)
    r = ball.radius if other_radius is None else ball.radius * other_radius / (ball.radius + other_radius)
    m = ball.mass if other_mass is None else ball.mass * other_mass / (ball.mass + other_mass)
    alpha = 4.0 / 3.0 * e_star * math.sqrt(r)
    delta = (5.0 * m * v ** 2 / (4.0 * alpha)) ** 0.4
    integral = quad(lambda x: 1.0 / math.sqrt(1.0 - x ** 2.5), 0.0, 1.0)[0]
    return 2.0 * delta / v * integral, alpha * delta ** 1.5, delta


def test_references_of_the_closed_form_scenes():
    """Equal titanium balls head-on (1.5 + 1.5 m/s, reduced mass m/2) and a 2 mm glass ball on rigid PMMA at
    15 m/s: the reference is the closed form (checked by hand against the run's report: 29.09938 us, 760.1415 N)."""
    from impactval.scenarios.materials import BUILTIN_MATERIALS as MAT

    balls = _scene("ball_ball_equal_ti")
    ti = MAT["titanium"]
    b = balls.ball
    ball = type("B", (), dict(young=ti.young, poisson=ti.poisson, radius=b.radius, mass=b.mass))
    want = _hertz_closed_form(ball, ti.young, ti.poisson, balls.target.radius, balls.target.mass,
                              b.velocity + balls.target.velocity)
    got = impactval.solve(balls, tol=1e-8)
    for w, g in zip(want, (got.t_m, got.f_m, got.delta_m)):
        assert abs(g / w - 1) < 1e-7, (g, w)
    plate = _scene("rigid_pmma_glass_fast")
    glass, pmma = MAT["glass"], MAT["pmma"]
    ball = type("B", (), dict(young=glass.young, poisson=glass.poisson, radius=plate.ball.radius,
                              mass=plate.ball.mass))
    want = _hertz_closed_form(ball, pmma.young, pmma.poisson, None, None, plate.ball.velocity)
    got = impactval.solve(plate, tol=1e-8)
    for w, g in zip(want, (got.t_m, got.f_m, got.delta_m)):
        assert abs(g / w - 1) < 1e-7, (g, w)
    assert any(v.startswith("Hertz: delta_m is 5.29 %") for v in got.validity)     # honest: a/R = 0.23


def test_every_subcommand_help_exits_0():
    from impactval.cli import main

    runner = CliRunner()
    assert len(main.commands) >= 10
    for name in main.commands:
        res = runner.invoke(main, [name, "--help"])
        assert res.exit_code == 0, (name, res.exit_code, res.output)
        assert "Usage:" in res.output and "internal error" not in res.output, name
    bad = runner.invoke(main, ["run", "--no-such-option"])
    assert bad.exit_code == 2 and "No such option" in bad.output


def test_a_refused_row_names_its_limit_on_the_terminal_and_joins_its_series():
    pytest.importorskip("mujoco", reason="pip install 'impactval[mujoco]'")
    import pandas as pd

    from impactval.runner import make_row, text_table
    from impactval.sweep import stability

    scene = _scene("ss_glass_wc_fast")
    ref = impactval.solve(scene, tol=1e-6)
    rows = []
    for dt in (1e-6, 2e-7):
        settings = EngineSettings(dt=dt)
        res = execute_job("mujoco", scene, settings)
        rows.append(make_row("run", scene, "mujoco", settings, res, ref, None))
    refused, ok = rows
    assert (refused["status"], ok["status"]) == ("unstable", "ok")
    assert (refused["segments"], refused["integrator"]) == (ok["segments"], ok["integrator"]) == ("41", "Euler")
    plate = _scene("plate_al_near_edge")
    skipped = execute_job("mujoco", plate, EngineSettings())
    rows.append(make_row("run", plate, "mujoco", EngineSettings(), skipped, impactval.solve(plate, tol=1e-3), None))
    table = text_table(pd.DataFrame(rows))
    assert "  - ss_glass_wc_fast / mujoco: unstable: dt = 1e-06 s is above the predicted explicit stability limit" \
        in table and "use dt <= 2e-07 s or dt = auto" in table
    assert "  - plate_al_near_edge / mujoco: skipped: mujoco: target kind 'plate' is not supported" in table
    refused_line, _, skipped_line = table.splitlines()[1:4]
    assert skipped_line.endswith("skipped") and refused_line.endswith("unstable")   # no 0.0 ms / 0 steps
    st = stability(pd.DataFrame(rows[:2]))
    assert len(st) == 1, st                            # one series, N = 41 (was two: "default" and 41)
    assert st["dt_stable_max"].iloc[0] == 2e-7 and st["dt_refused_min"].iloc[0] == 1e-6
    assert math.isnan(st["dt_limit_observed"].iloc[0])       # refused, never stepped: no observed limit (s20)
    assert 2e-7 < st["dt_limit_predicted"].iloc[0] < 1e-6


def test_explain_names_the_solved_mode_count_of_a_plate_and_says_ball_for_a_ball():
    from impactval.cli import main

    runner = CliRunner()
    res = runner.invoke(main, ["reference", _path("plate_al_near_edge"), "--explain"])
    assert res.exit_code == 0, res.output
    solved = impactval.solve(_scene("plate_al_near_edge"), tol=1e-6).modes
    assert f"modes the solve used at tol 1e-06: {solved} (measured: doubled" in res.output
    assert "None" not in res.output
    res = runner.invoke(main, ["reference", _path("ball_ball_equal_ti"), "--explain"])
    assert res.exit_code == 0 and "ball target: no structure modes" in res.output and "rigid plate" not in res.output


def test_report_of_scene_files_has_their_references_and_a_rerender_matches(tmp_path):
    """A run of two scene files at dt = auto (MuJoCo picks 1e-7 s for the balls, 5e-8 s for the PMMA plate):
    the report has both reference values and force curves; `impactval report` re-renders it without a
    speed/accuracy section, which a `--dt a,b` run does get."""
    pytest.importorskip("mujoco", reason="pip install 'impactval[mujoco]'")
    pytest.importorskip("matplotlib")
    from impactval.nightly import is_dt_sweep, render_stored
    from impactval.runner import run

    out = tmp_path / "run"
    df = run([_path("ball_ball_equal_ti"), _path("rigid_pmma_glass_fast")], ["mujoco"], out=out, keep_series=True,
             workers=1, progress=None)
    assert sorted(df["dt"]) == [5e-8, 1e-7] and not is_dt_sweep(df)
    md = (out / "report.md").read_text()
    assert "not in the catalogue" not in md
    ref_lines = [ln for ln in md.splitlines() if ln.startswith("| ball_ball_equal_ti | 29.09938")]
    assert ref_lines and "closed form" in ref_lines[0], ref_lines
    assert (out / "curves_rigid_pmma_glass_fast.png").stat().st_size > 1000
    again = tmp_path / "again"
    render_stored(str(out), out=again)
    assert "Speed against accuracy" not in (again / "report.md").read_text()
    swept = run([_path("rigid_pmma_glass_fast")], ["mujoco"], dt=[1e-7, 5e-8], workers=1, progress=None)
    assert is_dt_sweep(swept)


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["mujoco", "pybullet", "exudyn"])
def test_every_unseen3_row_is_ok_or_honest(engine):
    """All defaults, injected Hertz: every row ok within the bar (measured worst: MuJoCo 0.385 %, PyBullet
    0.384 %, both f_m on ss_pmma_big_ball_slow; Exudyn 0.282 %, f_m on cantilever_timo_03) or skipped with
    its reason (plates; PyBullet's modal target)."""
    pytest.importorskip(engine)
    for path, scene, res, row in rows_at_defaults(engine, SCENES):
        if row is None:
            assert scene.target.kind == "plate" or (engine, scene.target.kind) == ("pybullet", "modal")
            continue
        worst = max(abs(row[f"err_{m}"]) for m in METRICS)
        assert worst <= (BAR_EXUDYN if engine == "exudyn" else BAR), (path.name, worst)
        if math.isfinite(res.model_error):
            assert worst <= abs(res.model_error) + 5e-3 or row["message"], (path.name, worst, res.model_error)


def test_tune_default_dt_stays_below_the_engine_models_stability_limit():
    """`tune pybullet cc_short_heavy_ball --speeds 0.02:0.1:2` took dt = 2e-7 s from the contact time alone, above
    the 27-link chain's limit 1.7e-7 s: every fit run was refused (unstable) and the emitted options were never
    evaluated (exit 1). The default now stays below DT_MARGIN x the engine model's predicted limit (then: 5e-8 s,
    both speeds ok). Since round 20 the contact time alone gives 5e-7 s (500 steps per contact, not 2000)."""
    pytest.importorskip("pybullet", reason="pip install 'impactval[pybullet]'")
    from impactval.engines.base import EngineSettings as ES, load_adapter
    from impactval.tune import at_speed, default_dt

    scene, speeds = _scene("cc_short_heavy_ball"), [0.02, 0.1]
    assert default_dt(scene, speeds) == 5e-7          # the contact time alone (437 us / 500 steps, 1-2-5 down)
    adapter = load_adapter("pybullet")
    limit = adapter.plan(at_speed(scene, 0.1), adapter.check_settings(ES(dt=1e-7, contact="native"))).dt_limit
    assert 1.5e-7 < limit < 2e-7
    dt = default_dt(scene, speeds, "pybullet")
    assert dt <= 0.5 * limit and dt == 5e-8
    plate = impactval.load_scene("plate_steel")                            # no structure: unchanged
    assert default_dt(plate, [0.1, 1.0, 10.0], "pybullet") == default_dt(plate, [0.1, 1.0, 10.0])


def test_theory_verdict_follows_the_spectrum_when_it_is_clear():
    """Exudyn's solid on the Timoshenko cantilever hit at 0.3 L: structure error +0.285 % f_m, theory gap to EB
    +0.557 %; the report said its model "is closer to Euler-Bernoulli's than to Timoshenko's", next to its own
    frequencies: +0.7..+2.3 % from Timoshenko's, up to -15.4 % from EB's. A coarse (N = 9), slightly stiff
    Timoshenko model, not an EB one: the sentence now says so."""
    pytest.importorskip("exudyn", reason="pip install 'impactval[exudyn]'")
    from impactval.reports.run_report import error_source_section
    from impactval.runner import run

    df = run([_path("cantilever_timo_03")], ["exudyn"], workers=1, progress=None)
    assert df["status"].tolist() == ["ok"]
    assert 0.0 < df["structure_err_f_m"].iloc[0] < df["theory_gap_f_m"].iloc[0]     # moved toward EB
    text = "\n".join(error_source_section(df))
    assert "follows Timoshenko's spectrum" in text and "closer to Euler-Bernoulli's" not in text, text


def test_theory_page_says_n_a_where_first_order_theory_has_no_answer(tmp_path):
    """The light strongly coupled mode shifts f_m by -112 % at first order: no first-order answer. The theory page
    printed `nan | nan | nan | +nan %` rows (README: "gives no answer (n/a)"; never a NaN as an answer)."""
    pytest.importorskip("matplotlib")
    from impactval.cli import main

    res = CliRunner().invoke(main, ["theory", _path("modal_light_coupled"), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    page = (tmp_path / "theory_modal_light_coupled.md").read_text()
    assert not re.search(r"\bnan\b", page, re.IGNORECASE), page
    row = next(ln for ln in page.splitlines() if ln.startswith("| Hertz, first order in s"))
    assert row.count("n/a") == 6, row


def test_exudyn_segments_size_the_fe_beam_and_are_refused_on_the_solid():
    """`sweep cantilever_timo_03 --engines pybullet,exudyn --segments pybullet.11,35` gave Exudyn segments = 35,
    which it ignored (its solid is sized by modes): rows said N = 35 with the default model's numbers. Now the
    fe-beam takes segments as its element count, the solid refuses them (skipped, with the fix), and a row's N
    is what the engine used before what was asked."""
    pytest.importorskip("exudyn", reason="pip install 'impactval[exudyn]'")
    res = execute_job("exudyn", _scene("cantilever_timo_03"), EngineSettings(segments=35))
    assert res.status == "skipped" and "sized by --modes" in res.message and "pybullet.11,pybullet.35" in res.message
    beam = _scene("ss_glass_wc_fast")
    res = execute_job("exudyn", beam, EngineSettings(segments=8))
    assert res.status == "ok" and res.settings["segments"] == 8
    default = execute_job("exudyn", beam, EngineSettings())
    assert default.settings["segments"] == 19 and res.model_error > 10 * default.model_error   # a coarser mesh
    res = execute_job("exudyn", beam, EngineSettings(segments=8, options=(("beam_elements", 9),)))
    assert res.status == "skipped" and "disagree" in res.message


@pytest.mark.slow
def test_sweep_text_never_prints_nan_or_an_empty_limit(tmp_path):
    """Exudyn on the Timoshenko cantilever: every cell skipped printed "best nan %" and "up to  s"; its implicit
    integrator (dt_limit inf) printed "predicted limit  s"."""
    pytest.importorskip("exudyn", reason="pip install 'impactval[exudyn]'")
    from impactval.cli import main

    runner = CliRunner()
    args = ["sweep", _path("cantilever_timo_03"), "--engines", "exudyn", "--dt", "4e-7,2e-7", "-j", "1"]
    res = runner.invoke(main, [*args, "--segments", "35", "--out", str(tmp_path / "skipped")])
    assert res.exit_code == 0, res.output
    md = (tmp_path / "skipped" / "sweep.md").read_text()
    assert "no cell has a result" in md and "no cell has a result" in res.output
    res = runner.invoke(main, [*args, "--out", str(tmp_path / "ok")])
    assert res.exit_code == 0, res.output
    md += (tmp_path / "ok" / "sweep.md").read_text()
    assert "no explicit stability limit (implicit integrator)" in md
    for bad in (r"\bnan\b", r"up to  s", r"limits?  s"):
        assert not re.search(bad, md + res.output, re.IGNORECASE), bad


def test_section_chain_is_sized_by_discretisation_not_by_the_rayleigh_shift():
    """MuJoCo `rotary_inertia=section` on the glass beam: the frequency criterion compared the Rayleigh chain with
    Euler-Bernoulli, whose high modes it never meets, and ran N to 375 (44x the default's stepping time; model
    error 0.29 %). The frequency criterion is now on the bar chain; the model-error criterion (chain_tol) still on
    the chain as built."""
    from impactval.engines.chain import DEFAULT_CHAIN_TOL, hencky_chain, model_error, segments_for

    scene = _scene("ss_glass_wc_fast")
    sized = segments_for(scene, rotary="section")
    assert sized.n <= 60 and sized.model_error.largest <= DEFAULT_CHAIN_TOL, (sized.n, sized.model_error)
    again = model_error(scene, hencky_chain(scene.target, sized.n, "section"))
    assert again.largest == pytest.approx(sized.model_error.largest, rel=1e-9)   # the chain as built
    assert segments_for(scene).n == 40          # the bar chain (MuJoCo centres the impact point in a segment: 41)


@pytest.mark.parametrize("command", ["run", "sweep", "nightly"])
def test_two_different_scenes_with_one_name_are_refused_before_any_write(tmp_path, command):
    """The glass-beam file and a copy at 2 m/s, both named ss_glass_wc_fast by their stem, ran as two rows that
    nothing told apart (the report showed one reference for both). Refused with one line (exit 2), nothing
    written; the same scene twice runs once."""
    from impactval.cli import main

    copy = tmp_path / "elsewhere" / "ss_glass_wc_fast.toml"
    copy.parent.mkdir()
    copy.write_text(Path(_path("ss_glass_wc_fast")).read_text().replace("velocity = 5.0", "velocity = 2.0"))
    out = tmp_path / "out"
    extra = ["--dt", "1e-7"] if command == "sweep" else []
    res = CliRunner().invoke(main, [command, _path("ss_glass_wc_fast"), str(copy), "--engines", "mujoco",
                                    "--out", str(out), *extra])
    assert res.exit_code == 2, res.output
    assert "two different scenes are named 'ss_glass_wc_fast'" in res.output and "Traceback" not in res.output
    assert not out.exists()
    from impactval.runner import unique_scenes

    same = [_scene("rigid_pmma_glass_fast"), _scene("rigid_pmma_glass_fast")]
    assert len(unique_scenes(same)) == 1


def test_rerendered_report_of_scene_files_finds_them_on_the_command_line(tmp_path, monkeypatch):
    """`impactval report DIR` of a run of scene files had no reference values ("not in the catalogue"): it now
    loads the *.toml files named on the stored command line (hash-checked against the rows)."""
    pytest.importorskip("mujoco", reason="pip install 'impactval[mujoco]'")
    from impactval.nightly import render_stored
    from impactval.runner import run

    monkeypatch.chdir(UNSEEN3.parent.parent)
    path = str(Path("tests/unseen3/rigid_pmma_glass_fast.toml"))
    run([path], ["mujoco"], out=tmp_path / "run", workers=1, progress=None,
        command=f"impactval run {path} --engines mujoco --out {tmp_path / 'run'}")
    render_stored(str(tmp_path / "run"), out=tmp_path / "again")
    md = (tmp_path / "again" / "report.md").read_text()
    assert "| rigid_pmma_glass_fast | 10.3836261 | 55.6559651 |" in md and "not in the catalogue" not in md
    monkeypatch.chdir(tmp_path)                      # the relative path no longer resolves: an honest note
    render_stored(str(tmp_path / "run"), out=tmp_path / "elsewhere")
    assert "re-render from the directory the run started in" in (tmp_path / "elsewhere" / "report.md").read_text()


def test_no_segment_count_on_targets_without_a_structure():
    """`run --segments 35` on the rigid PMMA plate, the two balls and the modal target printed N = 35 for every
    engine (nothing there has segments); a sweep's segments axis on a ball or modal scene made duplicate cells."""
    pytest.importorskip("mujoco", reason="pip install 'impactval[mujoco]'")
    from impactval.runner import make_row
    from impactval.sweep import build_jobs

    settings = EngineSettings(segments=35)
    # a modal target's N is the mode count the engine built (round 20: MuJoCo's one oscillator per mode, as Exudyn's
    # rows already said), never the asked --segments
    for name, n in (("rigid_pmma_glass_fast", ""), ("ball_ball_equal_ti", ""), ("modal_light_coupled", "3"),
                    ("ss_glass_wc_fast", "35")):
        scene = _scene(name)
        res = execute_job("mujoco", scene, settings)
        assert res.status == "ok", res.message
        row = make_row("run", scene, "mujoco", settings, res, impactval.solve(scene, tol=1e-6), None)
        assert row["segments"] == n, (name, row["segments"])
    scenes = [_scene("ball_ball_equal_ti"), _scene("modal_light_coupled"), _scene("ss_glass_wc_fast")]
    jobs = build_jobs(scenes, ["mujoco"], EngineSettings(dt=1e-7), segments={"mujoco": [21, 41]})
    assert [j.scene.name for j in jobs] == ["ball_ball_equal_ti", "modal_light_coupled", "ss_glass_wc_fast",
                                            "ss_glass_wc_fast"]


def test_a_job_that_newly_times_out_fails_the_night(tmp_path):
    """A night with --timeout 1 s after a good night: the timed-out rows carry no integrator and no N, so they
    matched no baseline row (`x`) and the night said "no regression", exit 0, with six newly failing jobs. They
    are now matched on the fields they could report: `!`, exit 1, and no phantom "engine version -> ?"."""
    pytest.importorskip("mujoco", reason="pip install 'impactval[mujoco]'")
    from impactval.cli import main

    runner = CliRunner()
    args = ["nightly", _path("ss_glass_wc_fast"), _path("rigid_pmma_glass_fast"), "--engines", "mujoco",
            "--out", str(tmp_path), "-j", "1"]
    first = runner.invoke(main, args)
    assert first.exit_code == 0, first.output
    second = runner.invoke(main, [*args, "--timeout", "0.001"])
    assert second.exit_code == 1, second.output
    assert "! ss_glass_wc_fast / mujoco" in second.output and "ok -> timeout" in second.output
    assert "x ss_glass_wc_fast" not in second.output and "-> ?" not in second.output
    third = runner.invoke(main, args)                       # runs again: against the timed-out night, fixed
    assert third.exit_code == 0, third.output
    from impactval import history
    from impactval.store import Store

    db = Store(tmp_path / "impactval.sqlite")
    ids = [ln.split()[2] for ln in (second.output + third.output).splitlines() if ln.startswith("nightly run ")]
    cmp = history.compare(db.rows(run_id=ids[1]), db.rows(run_id=ids[0]), 0.2)
    assert set(cmp.loc[cmp["scene"] == "ss_glass_wc_fast", "mark"]) == {"*"}, cmp[["scene", "mark", "why"]]
    db.close()
