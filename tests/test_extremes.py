"""Stability maps at the extremes (issue 14): axes, scene variants, cell statuses, a map that
survives a crashing and a hanging engine, the CLI, and the bar: the observed first-unstable dt of
MuJoCo and PyBullet within a factor 2 of the predicted dt_limit, on the rigid plate and on a beam
the engines were not tuned on (tests/extremes/beam_titanium_ss_04.toml)."""
import importlib.util
import math
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

import impactval
import impactval.cli
from conftest import has_mujoco, has_pybullet, requires_mujoco
from impactval.engines.base import EngineSettings
from impactval.errors import ImpactvalError
from impactval.extremes import (Axis, CellStatus, classify, first_omega, impact_omega, onsets, parse_axis,
                                perturbations, predicted_limits, run_map, structure_mass, vary)

UNSEEN_BEAM = Path(__file__).parent / "extremes" / "beam_titanium_ss_04.toml"
FAKE = "impactval.engines.fake_:HertzSpringAdapter"
FAKE_EXPLICIT = "impactval.engines.fake_:ExplicitHertzSpringAdapter"    # closed form, declared explicit


@pytest.fixture(scope="module")
def beam():
    return impactval.load_scene(UNSEEN_BEAM)


# ---------------------------------------------------------------------------- axes
def test_dt_axis_default_and_t_m_tokens():
    t_m = 4e-5
    ax = parse_axis("dt", t_m)
    assert len(ax.values) == 13 and ax.log and ax.unit == "s"
    assert ax.values[0] == pytest.approx(t_m / 1e4) and ax.values[-1] == pytest.approx(t_m)
    ratios = [b / a for a, b in zip(ax.values, ax.values[1:])]
    assert max(ratios) == pytest.approx(min(ratios)) == pytest.approx(10 ** (4 / 12))
    ax = parse_axis("dt=t_m/100:0.5*t_m:3", t_m)
    assert ax.values == pytest.approx((4e-7, math.sqrt(4e-7 * 2e-5), 2e-5))
    assert parse_axis("velocity=2,0.5,1").values == (0.5, 1.0, 2.0)
    assert parse_axis("target.height=0.01:0.04:3").values == (0.01, 0.02, 0.04)        # a:b:n is log-spaced
    assert parse_axis("target.height=0.01,0.015,0.02").values == (0.01, 0.015, 0.02)  # linear: a list
    assert parse_axis("stiffness=pmma,1e13").values == ("pmma", 1e13)


@pytest.mark.parametrize("text, match", [
    ("speed=1:2:3", r"unknown axis 'speed'; known: dt, velocity"),
    ("velocity=-1,2", r"values must be positive"),
    ("dt=1e-3:1:3", r"time steps must be <= 0.01 s"),
    ("stiffness=rubber", r"'rubber' is neither a material"),
    ("velocity=1:2:x", r"--axis velocity: in a:b:n, n is a whole number"),
    ("velocity=1..2", r"LO..HI\[:N\] is no longer read; .* e.g. --axis velocity=1:2:9"),
    ("ball.radius", r"give values"),
])
def test_bad_axis_is_one_line_error(text, match):
    with pytest.raises(ImpactvalError, match=match):
        parse_axis(text, 4e-5)


# ---------------------------------------------------------------------------- scene variants
def test_variants_set_what_they_say(beam):
    v = vary(beam, parse_axis("velocity=3"), 3.0)
    assert v.ball.velocity == 3.0 and v.target == beam.target
    t = beam.target
    m_beam = 4430.0 * 0.012 * 0.008 * 0.35                      # titanium rho * A * L, by hand
    assert structure_mass(beam) == pytest.approx(m_beam)
    assert vary(beam, parse_axis("mass_ratio=0.5"), 0.5).ball.mass == pytest.approx(0.5 * m_beam)
    soft = vary(beam, parse_axis("stiffness=pmma"), "pmma")
    e, nu = 3.1e9, 0.37                                           # pmma on pmma: E* = E / (2 (1 - nu^2))
    assert soft.e_star == pytest.approx(e / (2 * (1 - nu**2)))
    assert soft.ball.mass == beam.ball.mass and soft.target.material.density == t.material.density
    for ratio in (0.05, 3.0):
        f = vary(beam, parse_axis(f"frequency_ratio={ratio}"), ratio)
        assert first_omega(f) / impact_omega(f) == pytest.approx(ratio, rel=1e-6)
    h = vary(beam, parse_axis("target.height=0.02"), 0.02)
    assert h.target.height == 0.02 and h.target.length == t.length


