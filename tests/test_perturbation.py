"""First-order perturbation theory (issue 3, part 2) against exact solutions and independent integrations."""
import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import impactval
from impactval.reference.hertz import C_HERTZ, plate_impact
from impactval.reference.linear import solve_linear
from impactval.reference.perturbation import (
    L_linear, M_linear, T_linear, hertz_d1, hertz_static_weights, hertz_weights, perturbation,
    perturbation_curve, zero_order,
)

BASE = impactval.load_scene("modal_two_mode")
PLATE = plate_impact(BASE.ball.mass, BASE.alpha, BASE.ball.velocity)


def _scaled(scene, factor):
    """The scene with every modal mass multiplied by `factor` (s_j divided by it)."""
    t = scene.target
    return dataclasses.replace(scene, target=dataclasses.replace(t, modal_mass=tuple(m * factor for m in t.modal_mass)))


def _one_mode(w, s):
    om = w * BASE.ball.velocity / PLATE.delta_m
    tgt = dataclasses.replace(BASE.target, omega=(om,), modal_mass=(BASE.ball.mass / s,), phi=(1.0,))
    return dataclasses.replace(BASE, name=f"one_mode_w{w}", target=tgt)


def _naive_L(th, r):
    return -th * np.cos(th) / (2 * (r * r - 1)) - (1 + r * r) * np.sin(th) / (2 * (r * r - 1) ** 2) \
        + r * np.sin(r * th) / (r * r - 1) ** 2


def test_linear_weights_match_formulas_and_limits():
    th = np.linspace(0, math.pi, 41)
    for r in (0.05, 0.3, 0.8, 1.2, 2.5, 7.0):
        assert np.allclose(L_linear(th, r), _naive_L(th, r), rtol=0, atol=1e-12)
        assert T_linear(r) == pytest.approx(1 / (2 * (r * r - 1)) + r * math.sin(math.pi * r) / (math.pi * (r * r - 1) ** 2),
                                            abs=1e-13)
        assert M_linear(r) == pytest.approx((r * math.sin(math.pi * r / 2) - (1 + r * r) / 2) / (r * r - 1) ** 2, abs=1e-13)
    # removable singularity at r = 1: exact values and continuity through it
    assert T_linear(1.0) == pytest.approx(-1 / 8, abs=1e-15)
    assert M_linear(1.0) == pytest.approx(-(4 + math.pi**2) / 32, abs=1e-15)
    for e in (1e-3, 1e-6, 1e-9):
        assert abs(T_linear(1 + e) - T_linear(1 - e)) < 2 * e
    # limits: free mass (r -> 0) and spring in series (r -> inf)
    assert T_linear(1e-6) == pytest.approx(-0.5, abs=1e-9) and M_linear(1e-6) == pytest.approx(-0.5, abs=1e-9)
    assert 1e8 * T_linear(1e4) == pytest.approx(0.5, rel=1e-6)
    assert 1e8 * M_linear(1e4) == pytest.approx(-0.5, rel=1e-6)


def test_zero_order_curve_is_the_hertz_solution():
    z = zero_order(2048)
    assert np.allclose(z.d0p**2 + z.d0**2.5, 1.0, rtol=0, atol=1e-13)      # energy
    assert z.t[-1] == pytest.approx(2 * C_HERTZ, rel=1e-15)
    assert z.d0[1024] == pytest.approx(1.0, abs=1e-15) and abs(z.d0p[1024]) < 1e-7
    p = plate_impact(1.0, 1.25, 1.0)      # scaled units: delta_m = v0 = 1
    assert np.allclose(z.d0, p.delta(z.t), atol=1e-13)


def _d1_by_ode(w):
    """d1(c), d1(2c)/(2c) from one DOP853 integration of d0, the mode oscillator x'' + w^2 x = d0^1.5 and
    d1'' + (15/8) sqrt(d0) d1 = -(5/4)(d0^1.5 - w^2 x) (independent of the quadrature)."""
    def rhs(_t, y):
        d0, v0, x, vx, d1, v1 = y
        g = max(d0, 0.0) ** 1.5
        return [v0, -1.25 * g, vx, -w * w * x + g, v1, -1.875 * math.sqrt(max(d0, 0.0)) * d1 - 1.25 * (g - w * w * x)]
    sol = solve_ivp(rhs, (0, 2 * C_HERTZ), [0, 1, 0, 0, 0, 0], method="DOP853", rtol=1e-12, atol=1e-14,
                    dense_output=True, first_step=1e-5)
    return sol.sol(2 * C_HERTZ)[4] / (2 * C_HERTZ), sol.sol(C_HERTZ)[4]


