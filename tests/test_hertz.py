"""Closed-form Hertz impact on a rigid plate (physics.md sec. 2)."""
import math

import numpy as np
import pytest
from scipy import integrate

import impactval
from impactval.reference.hertz import C_HERTZ, E0, hertz_alpha, plate_impact


def test_constant_c_matches_its_integral():
    val, _ = integrate.quad(lambda x: 1.0 / math.sqrt(1.0 - x**2.5), 0.0, 1.0, limit=200)
    assert C_HERTZ == pytest.approx(val, rel=1e-10)
    assert C_HERTZ == pytest.approx(1.4716376, abs=1e-7)
    assert E0 == pytest.approx(1.0674, abs=5e-5)


def test_worked_case_of_physics_md():
    # physics.md quotes 6 significant figures: compare at that precision
    scene = impactval.load_scene("plate_steel")
    assert scene.ball.mass == pytest.approx(0.0326726, rel=6e-6)
    assert scene.alpha == pytest.approx(1.53846e10, rel=6e-6)
    p = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    assert p.delta_m == pytest.approx(23.4208e-6, rel=6e-6)
    assert p.f_m == pytest.approx(1743.78, rel=6e-6)
    assert p.t_m == pytest.approx(68.934e-6, rel=6e-6)
    assert p.k0 == pytest.approx(0.8 * p.f_m / p.delta_m, rel=1e-14)


def test_curve_is_exact_against_the_energy_integral():
    p = plate_impact(0.05, 2e10, 2.0)
    t = np.linspace(0, p.t_m, 2001)
    d = p.delta(t)
    # round trip t -> delta -> t on the rising half
    rising = t <= p.t_m / 2
    assert np.allclose(p.time_of(d[rising]), t[rising], rtol=1e-10, atol=1e-10 * p.t_m)
    # energy conservation along the curve: m v^2/2 + (2/5) alpha delta^2.5 = m v0^2 / 2
    v = np.gradient(d, t, edge_order=2)
    inner = slice(10, -10)
    e = 0.5 * p.mass * v[inner] ** 2 + 0.4 * p.alpha * d[inner] ** 2.5
    assert np.allclose(e, 0.5 * p.mass * p.v0**2, rtol=2e-4)
    assert d.max() == pytest.approx(p.delta_m, rel=1e-9)
    assert np.allclose(d, d[::-1], atol=1e-12 * p.delta_m)            # symmetric about the peak


def test_alpha_formula():
    assert hertz_alpha(0.01, 1e11) == pytest.approx(4 / 3 * 1e11 * 0.1)


def test_ball_on_ball_tends_to_ball_on_plane():
    from impactval.reference.hertz import hertz_alpha_spheres
    assert hertz_alpha_spheres(0.01, 1e9, 1e11) == pytest.approx(hertz_alpha(0.01, 1e11), rel=1e-10)
    # two equal balls: effective radius R/2
    assert hertz_alpha_spheres(0.01, 0.01, 1e11) == pytest.approx(hertz_alpha(0.005, 1e11), rel=1e-14)


def test_contact_law_force_potential_stiffness_are_consistent():
    """ContactLaw: potential' = force and force' = stiffness (central differences), both laws."""
    from impactval.reference.hertz import ContactLaw

    for law in (ContactLaw.hertz(3.7e9), ContactLaw.linear(2.1e7)):
        for d in (1e-7, 3e-6, 2e-5):
            h = d * 1e-5
            assert abs((law.potential(d + h) - law.potential(d - h)) / (2 * h) / law.force(d) - 1) < 1e-8
            assert abs((law.force(d + h) - law.force(d - h)) / (2 * h) / law.stiffness(d) - 1) < 1e-8
        assert law.force(-1e-6) == 0.0 and law.potential(0.0) == 0.0
    with pytest.raises(ValueError):
        ContactLaw("cubic", 1.0)


def test_status_is_a_string_enum():
    from impactval.reference.result import ImpactResult, Status

    r = ImpactResult.failed("s", "e", "timeout", "slow")
    assert r.status is Status.TIMEOUT and r.status == "timeout" and f"{r.status}" == "timeout"
    assert Status.UNSTABLE.failed and not Status.SKIPPED.failed