def test_bad_variants_name_the_field(beam, plate_scene):
    with pytest.raises(ImpactvalError, match=r"no numeric field 'support'"):
        vary(beam, Axis("target.support", (1.0,)), 1.0)
    with pytest.raises(ImpactvalError, match=r"impact_at must be a fraction"):
        vary(beam, Axis("target.impact_at", (1.5,)), 1.5)
    with pytest.raises(ImpactvalError, match=r"rigid-plate target has no finite mass"):
        vary(plate_scene, Axis("mass_ratio", (1.0,)), 1.0)
    with pytest.raises(ImpactvalError, match=r"has no vibration modes"):
        vary(plate_scene, Axis("frequency_ratio", (1.0,)), 1.0)


# ---------------------------------------------------------------------------- statuses and limits
def test_classify_by_under():
    row = dict(status="ok", err_t_m=0.004, err_f_m=-0.012, err_delta_m=0.0)
    assert classify(row, 0.01) is CellStatus.INACCURATE
    assert classify(row, 0.02) is CellStatus.OK
    assert classify(dict(status="ok", err_t_m=math.nan, err_f_m=math.nan, err_delta_m=math.nan), 1.0) \
        is CellStatus.INACCURATE
    for s in ("unstable", "no-contact", "crashed", "timeout"):
        assert classify(dict(status=s), 0.01).value == s


def test_predicted_limits_of_the_contact_spring(plate_scene, plate):
    """Ball on the Hertz spring's tangent stiffness at f_m: 2 / sqrt(1.5 alpha delta_m^0.5 / m)."""
    lim = predicted_limits(FAKE, plate_scene, EngineSettings(dt=1e-7), plate.delta_m)
    k = 1.5 * plate_scene.alpha * math.sqrt(plate.delta_m)
    assert lim.dt_contact == pytest.approx(2 / math.sqrt(k / plate_scene.ball.mass), rel=1e-9)
    assert lim.dt_tunnel == pytest.approx(plate.delta_m / plate_scene.ball.velocity)


def test_onsets_need_every_larger_step_broken():
    df = pd.DataFrame(dict(engine=["e"] * 5, dt=[1, 2, 3, 4, 5], dt_limit=[3.5] * 5, dt_limit_what=[""] * 5,
                           cell_status=["ok", "unstable", "ok", "unstable", "unstable"]))
    df.attrs["axes"] = [Axis("dt", (1, 2, 3, 4, 5))]
    (o,) = onsets(df)
    assert o.first_unstable == 4 and o.largest_ok == 3 and o.ratio == pytest.approx(4 / 3.5)
    assert not o.whole_axis
    df["cell_status"] = "unstable"
    (o,) = onsets(df)
    assert o.whole_axis and o.first_unstable == 1 and math.isnan(o.largest_ok)


# ---------------------------------------------------------------------------- maps
def test_map_with_crashing_and_hanging_cells_finishes():
    """Bar: one engine crashes (SIGKILL) in every cell, one hangs; every other cell has its status."""
    df = run_map(impactval.load_scene("plate_steel"), [FAKE, "fake_engines:KillSelf", "fake_engines:Hang"],
                 [parse_axis("velocity=0.5,2")], settings=EngineSettings(timeout_s=4), workers=2)
    got = {(r.engine, r.velocity): r.cell_status for r in df.itertuples()}
    assert got == {(FAKE, 0.5): "ok", (FAKE, 2.0): "ok",
                   ("fake_engines:KillSelf", 0.5): "crashed", ("fake_engines:KillSelf", 2.0): "crashed",
                   ("fake_engines:Hang", 0.5): "timeout", ("fake_engines:Hang", 2.0): "timeout"}
    ok = df[df["engine"] == FAKE]
    assert (ok["max_abs_err"] < 1e-3).all()               # the closed-form adapter matches the reference
    assert (ok["ref_t_m"].iloc[0] / ok["ref_t_m"].iloc[1]) == pytest.approx(4 ** 0.2, rel=1e-6)   # t_m ~ v0^-1/5


