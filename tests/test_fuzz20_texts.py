"""s20 fuzz report, findings 4, 6, 7, 8 and 9: texts that said more than the data showed."""
import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from impactval import sweep as sw
from conftest import requires_mujoco

# ---------------------------------------------------------------------------- finding 4: sweep floors


def _cells(errs_by_dt: dict, model_error: float = math.nan, refused=(), segments="65"):
    """One sweep series (MuJoCo Euler, N = segments): ok cells {dt: largest error} and cells refused before
    stepping at the dt in `refused`."""
    from impactval.engines.base import message

    base = dict(scene="c", engine="mujoco", contact="hertz", integrator="Euler", segments=segments,
                ref_t_m=1.0, ref_f_m=1.0, ref_delta_m=1.0, dt_limit=6.85e-7, model_error=model_error)
    rows = [dict(base, dt=dt, status="unstable", err_t_m=np.nan, err_f_m=np.nan, err_delta_m=np.nan, n_steps=0,
                 t_m=np.nan, f_m=np.nan, delta_m=np.nan,
                 wall_time_step_s=0.0, message=message("dt-limit", dt=dt, limit=6.85e-7, what="Euler, chain",
                                                       suggest=2e-7)[1]) for dt in refused]
    rows += [dict(base, dt=dt, status="ok", err_t_m=-e / 3, err_f_m=e, err_delta_m=e / 2, n_steps=int(5e-5 / dt),
                  t_m=1 - e / 3, f_m=1 + e, delta_m=1 + e / 2,
                  wall_time_step_s=0.5e-3 * 5e-5 / dt * 1e-3, message="") for dt, e in errs_by_dt.items()]
    return pd.DataFrame(rows)


def _floor_line(md: str) -> str:
    return next(ln for ln in md.splitlines() if ln.startswith("- **Floor**"))


def test_one_stable_step_at_the_model_error_is_the_structure_floor_not_still_falling():
    """s20 #4: 2e-6 and 1e-6 refused, 2e-7 stepped at 0.236 % with the chain's model error 0.235 %: the sweep said
    "not reached in this grid (...; still falling: refine dt)"; one step shows no trend and the error is the floor."""
    from impactval.reports.sweep import sweep_markdown

    df = _cells({2e-7: 2.36e-3}, model_error=2.35e-3, refused=(2e-6, 1e-6))
    f = sw.floors(df, {"c": "beam"}).iloc[0]
    assert f["cause_kind"] == "structure discretisation", f["cause"]
    assert "own model-error estimate (0.235 % for N = 65)" in f["cause"], f["cause"]
    assert "one stable step in this grid cannot show a trend" in f["cause"], f["cause"]
    line = _floor_line(sweep_markdown(df, [0.01], {"c": "beam"}))
    assert "still falling" not in line and "refine dt" not in line, line
    assert "N = 65: 0.236 % at 2e-07 s" in line and "refining dt will not lower it" in line, line


def test_one_stable_step_without_a_model_error_says_it_cannot_tell():
    from impactval.reports.sweep import sweep_markdown

    df = _cells({2e-7: 2.36e-3}, refused=(2e-6, 1e-6))
    f = sw.floors(df, {"c": "beam"}).iloc[0]
    assert f["cause_kind"] == "one stable step" and not f["reached"], f["cause"]
    line = _floor_line(sweep_markdown(df, [0.01], {"c": "beam"}))
    assert "one stable step in this grid cannot show a trend in dt" in line, line
    assert "still falling" not in line, line


def test_still_falling_down_to_the_model_error_is_the_structure_floor():
    """Several steps, the last one still 30 % lower than the one before, but already at the model error: the
    model-error test comes before "no floor ... refine dt"."""
    df = _cells({1e-6: 9e-3, 5e-7: 4e-3, 2.5e-7: 3.1e-3}, model_error=-3.0e-3, segments="41")
    f = sw.floors(df, {"c": "beam"}).iloc[0]
    assert not f["reached"] and f["cause_kind"] == "structure discretisation", f["cause"]
    assert "does not show the error level off" in f["cause"], f["cause"]
    # away from the model error it still falls: unchanged
    far = sw.floors(_cells({1e-6: 9e-3, 5e-7: 4e-3, 2.5e-7: 2e-3}, model_error=-3.0e-4), {"c": "beam"}).iloc[0]
    assert far["cause_kind"] == "no floor" and "refine dt further" in far["cause"]


