"""`impactval tune`'s default step (tune.default_dt): sized from the engines' order-2 step error, not a fixed
2000 steps.

Rule (impactval/tune.py, docs/tuning.md): N = ceil(sqrt(STEP_ERROR_C / STEP_ERROR_TARGET)) = ceil(sqrt(2.5 / 1e-5))
= 500 steps per shortest rigid-plate Hertz contact time over the speeds, rounded down to 1-2-5; STEP_ERROR_C = 2.5
bounds the measured |c| in rel. error = c / N^2 of t_m, f_m, delta_m (plate_steel, MuJoCo, PyBullet, Exudyn: <= 2.31;
MuJoCo on the fz2902 beam: <= 2.12).
"""
from __future__ import annotations

import math

import pytest

import impactval
from impactval import tune as T

# a scene that is not in the catalogue: a titanium ball (R = 6 mm) on a rigid aluminium plate
TI_ON_AL = ('[ball]\nradius = 0.006\nvelocity = 1.0\nmaterial = "titanium"\n'
            '[target]\nkind = "rigid-plate"\nmaterial = "aluminium"\n')
SPEEDS = (0.3, 3.0)


def _scene(tmp_path):
    path = tmp_path / "ti_on_al.toml"
    path.write_text(TI_ON_AL)
    return impactval.load_scene(str(path))


def _hertz_t_m(v: float) -> float:
    """Rigid-plate Hertz contact time from the materials alone (Johnson 11.4), not through impactval.tune:
    t_m = 2.9432 delta_m / v, delta_m = (5 m v^2 / (4 alpha))^(2/5), alpha = 4/3 E* sqrt(R)."""
    e1, nu1, rho1, e2, nu2, r = 113.8e9, 0.342, 4430.0, 68.9e9, 0.33, 0.006
    m = rho1 * 4.0 / 3.0 * math.pi * r**3
    e_star = 1.0 / ((1 - nu1**2) / e1 + (1 - nu2**2) / e2)
    alpha = 4.0 / 3.0 * e_star * math.sqrt(r)
    return 2.9432 * (5 * m * v * v / (4 * alpha)) ** 0.4 / v


def test_default_step_is_the_step_error_rule(tmp_path):
    """N = 500 from c = 2.5 and the 1e-5 target; on Ti on Al at 0.3 and 3 m/s the shortest contact is 37.5 us, /500 =
    75 ns, rounded down to 1-2-5: 5e-8 s (the old fixed 2000 gave 1e-8 s; N = 250 would give 1e-7 s). No structure,
    so every engine gets the same step; the engines then take 750 steps over the shortest contact, error 4.4e-6."""
    assert T.STEPS_PER_SHORTEST_CONTACT == 500
    assert T.STEP_ERROR_C / T.STEPS_PER_SHORTEST_CONTACT**2 <= T.STEP_ERROR_TARGET
    assert T.STEP_ERROR_C / (T.STEPS_PER_SHORTEST_CONTACT - 1) ** 2 > T.STEP_ERROR_TARGET     # the smallest such N
    scene = _scene(tmp_path)
    t_short = min(_hertz_t_m(v) for v in SPEEDS)
    assert t_short == pytest.approx(3.7502e-5, rel=1e-4)
    dt = T.default_dt(scene, SPEEDS)
    assert dt == 5e-8
    assert 500 <= t_short / dt < 1250 and T.STEP_ERROR_C * (dt / t_short) ** 2 <= 1e-5
    for engine in ("mujoco", "pybullet", "exudyn"):
        assert T.default_dt(scene, SPEEDS, engine) == dt


# the residuals (signed fractions) of a fit at the default step and one at a 4x finer step: each engine's step error
# is <= STEP_ERROR_TARGET = 1e-5 at the default and 16x less at the finer one; the fitted stiffness absorbs part of it.
# Tolerance 2e-5 = 2 x STEP_ERROR_TARGET on every signed error (measured here: 2.0e-6 Exudyn, 3.6e-6 MuJoCo; plate_steel
# at 1e-7 against 2e-8: <= 5e-6)
REPRODUCE_TOL = 2 * T.STEP_ERROR_TARGET


@pytest.mark.parametrize("engine,contact", [
    pytest.param("exudyn", "native-hertz", id="exudyn-hertz", marks=pytest.mark.slow),
    pytest.param("mujoco", "native", id="mujoco-linear"),
])
def test_a_fit_at_the_default_step_reproduces_one_at_a_4x_finer_step(engine, contact, tmp_path):
    """Same scene (not in the catalogue), same speeds: a fit at the default step (5e-8 s) and at 1.25e-8 s print the
    same residuals within 2e-5 (0.002 % points) and the same stiffness within 1e-4. Both fits: exudyn 26 s, hence
    slow; mujoco 17 s (a shared 2-core machine)."""
    pytest.importorskip(engine)
    scene = _scene(tmp_path)
    dt = T.default_dt(scene, SPEEDS, engine, contact)
    coarse = T.tune(engine, scene, SPEEDS, contact=contact, store=str(tmp_path / "coarse.sqlite"), workers=2)
    fine = T.tune(engine, scene, SPEEDS, contact=contact, dt=dt / 4, store=str(tmp_path / "fine.sqlite"), workers=2)
    assert coarse.dt == dt == 5e-8 and fine.dt == pytest.approx(1.25e-8)
    assert [r["status"] for r in coarse.residuals + fine.residuals] == ["ok"] * 4
    for a, b in zip(coarse.residuals, fine.residuals):
        for m in ("t_m", "f_m", "delta_m"):
            assert abs(a[f"err_{m}"] - b[f"err_{m}"]) <= REPRODUCE_TOL, (a["speed"], m, a[f"err_{m}"], b[f"err_{m}"])
    key = "contact_stiffness" if engine == "exudyn" else "k"
    assert coarse.parameters[key] == pytest.approx(fine.parameters[key], rel=1e-4)
    if engine == "exudyn":                       # alpha at the default step: measured 1.5e-6 off (3.9e-8 at dt / 4)
        assert abs(coarse.parameters["alpha_fit_rel_error"]) < 1e-5