def test_dt_axis_steps_past_the_limit_and_a_failed_reference_is_a_status(monkeypatch):
    """An explicit dt above the predicted limit is stepped (impactval.unguarded), not refused; a
    cell whose reference fails is "no-reference" and its engines are not run."""
    scene = impactval.load_scene("plate_steel")
    lim = predicted_limits(FAKE_EXPLICIT, scene, EngineSettings(dt=1e-7), 1e-5).dt_limit
    assert 0 < lim < 1e-4
    df = run_map(scene, [FAKE_EXPLICIT], [parse_axis(f"dt={lim / 4:.6g},{2 * lim:.6g}")], workers=1)
    assert list(df["status"]) == ["ok", "ok"]          # the analytic adapter is stable at any step
    assert "refused" not in " ".join(df["message"])
    assert df["limit_ratio"].tolist() == pytest.approx([0.25, 2.0], rel=1e-5)
    guarded = run_map(scene, [FAKE_EXPLICIT], [parse_axis(f"dt={2 * lim:.6g}")], workers=1, unguarded=False)
    assert guarded["cell_status"][0] == "unstable" and "refused before stepping" in guarded["message"][0]

    real = impactval.solve

    def solve(sc, **kw):
        if sc.ball.velocity > 1.5:
            raise ImpactvalError("test: no reference here")
        return real(sc, **kw)

    monkeypatch.setattr(impactval, "solve", solve)
    df = run_map(scene, [FAKE], [parse_axis("velocity=1,2")], workers=1)
    assert list(df["cell_status"]) == ["ok", "no-reference"] and "no reference here" in df["message"][1]


def test_cli_writes_report_and_refuses_bad_axis(tmp_path):
    out = tmp_path / "map"
    res = CliRunner().invoke(impactval.cli.main, ["extremes", "plate_steel", "--engines", FAKE, "--axis",
                                                  "velocity=0.5,1", "--axis", "stiffness=pmma,steel", "--out",
                                                  str(out), "-j", "1"])
    assert res.exit_code == 0, res.output
    assert "when stiffness = pmma: ok (all errors under 1 %) for velocity in [0.5, 1] m/s." in res.output
    md = (out / "extremes.md").read_text()
    assert "## Safe region" in md and md.count("| HertzSpringAdapter") + md.count(f"| {FAKE} |") == 4
    assert (out / "extremes.csv").exists()
    if importlib.util.find_spec("matplotlib"):
        assert (out / "extremes.png").stat().st_size > 10_000 and "![stability map](extremes.png)" in md
    res = CliRunner().invoke(impactval.cli.main, ["extremes", "plate_steel", "--engines", FAKE, "--axis",
                                                  "stiffness=pmma,1e13", "--out", str(tmp_path / "mixed"), "-j", "1"])
    assert res.exit_code == 0 and "ok (all errors under 1 %) for stiffness in [pmma, 1e+13] Pa" in res.output
    res = CliRunner().invoke(impactval.cli.main, ["extremes", "plate_steel", "--engines", FAKE, "--axis", "spin=1"])
    assert res.exit_code == 2 and "unknown axis 'spin'" in res.output and "Traceback" not in res.output


def test_perturbations_are_small(beam):
    p = {x.what: x for x in perturbations(beam, segments=20)}
    assert p["v0"].scene.ball.velocity / beam.ball.velocity - 1 == pytest.approx(1e-6)
    assert p["impact point"].scene.target.impact_at - beam.target.impact_at == pytest.approx(0.1 / 20)


def test_predictability_flags_a_jump_and_not_a_smooth_change(plate_scene):
    """A contact law that jumps 10 % at v0 = 1 + 5e-7 m/s is flagged (f_m moves ~ 1.1^(2/5) - 1 = 3.9 %
    against the reference's 1.2e-6); the smooth closed form is not."""
    from impactval.extremes import predictability

    df = predictability(plate_scene, [FAKE, "extremes_fakes:Jumpy"], [1e-7], workers=1)
    smooth, jumpy = (df[df["engine"] == e].iloc[0] for e in (FAKE, "extremes_fakes:Jumpy"))
    assert not smooth["jumped"] and abs(smooth["change_f_m"] - smooth["ref_change_f_m"]) < 1e-6
    assert jumpy["jumped"] and "f_m changed" in jumpy["why"]
    assert jumpy["change_f_m"] == pytest.approx(1.1 ** 0.4 - 1, rel=1e-3)


