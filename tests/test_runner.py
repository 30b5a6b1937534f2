"""`impactval.runner.run` / `impactval run`: rows, statuses, isolation, files (issue 4)."""
import csv
import math

import numpy as np
import pytest
from click.testing import CliRunner

import impactval
import impactval.cli
from conftest import requires_mujoco
from impactval.compare import curve_error, relative_errors
from impactval.errors import EngineError
from impactval.runner import run
from impactval.store import EXPORT_COLUMNS


@pytest.fixture(scope="module")
def plate_ref():
    return impactval.solve(impactval.load_scene("plate_steel"), tol=1e-6)


def test_curve_error_is_zero_for_itself_and_scales(plate_ref):
    from dataclasses import replace

    assert curve_error(plate_ref, plate_ref) == pytest.approx(0.0, abs=1e-12)
    scaled = replace(plate_ref, f=plate_ref.f * 1.01)
    c = plate_ref.contacts[0]
    inside = (plate_ref.t >= c.t_start) & (plate_ref.t <= c.t_end)
    t, f = plate_ref.t[inside], plate_ref.f[inside]
    expected = 0.01 * math.sqrt(np.trapezoid(f**2, t) / (t[-1] - t[0])) / plate_ref.f_m if hasattr(np, "trapezoid") \
        else 0.01 * math.sqrt(np.trapz(f**2, t) / (t[-1] - t[0])) / plate_ref.f_m
    assert curve_error(scaled, plate_ref) == pytest.approx(expected, rel=1e-9)
    assert 0.005 < expected < 0.01          # RMS of a half-wave below its peak
    e = relative_errors(replace(plate_ref, t_m=plate_ref.t_m * 1.02), plate_ref)
    assert e["t_m"] == pytest.approx(0.02) and e["f_m"] == 0.0


def test_unknown_engine_is_a_clear_error():
    with pytest.raises(EngineError, match=r"unknown engine 'mujuco'; known: mujoco, pybullet, exudyn"):
        run(["plate_steel"], ["mujuco"])
    res = CliRunner().invoke(impactval.cli.main, ["run", "plate_steel", "--engines", "mujuco"])
    assert res.exit_code == 2 and "unknown engine 'mujuco'" in res.output


def test_missing_engine_is_a_not_installed_row(monkeypatch, tmp_path):
    import impactval.runner as runner

    monkeypatch.setitem(runner.ENGINE_MODULES, "mujoco", "no_such_engine_module_xyz")
    df = run(["plate_steel"], ["mujoco"], out=tmp_path)
    assert list(df["status"]) == ["not-installed"]
    assert "pip install 'impactval[mujoco]'" in df["message"][0]
    assert not runner.any_failed(df)