SMALL_BEAM = """description = "steel ball 5 mm on a simply supported aluminium beam (unseen, s20 #4)"
[ball]
radius = 0.0025
velocity = 0.5
material = "steel"
[target]
kind = "beam"
material = "aluminium"
support = "simply-supported"
length = 0.12
width = 0.01
height = 0.004
impact_at = 0.35
"""


@requires_mujoco
def test_sweep_command_with_one_stable_step_names_the_structure_floor(tmp_path):
    """s20 #4 and #9 end to end (MuJoCo, ~6 s): 2e-6 and 1e-6 are refused (predicted limit ~3.7e-7 s), 2e-7 runs at
    the chain's own model error. sweep.md must not say "still falling: refine dt"; orders.csv's dt_limit_observed
    is empty (nothing was stepped unstable)."""
    from click.testing import CliRunner

    from impactval.cli import main

    scene = tmp_path / "ssb.toml"
    scene.write_text(SMALL_BEAM)
    out = tmp_path / "sw"
    res = CliRunner().invoke(main, ["sweep", str(scene), "--engines", "mujoco", "--dt", "2e-6,1e-6,2e-7", "--under",
                                    "1%", "-j", "1", "--out", str(out), "--no-plot"])
    assert res.exit_code == 0, res.output
    md = (out / "sweep.md").read_text()
    line = _floor_line(md)
    assert "still falling" not in line and "refine dt" not in line, line
    assert "one stable step in this grid cannot show a trend in dt" in line, line
    assert "own model-error estimate" in line and "refining dt will not lower it" in line, line
    orders = pd.read_csv(out / "orders.csv")
    assert orders["dt_limit_observed"].isna().all() and (orders["dt_refused_min"] == 1e-6).all(), orders


# ---------------------------------------------------------------------------- finding 9: dt_limit_observed
def test_dt_limit_observed_is_empty_when_the_only_unstable_cells_were_refused(tmp_path):
    refused_only = _cells({2e-7: 2.36e-3}, model_error=2.35e-3, refused=(2e-6, 1e-6))
    o = sw.orders_table(refused_only, {"c": "beam"})
    assert "dt_limit_observed" in o.columns                    # the column keeps its name (older readers)
    assert o["dt_limit_observed"].isna().all() and (o["dt_refused_min"] == 1e-6).all()
    o.to_csv(tmp_path / "orders.csv", index=False)
    assert pd.read_csv(tmp_path / "orders.csv")["dt_limit_observed"].isna().all()
    stepped = pd.concat([refused_only, _cells({5e-7: np.nan})]).reset_index(drop=True)
    stepped.loc[stepped["dt"] == 5e-7, ["status", "message", "n_steps"]] = ["unstable", "NaN/inf after 41 steps", 41]
    s = sw.stability(stepped).iloc[0]
    assert s["dt_limit_observed"] == 5e-7 == s["dt_unstable_stepped"] and s["dt_stable_max"] == 2e-7


# ---------------------------------------------------------------------------- finding 6: reference --explain
HEAVY_BALL = """description = "heavy steel ball on a slender aluminium cantilever (unseen, s20 #6)"
[ball]
radius = 0.02
velocity = 0.2
material = "steel"
[target]
kind = "beam"
material = "aluminium"
support = "cantilever"
length = 0.3
width = 0.015
height = 0.004
impact_at = 0.6
"""


def test_explain_prints_na_where_the_first_order_expansion_does_not_apply(tmp_path):
    """s20 #6: --explain printed "structure effect (first order): t_m -393.397 %, f_m -2189.858 %" where
    --model perturbation prints n/a; both use reference.validity.perturbation_validity now."""
    from click.testing import CliRunner

    from impactval.cli import main

    scene = tmp_path / "heavy.toml"
    scene.write_text(HEAVY_BALL)
    res = CliRunner().invoke(main, ["reference", str(scene), "--explain", "--tol", "1e-4"])
    assert res.exit_code == 0, res.output
    line = next(ln for ln in res.output.splitlines() if "structure effect (first order)" in ln)
    assert "structure effect (first order): n/a (first-order shift of f_m is" in line, line
    assert "(<= -100 %): the light-ball expansion does not apply to this scene" in line, line
    assert "t_m -" not in line and "rigid plate enough at tol 0.0001: no" in line, line
    pert = CliRunner().invoke(main, ["reference", str(scene), "--model", "perturbation", "--tol", "1e-4"])
    assert pert.exit_code == 0, pert.output
    reason = line.split("n/a (", 1)[1].rsplit("); rigid plate", 1)[0]
    assert f"! perturbation: {reason}" in pert.output and " n/a " in pert.output, pert.output