@requires_mujoco
def test_predictability_smooth_inside_the_limit(plate_scene):
    from impactval.extremes import predictability

    df = predictability(plate_scene, ["mujoco"], [1e-7], workers=1)
    (r,) = df.itertuples()
    assert not r.jumped, r.why
    assert abs(r.change_f_m - r.ref_change_f_m) < 1e-4     # 1e-6 in v0 moves f_m by ~1.2e-6


# ---------------------------------------------------------------------------- the bar
def _onset_ratio(scene, engine: str) -> float:
    lim = predicted_limits(engine, scene, EngineSettings(dt=1e-6), impactval.solve(scene).delta_m).dt_limit
    values = ",".join(f"{lim * 2 ** (k / 4):.6g}" for k in range(-6, 4))      # 0.35 .. 1.68 dt_limit
    df = run_map(scene, [engine], [parse_axis("dt=" + values)], settings=EngineSettings(timeout_s=300))
    (o,) = onsets(df)
    return o.ratio


BAR_CASES = [
    # was a strict xfail (onset at 0.42 of dt_limit): the energy measure's ripple, not instability; with the
    # measure semi-implicit Euler conserves (1/2 v_before' M v_after + V) the onset is at 0.71 (measured)
    pytest.param("plate_steel", "mujoco"),
    pytest.param("plate_steel", "pybullet"),
    pytest.param(str(UNSEEN_BEAM), "mujoco"),
    pytest.param(str(UNSEEN_BEAM), "pybullet"),
]


@pytest.mark.slow
@pytest.mark.parametrize("scene_name, engine", BAR_CASES)
def test_first_unstable_dt_within_factor_2_of_prediction(scene_name, engine):
    if (engine == "mujoco" and not has_mujoco) or (engine == "pybullet" and not has_pybullet):
        pytest.skip(f"{engine} not installed")
    ratio = _onset_ratio(impactval.load_scene(scene_name), engine)
    assert 0.5 <= ratio <= 2.0, f"observed/predicted first unstable dt = {ratio:.3f}"


def test_report_names_a_loose_reference():
    from impactval.reports.extremes import markdown

    df = pd.DataFrame(dict(engine=["e", "e"], velocity=[1.0, 2.0], scene=["s[v=1]", "s[v=2]"],
                           cell_status=["ok", "ok"], ref_uncertainty=[1e-7, 0.05], ref_validity=["", "delta_m/R = 0.2"]))
    df.attrs.update(axes=[Axis("velocity", (1.0, 2.0), "m/s")], under=0.01, tol=1e-6, scene="s", engines=["e"])
    md = markdown(df)
    assert "s[v=2]: reference uncertainty 0.05" in md and "s[v=1]: reference" not in md
    assert "- velocity = 2 m/s: delta_m/R = 0.2" in md           # the cell it belongs to (s20 finding 7)
    assert "e: ok (all errors under 1 %) for velocity in [1, 2] m/s." in md


# ---------------------------------------------------------------------------- one solve per cell
def _count_solves(monkeypatch) -> list[str]:
    """Count impactval.solve calls in this process (extremes, the runner and the CLI all call it there)."""
    calls: list[str] = []
    real = impactval.solve

    def counting(scene, **kw):
        calls.append(getattr(scene, "name", str(scene)))
        return real(scene, **kw)

    monkeypatch.setattr(impactval, "solve", counting)
    return calls