@requires_mujoco
def test_killed_engine_leaves_crashed_row_and_the_others(tmp_path):
    """Issue 4 bar: an engine process killed mid-run is a `crashed` row; the other rows are there.
    An engine named twice runs once: one row in the DataFrame and in the export (until round 20 two equal rows in
    the DataFrame, so the table and the summary counted it twice)."""
    df = run(["plate_steel"], ["mujoco", "fake_engines:KillSelf", "mujoco"], dt=1e-6, timeout_s=120, out=tmp_path)
    assert list(df["status"]) == ["ok", "crashed"]
    assert "SIGKILL" in df["message"][1]
    assert abs(df["err_f_m"][0]) < 5e-4
    with (tmp_path / "results.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert sorted((r["engine"], r["status"]) for r in rows) == [("KillSelf", "crashed"), ("mujoco", "ok")]
    assert list(rows[0]) == list(EXPORT_COLUMNS)
    report = (tmp_path / "report.md").read_text()
    assert "| plate_steel | mujoco |" in report and "**crashed**" in report


def test_hanging_engine_is_a_timeout_row():
    df = run(["plate_steel"], ["fake_engines:Hang"], timeout_s=3)
    assert list(df["status"]) == ["timeout"]
    assert "no result after 3 s" in df["message"][0]


@requires_mujoco
def test_native_rows_compare_with_linear_theory(plate_ref):
    """A native (linear) row carries its error against the linear-theory reference for the same
    spring; on the plate that is the closed-form sine, bar 0.1 %."""
    df = run(["plate_steel"], "mujoco", contact="native", tol=1e-7)
    r = df.iloc[0]
    assert r["status"] == "ok"
    pytest.importorskip("impactval.reference.linear")
    scene = impactval.load_scene("plate_steel")
    omega0 = math.sqrt(r["contact_stiffness"] / scene.ball.mass)
    assert r["lin_t_m"] == pytest.approx(math.pi / omega0, rel=1e-6)
    for k in ("lin_err_t_m", "lin_err_f_m", "lin_err_delta_m"):
        assert abs(r[k]) <= 1e-3
    assert r["err_f_m"] == pytest.approx(-0.2, abs=0.002)     # linear spring: 4/5 of Hertz's peak force
    assert r["lin_err_curve"] < 2e-3


@requires_mujoco
def test_cli_run_writes_files_and_exit_codes(tmp_path):
    out = tmp_path / "o"
    res = CliRunner().invoke(impactval.cli.main, ["run", "plate_steel", "--engines", "mujoco", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "plate_steel" in res.output and "t_m %" in res.output
    assert (out / "results.csv").exists() and (out / "report.md").exists()
    res = CliRunner().invoke(impactval.cli.main, ["run", "plate_steel", "--engines", "fake_engines:KillSelf",
                                                  "--out", str(out)])
    assert res.exit_code == 1
    with (out / "results.csv").open() as fh:
        # the export covers every job run into this --out, each once
        assert sorted(r["status"] for r in csv.DictReader(fh)) == ["crashed", "ok"]


@requires_mujoco
def test_settings_no_engine_accepts_are_bad_input():
    with pytest.raises(EngineError, match="unknown integrator 'euler'"):
        run(["plate_steel"], ["mujoco"], integrator="euler")
    res = CliRunner().invoke(impactval.cli.main, ["run", "plate_steel", "--integrator", "rk4"])
    assert res.exit_code == 2 and "unknown integrator 'rk4'" in res.output


@requires_mujoco
def test_unsupported_scene_is_a_skipped_row():
    df = run(["modal_two_mode"], ["mujoco"], contact="native")
    assert list(df["status"]) == ["skipped"] and "modal target" in df["message"][0]


def test_engine_prefixed_options_reach_only_that_engine():
    from impactval.engines.base import EngineSettings
    from impactval.runner import settings_for
    s = EngineSettings(options=(("exudyn.beam_model", "reference-modes"), ("max_time", 1e-4),
                                ("pybullet.native_route", "per-body")))
    assert dict(settings_for(s, "exudyn").options) == {"beam_model": "reference-modes", "max_time": 1e-4}
    assert dict(settings_for(s, "pybullet").options) == {"native_route": "per-body", "max_time": 1e-4}
    assert dict(settings_for(s, "mujoco").options) == {"max_time": 1e-4}


def test_cli_option_syntax_error_is_one_line(tmp_path):
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines", "mujoco",
                          "--option", "nonsense", "--out", str(tmp_path)], capture_output=True, text=True)
    assert out.returncode == 2 and "--option takes KEY=VALUE" in out.stderr and "Traceback" not in out.stderr


@requires_mujoco
def test_dt_sweep_rows_table_and_plot(tmp_path):
    """Several time steps: one row per dt, a speed/accuracy table and a plot; errors fall with dt."""
    from impactval.runner import run
    df = run(["plate_steel"], ["mujoco"], dt=[1e-6, 2.5e-7], tol=1e-7, out=tmp_path)
    assert sorted(df["dt"]) == [2.5e-7, 1e-6] and (df["status"] == "ok").all()
    err = df.set_index("dt")["err_f_m"].abs()
    assert err[2.5e-7] < err[1e-6] / 4                  # first-order-or-better in dt on the plate
    report = (tmp_path / "report.md").read_text()
    assert "## Speed against accuracy" in report and "speed_accuracy.png" in report
    assert (tmp_path / "speed_accuracy.png").stat().st_size > 1000


@requires_mujoco
def test_dt_sweep_where_every_step_fails_still_writes_its_plots(tmp_path):
    """Every dt of a run unstable (a user's 1.3 m WC cantilever under a glass ball: Exudyn's energy grew at 1e-7 and
    5e-8 s) left the speed/accuracy panel without a positive value: matplotlib's log axes raised and the run ended in
    an internal error with no results.csv. Here both steps are above MuJoCo's predicted limit (refused, no stepping
    time either): the run writes its files, the plots say the cells have no error."""
    from impactval.reports.sweep import plot_error_vs_dt
    from impactval.runner import run

    df = run(["plate_steel"], ["mujoco"], dt=[1e-3, 5e-4], out=tmp_path)
    assert (df["status"] == "unstable").all() and df["err_f_m"].isna().all()
    assert (tmp_path / "results.csv").is_file() and (tmp_path / "speed_accuracy.png").stat().st_size > 1000
    paths = plot_error_vs_dt(df, [], tmp_path / "vs_dt")
    assert {p.suffix for p in paths} == {".png", ".svg"} and "no cell gave an error" in (tmp_path / "vs_dt.svg").read_text()


def test_cli_bad_dt_list_is_one_line(tmp_path):
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--dt", "1e-6,abc",
                          "--out", str(tmp_path)], capture_output=True, text=True)
    assert out.returncode == 2 and "--dt" in out.stderr and "'abc' is not a number" in out.stderr and len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr


def test_unexplained_error_note_names_the_structure_model_under_a_linear_spring():
    """A row whose error against the linear theory is beyond its Hertz-measured structure estimate (a capped chain
    under a linear spring: MuJoCo Warp on heavy_wc_slender_timoshenko, t_m +14.9 % where the Hertz estimate is
    +0.23 %) names the structure model under the spring as a cause, not only the time step; against the Hertz
    reference the note keeps naming the time step."""
    from impactval.reference.result import ImpactResult
    from impactval.runner import row_notes

    res = ImpactResult(scene="s", source="fake", model="chain", t_m=1.0, f_m=1.0, delta_m=1.0, dt=5e-7)
    structure = {"t_m": 0.0023, "f_m": -0.0049, "delta_m": -0.0033}
    err = {"t_m": 0.149, "f_m": -0.0056, "delta_m": -0.0057}
    linear = " ".join(row_notes(res, err, structure, True, against="the linear theory"))
    assert "t_m +14.90 %" in linear and "structure model under this spring" in linear and "more segments" in linear
    assert "f_m" not in linear.split("(")[1].split(")")[0]          # f_m and delta_m are within the estimate
    hertz = " ".join(row_notes(res, err, structure, True))
    assert "try a smaller --dt" in hertz and "under this spring" not in hertz


@pytest.mark.slow
@requires_mujoco
def test_a_scene_whose_reference_is_refused_keeps_its_rows_and_the_run_goes_on(tmp_path, monkeypatch):
    """A reference the solver refuses (here the heavy ball on the slender beam at tol 1e-12: over its node budget,
    ~14 s) aborted the whole run with exit 2 once its first row finished (a user's thin PMMA plate under a 0.95 kg
    ball at tol 1e-6). Now that scene's engine rows are stored with their own numbers and no errors, the message
    names the refusal, the other scenes are compared as usual, and the run exits 1 (a row nobody checked). The report
    takes the run's references (the refusal included) instead of solving each scene again: one refusal is paid once."""
    import impactval
    from impactval.compare import NO_REFERENCE
    from impactval.runner import any_failed

    real_solve, calls = impactval.solve, []

    def counted(scene, *args, **kwargs):        # the real solver, its calls on the heavy-ball scene counted
        if scene.name == "heavy_ball_slender_beam" and scene.target.theory == "euler-bernoulli":
            calls.append(kwargs.get("tol"))
        return real_solve(scene, *args, **kwargs)

    monkeypatch.setattr(impactval, "solve", counted)
    df = run(["heavy_ball_slender_beam", "plate_steel"], ["mujoco"], tol=1e-12, out=tmp_path)
    assert calls == [1e-12]
    heavy, plate = df.iloc[0], df.iloc[1]
    assert heavy["status"] == "ok" and math.isfinite(heavy["t_m"]) and math.isnan(heavy["err_t_m"])
    assert math.isnan(heavy["ref_t_m"]) and heavy["message"].startswith(NO_REFERENCE)
    assert "steps" in heavy["message"] and "looser tol" in heavy["message"]
    assert plate["status"] == "ok" and abs(plate["err_f_m"]) < 5e-4
    assert any_failed(df) and not any_failed(df.iloc[[1]])
    report = (tmp_path / "report.md").read_text()
    assert "heavy_ball_slender_beam: no reference at tol 1e-12" in report


@pytest.fixture(scope="module")
def grazing():
    """A 3 kg aluminium ball at 30.8 m/s near a clamp of a 250 x 25 x 9.8 mm WC beam (a random user scene): the
    reference separates at 430 us and re-touches 15 us later. Returns (scene, first-contact reference, reference with
    a window showing the re-contact)."""
    from impactval.scenarios.scene import scene_from_dict

    sc = scene_from_dict({"name": "grazing", "ball": {"radius": 0.064468, "velocity": 30.8, "material": "aluminium"},
                          "target": {"kind": "beam", "material": "tungsten-carbide", "support": "clamped-clamped",
                                     "length": 0.25031, "width": 0.025154, "height": 0.0098014, "impact_at": 0.1603}})
    return sc, impactval.solve(sc, tol=1e-6), impactval.solve(sc, tol=1e-6, window=1e-4)