@pytest.mark.parametrize("w", [0.3, 1.0, 1.7, 4.0, 12.0])
def test_hertz_weights_quadrature_vs_ode(w):
    TH, MH = hertz_weights([w])
    th, mh = _d1_by_ode(w)
    assert TH[0] == pytest.approx(th, abs=2e-9)
    assert MH[0] == pytest.approx(mh, abs=2e-9)


@pytest.mark.parametrize("w", [0.25, 1.0, 1.5, 2.0, 5.0])
def test_hertz_weights_vs_exact_solutions_at_small_s(w):
    """TH, MH as the limit s -> 0 of the exact (Volterra) solution's relative shifts / s: three-point
    Richardson extrapolation in s removes the O(s) and O(s^2) terms."""
    X = []
    for s in (0.008, 0.004, 0.002):
        r = impactval.solve(_one_mode(w, s), tol=1e-12)
        X.append(np.array(((r.t_m / PLATE.t_m - 1) / s, (r.delta_m / PLATE.delta_m - 1) / s)))
    th_ex, mh_ex = (8 * X[2] - 6 * X[1] + X[0]) / 3
    TH, MH = hertz_weights([w])
    assert TH[0] == pytest.approx(th_ex, abs=2e-7)
    assert MH[0] == pytest.approx(mh_ex, abs=2e-7)


# physics.md 7.2 table (4 decimals). Checked here, not trusted: two entries are off by one unit in the
# last place (TH(1.5) = 0.124049 -> 0.1240, MH(0.75) = -0.377248 -> -0.3772, both confirmed by the ODE and
# by Richardson-extrapolated exact solutions above); the rest round exactly.
TABLE_W = [0, 0.25, 0.5, 0.75, 1, 1.25, 1.5, 2, 2.5, 3, 4, 5, 7, 10, 20]
TABLE_TH = [-0.4000, -0.3757, -0.3069, -0.2056, -0.0882, +0.0269, +0.1241, +0.2278, +0.2133, +0.1419, +0.0492,
            +0.0341, +0.0159, +0.0073, +0.0018]
TABLE_MH = [-0.4000, -0.3974, -0.3897, -0.3773, -0.3604, -0.3397, -0.3159, -0.2621, -0.2054, -0.1517, -0.0696,
            -0.0285, -0.0140, -0.0060, -0.0016]


def test_physics_md_table():
    TH, MH = hertz_weights(np.array(TABLE_W, float))
    assert np.max(np.abs(TH - TABLE_TH)) <= 1.01e-4
    assert np.max(np.abs(MH - TABLE_MH)) <= 1.01e-4
    wrong = sorted({TABLE_W[i] for i in np.flatnonzero(np.abs(np.round(TH, 4) - TABLE_TH) > 1e-9)}
                   | {TABLE_W[i] for i in np.flatnonzero(np.abs(np.round(MH, 4) - TABLE_MH) > 1e-9)})
    assert wrong == [0.75, 1.5]
    # small-w limit: a free mass (-2/5), approached continuously
    th, mh = hertz_weights([1e-4])
    assert th[0] == pytest.approx(-0.4, abs=1e-6) and mh[0] == pytest.approx(-0.4, abs=1e-6)


def test_hertz_weights_of_many_modes_at_once_are_each_modes_own():
    """A batch (repeats, the free-mass and static ends, cached and new values, more modes than one block) gives
    every mode the weights its own quadrature gives, in its own place; and the first-order curve of a scene with
    thousands of modes is the sum of its modes' curves (computed block by block)."""
    from impactval.reference import perturbation as pt

    rng = np.random.default_rng(3)
    w = np.concatenate(([0.0, 400.0, 2.0, 2.0], rng.uniform(0.01, 50.0, 700), [60.0, 0.0, 2.0]))
    rng.shuffle(w)
    pt._WEIGHTS.clear()
    hertz_weights(w[:5])                              # some cached before the batch
    old = pt._D1_BLOCK
    pt._D1_BLOCK = 100 * 2049                         # blocks of 100 modes
    try:
        TH, MH = hertz_weights(w)
    finally:
        pt._D1_BLOCK = old
    for i in rng.choice(len(w), 40, replace=False).tolist() + [int(np.argmax(w == 2.0))]:
        x = float(w[i])
        if x == 0.0:
            assert (TH[i], MH[i]) == (-0.4, -0.4)
        elif x > pt.W_QUADRATURE_MAX:
            th_inf, mh_inf = hertz_static_weights()
            assert (TH[i], MH[i]) == (th_inf / x**2, mh_inf / x**2)
        else:
            th, mh = pt._weights_one(x)
            assert TH[i] == pytest.approx(th, rel=1e-13, abs=1e-16)
            assert MH[i] == pytest.approx(mh, rel=1e-13, abs=1e-16)
    s = rng.uniform(0.0, 0.01, len(w))
    quad = w <= pt.W_QUADRATURE_MAX
    summed = pt._d1_sum(w[quad], s[quad], 2048)
    one_by_one = sum(si * hertz_d1(float(wi), 2048)[1] for si, wi in zip(s[quad], w[quad]))
    assert np.max(np.abs(summed - one_by_one)) <= 1e-13 * np.max(np.abs(one_by_one))