def test_each_cell_reference_is_solved_once(monkeypatch, tmp_path):
    """A 2 x 2 map (velocity x dt) has 2 cell scenes: 2 solves, the runner reuses them (it solved
    each again before: 4); with --predictability the base scene and its 2 perturbations once each."""
    scene = impactval.load_scene("plate_steel")
    calls = _count_solves(monkeypatch)
    df = run_map(scene, [FAKE], [parse_axis("velocity=0.5,2"), parse_axis("dt=1e-7,2e-7")], workers=1,
                 store=tmp_path / "a.sqlite")
    assert len(df) == 4 and set(df["status"]) == {"ok"}
    assert sorted(calls) == ["plate_steel[velocity=0.5]", "plate_steel[velocity=2]"]
    calls.clear()
    res = CliRunner().invoke(impactval.cli.main, ["extremes", "plate_steel", "--engines", FAKE, "--axis", "dt=1e-7,2e-7",
                                                  "--predictability", "-j", "1", "--out", str(tmp_path / "cli")])
    assert res.exit_code == 0, res.output
    # the CLI's t_m solve serves the map and the predictability runs; a plate has no impact-point perturbation
    assert sorted(calls) == ["plate_steel", "plate_steel+dv0"], calls


@requires_mujoco
def test_a_cell_that_blows_up_right_after_its_contact_is_unstable_not_inaccurate(monkeypatch):
    """An unseen clamped aluminium beam (747 x 113 x 42.7 mm) under a 1.65 mm titanium ball at 7.07 m/s: MuJoCo's
    N = 54 chain at dt 1.5e-6 s (1.7 x its predicted limit 8.9e-7 s) finishes the 8.7 us contact inaccurate
    (t_m -1.8 %, the ball leaving faster than it came) and gives NaN right after it. Each cell steps TAIL_CONTACTS
    contact times past the contact's end, so the map sees it: unstable (without the tail: 'inaccurate', and the
    first unstable dt read 3.4 x the prediction)."""
    import impactval.extremes as X
    from impactval.scenarios.scene import scene_from_dict

    scene = scene_from_dict({
        "name": "al_clamped_ti_ball", "ball": {"radius": 0.0016531, "velocity": 7.07, "material": "titanium"},
        "target": {"kind": "beam", "material": "aluminium", "support": "clamped-clamped", "length": 0.7472,
                   "width": 0.11273, "height": 0.042704, "impact_at": 0.6575}})
    axis = [parse_axis("dt=5e-7,1.5e-6")]
    df = run_map(scene, ["mujoco"], axis, workers=1)
    ok, past = df.iloc[0], df.iloc[1]
    assert past["limit_ratio"] > 1.5 and ok["limit_ratio"] < 0.6
    assert ok["cell_status"] == "ok", ok["message"]
    assert past["cell_status"] == "unstable" and "NaN" in past["message"], past["message"]
    monkeypatch.setattr(X, "TAIL_CONTACTS", 0.0)
    blind = run_map(scene, ["mujoco"], axis, workers=1).iloc[1]
    assert blind["cell_status"] in ("ok", "inaccurate") and blind["status"] == "ok"


@requires_mujoco
def test_a_ball_that_leaves_faster_than_it_came_is_said():
    """The same beam and ball, MuJoCo with no tail: at 1.7 x its limit the ball rebounds at 7.15 m/s from 7.07 m/s
    (energy the step made; the reference's rebound is below v0), and the row says so; at 0.56 x (+0.007 %) it
    does not."""
    from impactval.engines.base import REBOUND_SLACK, EngineSettings, execute_job
    from impactval.scenarios.scene import scene_from_dict

    scene = scene_from_dict({
        "name": "al_clamped_ti_ball", "ball": {"radius": 0.0016531, "velocity": 7.07, "material": "titanium"},
        "target": {"kind": "beam", "material": "aluminium", "support": "clamped-clamped", "length": 0.7472,
                   "width": 0.11273, "height": 0.042704, "impact_at": 0.6575}})
    assert impactval.solve(scene).rebound_velocity < 7.07
    past = execute_job("impactval.unguarded:mujoco", scene, EngineSettings(dt=1.5e-6))
    fine = execute_job("mujoco", scene, EngineSettings(dt=5e-7))
    assert past.status == "ok" and past.rebound_velocity > 7.07 * (1 + REBOUND_SLACK)
    note = next(v for v in past.validity if v.startswith("the ball left faster than it came"))
    assert f"rebound {past.rebound_velocity:.4g} m/s > approach 7.07 m/s" in note
    assert fine.status == "ok" and not any("faster than it came" in v for v in fine.validity)