# ---------------------------------------------------------------------------- finding 7: extremes warnings
def test_extremes_reference_warnings_name_their_cell():
    from impactval.extremes import Axis
    from impactval.reports.extremes import markdown

    v = [0.01, 100.0, 0.01, 100.0]
    df = pd.DataFrame(dict(engine=["e"] * 4, velocity=v, dt=[1e-7, 1e-7, 1e-6, 1e-6],
                           scene=[f"s[v={x:g}]" for x in v], cell_status=["ok"] * 4, ref_uncertainty=[1e-9] * 4,
                           dt_limit=[1e-5] * 4, max_abs_err=[1e-3] * 4,
                           ref_validity=["", "Hertz: delta_m is 8.04 % of R; yield: p0 = 10.5 GPa"] * 2))
    df.attrs.update(axes=[Axis("velocity", (0.01, 100.0), "m/s"), Axis("dt", (1e-7, 1e-6), "s")], under=0.01,
                    tol=1e-6, scene="s", engines=["e"])
    md = markdown(df)
    part = md.split("## Where the reference's assumptions fail")[1].strip().splitlines()
    assert part == ["- velocity = 100 m/s: Hertz: delta_m is 8.04 % of R; yield: p0 = 10.5 GPa"], part


@requires_mujoco
def test_extremes_command_prefixes_each_bullet_with_its_velocity(tmp_path):
    """s20 #7 end to end: an aluminium ball on a rigid plate at 0.5 and 60 m/s (unseen); only 60 m/s breaks
    small-strain Hertz, and its bullet says so."""
    from click.testing import CliRunner

    from impactval.cli import main

    scene = tmp_path / "al_plate.toml"
    scene.write_text('description = "Al ball 12 mm on a rigid plate (unseen, s20 #7)"\n[ball]\nradius = 0.006\n'
                     'velocity = 1.0\nmaterial = "aluminium"\n[target]\nkind = "rigid-plate"\nmaterial = "steel"\n')
    out = tmp_path / "ext"
    res = CliRunner().invoke(main, ["extremes", str(scene), "--engines", "mujoco", "--axis", "velocity=0.5,60",
                                    "--axis", "dt=t_m/200", "-j", "1", "--out", str(out)])
    assert res.exit_code == 0, res.output
    md = (out / "extremes.md").read_text()
    bullets = [ln for ln in md.split("## Where the reference's assumptions fail")[1].splitlines()
               if ln.startswith("- ")]
    assert bullets and all(b.startswith("- velocity = ") for b in bullets), bullets
    assert any(b.startswith("- velocity = 60 m/s: ") and "Hertz" in b for b in bullets), bullets


# ---------------------------------------------------------------------------- finding 8: tune progress
@pytest.mark.parametrize("quantities, words", [(("t_m", "f_m"), "largest fitted |error| (t_m, f_m) 19.6 %"),
                                               (("t_m", "f_m", "delta_m"),
                                                "largest fitted |error| (t_m, f_m, delta_m) 24.6 %")])
def test_tune_progress_line_names_the_fitted_metrics(quantities, words):
    """s20 #8: "largest |error| 19.6 %" while tune.md showed delta_m -24.6 %: MuJoCo's objective fits t_m and f_m."""
    from impactval.cli_tune import _evaluation_line

    objective = SimpleNamespace(quantities=quantities, speeds=[0.5, 2.0], phase="fit",
                                record=SimpleNamespace(evaluations=4, engine_runs=8, jobs_reused=0))
    res = np.array([0.196, -0.05, 0.1, 0.02] if len(quantities) == 2 else [0.196, -0.05, -0.246, 0.1, 0.02, 0.0])
    line = _evaluation_line(objective, {"solref": "-1,0"}, res, 30)
    assert words + " over 2 speeds; 8 engine runs, 0 reused" in line, line