def test_static_limit():
    th_inf, mh_inf = hertz_static_weights()
    assert mh_inf == pytest.approx(-5 / 8, abs=1e-10)       # energy with a series spring: exact
    from impactval.reference.perturbation import W_QUADRATURE_MAX, _weights_one

    w = W_QUADRATURE_MAX
    th, mh = _weights_one(w)                       # quadrature at the switch-over to the asymptotics
    assert w**2 * th == pytest.approx(th_inf, rel=1e-2)
    assert w**2 * mh == pytest.approx(mh_inf, rel=1e-2)
    th, mh = _weights_one(400.0)
    assert 400**2 * th == pytest.approx(th_inf, rel=2e-3)
    assert 400**2 * mh == pytest.approx(mh_inf, rel=2e-3)


def _errors(model, k):
    sc = _scaled(BASE, 2.0**k)
    exact = solve_linear(sc) if model == "linear" else impactval.solve(sc, tol=1e-11)
    e = perturbation(sc, model).metrics.relative_to(exact.metrics)
    return np.array([e.t_m, e.f_m, e.delta_m])


@pytest.mark.parametrize("model", ["hertz", "linear"])
def test_error_falls_like_s_squared(model):
    """Modal masses x 2^k (s_j / 2^k): the error ratio between s and s/2 tends to 4 (measured 3.97-4.03)."""
    errs = [_errors(model, k) for k in range(1, 6)]
    for a, b in zip(errs[:-1], errs[1:]):
        assert np.all(np.abs(a / b - 4.0) < 0.05), a / b
    assert np.max(np.abs(errs[-1])) < 3e-6


def test_sine_approximation_is_only_first_order_accurate():
    """The paper's sine approximation: error O(s), ratio -> 2 (physics.md 7.2), about 0.1 s."""
    errs = [_errors("hertz-sine", k) for k in range(2, 6)]
    ratios = [a / b for a, b in zip(errs[:-1], errs[1:])]
    assert np.all(np.abs(ratios[-1] - 2.0) < 0.05)


def test_beam_modes_with_residual_match_exact_auto_solution():
    """The beam form (modes up to w = 50 + residual with the static weights) for a light ball on a heavy beam."""
    sc = impactval.load_scene("light_ball_heavy_beam")
    exact = impactval.solve(sc, tol=1e-8)
    e = perturbation(sc, "hertz").metrics.relative_to(exact.metrics)
    shift = abs(perturbation(sc, "hertz").shift_delta)
    assert max(abs(e.t_m), abs(e.f_m), abs(e.delta_m)) <= max(5 * shift**2, 1e-7)


def test_curves():
    sc = _scaled(BASE, 8.0)
    for model in ("hertz", "linear", "hertz-sine"):
        t, d, f = perturbation_curve(sc, model)
        res = perturbation(sc, model)
        assert d.max() == pytest.approx(res.metrics.delta_m, rel=1e-3)
        assert d[0] == 0.0 and np.all(f >= 0)
    # d1 curve at the peak equals MH
    t, d1 = hertz_d1(2.0)
    assert d1[(len(t) - 1) // 2] == pytest.approx(hertz_weights([2.0])[1][0], abs=1e-12)


def test_automatic_mode_set_at_its_cap_says_so(monkeypatch):
    """The automatic first-order mode set takes every mode up to w = W_QUADRATURE_MAX; stopped by its cap below that,
    the modes above are static springs only, and the result says so (fz2513's t_m shift was 33 % low at 4,096 modes,
    without a word)."""
    from impactval.reference import perturbation as pt

    scene = impactval.load_scene("beam_ss_midspan")
    full = perturbation(scene)
    assert full.weights.w[-1] < pt.W_QUADRATURE_MAX < 2 * full.weights.w[-1]
    assert not any("stopped at its cap" in v for v in full.validity)
    monkeypatch.setattr(pt, "PERTURBATION_MODE_CAP", 16)
    capped = perturbation(scene)
    assert len(capped.weights.w) == 16 and capped.weights.w[-1] < pt.W_QUADRATURE_MAX
    assert any("stopped at its cap (16 modes" in v for v in capped.validity)
    assert capped.shift_t != full.shift_t