def _bridged(ref_window, floor: float):
    """`ref_window` with the force held at least `floor` x f_m from where the first contact's falls below it to where
    the second's rises above it (one contact)."""
    from dataclasses import replace

    from impactval.reference.result import Contact

    c1, c2 = ref_window.contacts[:2]
    t, low = ref_window.t, ref_window.f < floor * ref_window.f_m
    start = np.flatnonzero((t < c1.t_end) & ~low)[-1]          # the first contact's last node above the floor
    stop = np.flatnonzero((t > c2.t_start) & ~low)[0]          # the second's first
    f = ref_window.f.copy()
    f[start + 1:stop] = floor * ref_window.f_m
    return replace(ref_window, f=f, contacts=(Contact(c1.t_start, c2.t_end, c1.f_max, c1.delta_max),),
                   t_m=c2.t_end - c1.t_start)


def test_contact_cut_names_a_bridged_or_split_separation(grazing):
    """t_m of a near-grazing contact: an engine whose force stays at 0.5 % of f_m through the reference's 15 us gap
    reports one contact 13.6 % longer; the row says it bridged a separation (and, the other way round, that a contact
    which separates where the other's force only dips was split). No note for the same contact, or for a contact that
    ends as late without a dip (a real t_m error), or for a dip of 5 % of f_m."""
    from impactval.compare import contact_cut

    _, ref, ref_w = grazing
    assert ref_w.contacts[1].t_start - ref.contacts[0].t_end < 0.05 * ref.t_m      # the re-contact follows closely
    merged = _bridged(ref_w, 0.005)
    assert merged.t_m / ref.t_m - 1 > 0.1
    note = contact_cut(merged, ref)
    assert "bridged a separation the reference makes" in note and "0.5 % of its f_m" in note
    assert "split a contact the reference keeps" in contact_cut(ref, merged)
    assert contact_cut(ref, ref) == "" and contact_cut(_bridged(ref_w, 0.05), ref) == ""
    from dataclasses import replace

    stretched = replace(ref, t=ref.t * 1.1, contacts=tuple(replace(c, t_end=c.t_end * 1.1) for c in ref.contacts))
    assert contact_cut(stretched, ref) == ""


def test_contact_cut_is_silent_for_an_early_separation_without_a_dip(grazing):
    """An engine whose contact ends after 5 % of the reference's (a step past its stability limit) has no dip of the
    reference's force next to its end, only the rise at touch: no note (found on a map past dt_limit, where the
    touch's zero force read as a 'split')."""
    from dataclasses import replace

    from impactval.compare import contact_cut

    _, ref, _ = grazing
    early = ref.t <= 0.05 * ref.t_m
    short = replace(ref, t=ref.t[early], f=ref.f[early],
                    contacts=(replace(ref.contacts[0], t_end=float(ref.t[early][-1])),))
    assert short.contacts[0].t_end < 0.06 * ref.t_m
    assert contact_cut(short, ref) == ""


@requires_mujoco
def test_speed_table_names_integrator_and_n_and_shows_a_refused_step_as_not_run(tmp_path):
    """`run --dt a,b` on a beam: the speed/accuracy table has the integrator and N of each row (a re-rendered sweep
    had rows told apart by nothing), and a dt refused above the chain's predicted limit shows '-' for its time and
    steps and says it was refused, instead of '0 ms, 0 steps' as if it had run."""
    from impactval.runner import run

    df = run(["beam_ss_midspan"], ["mujoco"], dt=[2e-7, 1e-5], out=tmp_path)
    fine, coarse = df.sort_values("dt").iloc[0], df.sort_values("dt").iloc[1]
    assert fine["status"] == "ok" and coarse["status"] == "unstable" and coarse["n_steps"] == 0
    report = (tmp_path / "report.md").read_text()
    table = report[report.index("## Speed against accuracy"):]
    assert "| integrator | N | dt [s] |" in table
    n = str(fine["segments"]).removesuffix(".0")
    assert f"| beam_ss_midspan | mujoco | {fine['integrator']} | {n} | 1e-05 |  | - | - | unstable (refused before " \
           f"stepping) |" in table, table
    assert f"| {fine['integrator']} | {n} | 2e-07 | " in table
