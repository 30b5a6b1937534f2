"""The Volterra solver against the closed form and the independent ODE form (issue 8 bars)."""
import numpy as np
import pytest

import impactval
from impactval.reference.hertz import plate_impact
from impactval.reference.ode import solve_ode
from impactval.errors import ImpactvalError
from impactval.reference.solve import solve_modes, structure_modes


def test_plate_matches_closed_form_to_1e8():
    scene = impactval.load_scene("plate_steel")
    p = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    r = impactval.solve(scene, tol=1e-9)
    err = r.metrics.relative_to(p)
    assert max(abs(err.t_m), abs(err.f_m), abs(err.delta_m)) <= 1e-8
    # the self-reported bound holds
    assert abs(r.t_m - p.t_m) <= r.uncertainty.t_m
    assert abs(r.f_m - p.f_m) <= r.uncertainty.f_m
    assert abs(r.delta_m - p.delta_m) <= r.uncertainty.delta_m
    # the curve follows the closed form
    inside = r.t <= p.t_m
    assert np.allclose(r.delta[inside], p.delta(r.t[inside]), atol=1e-8 * p.delta_m)
    assert r.rebound_velocity == pytest.approx(scene.ball.velocity, rel=1e-8)


@pytest.mark.parametrize("name,modes", [("modal_two_mode", None), ("beam_ss_midspan", 12),
                                        ("beam_cantilever_tip", 10), ("beam_ss_quarter", 16),
                                        ("heavy_ball_slender_beam", 8)])
@pytest.mark.parametrize("tol", [1e-6, 1e-8])
def test_ode_form_agrees_within_reported_uncertainty(name, modes, tol):
    scene = impactval.load_scene(name)
    md = structure_modes(scene, modes)
    truth, _ = solve_ode(md, scene.ball.mass, scene.alpha, scene.ball.velocity, rtol=1e-13, atol=1e-15)
    r = impactval.solve(scene, tol=tol, modes=modes)
    for key in ("t_m", "f_m", "delta_m"):
        err = abs(getattr(r, key) - getattr(truth, key))
        unc = getattr(r.uncertainty, key)
        assert err <= unc, f"{key}: error {err:.3g} > reported uncertainty {unc:.3g}"
        assert unc <= tol * getattr(r, key)


def test_recontacts_agree_with_ode():
    scene = impactval.load_scene("heavy_ball_slender_beam")
    md = structure_modes(scene, 6)
    window = 3e-3
    _, info = solve_ode(md, scene.ball.mass, scene.alpha, scene.ball.velocity, rtol=1e-12, atol=1e-14,
                        window=window)
    r = impactval.solve(scene, tol=1e-8, modes=6, window=window)
    assert len(r.contacts) >= 2, "this scene is in the catalogue for its re-contacts"
    assert len(r.contacts) == len(info["ends"])
    for c, s, e in zip(r.contacts, info["starts"], info["ends"]):
        assert c.t_start == pytest.approx(s, abs=1e-9)
        assert c.t_end == pytest.approx(e, abs=1e-9)


def test_energy_converges_and_is_conserved_at_tight_tolerance():
    scene = impactval.load_scene("beam_ss_midspan")
    errs = [impactval.solve(scene, tol=tol, modes=20).energy_error for tol in (1e-5, 1e-7, 1e-9)]
    assert errs[0] > errs[1] > errs[2]
    assert impactval.solve(scene, tol=1e-10, modes=20).energy_error <= 1e-9


def test_long_window_streams_free_flight_and_keeps_the_first_contact_exact():
    """Issue 14: a 1000 s window on the heavy ball finishes with every re-contact, in bounded memory: free
    flight jumps ahead where no contact can occur, the series keeps ~SERIES_SAMPLES nodes plus the contacts'."""
    from impactval.reference.kernel import SERIES_SAMPLES

    scene = impactval.load_scene("heavy_ball_slender_beam")
    short = impactval.solve(scene, tol=1e-6, window=0.1)
    long = impactval.solve(scene, tol=1e-6, window=1000.0)
    assert long.t[-1] == pytest.approx(1000.0 + long.contacts[0].t_end, rel=1e-9)
    assert len(long.t) < 5 * SERIES_SAMPLES
    assert long.metrics == short.metrics                     # the first contact is the same run
    assert len(long.contacts) == len(short.contacts) >= 30   # all re-contacts are within the first 0.1 s
    assert np.all(np.isfinite(long.energy)) and long.energy_error < 1e-6
    # the ball leaves for good: last sample's velocity is the free-flight velocity, away from the beam
    assert long.x_ball[-1] < -1.0 and np.all(np.diff(long.t) > 0)


def test_free_flight_jumps_keep_recontacts_as_the_ode_has_them():
    scene = impactval.load_scene("heavy_ball_slender_beam")
    md = structure_modes(scene, 6)
    window = 0.012
    _, info = solve_ode(md, scene.ball.mass, scene.alpha, scene.ball.velocity, rtol=1e-12, atol=1e-14,
                        window=window)
    run, _ = solve_modes(md, scene.ball.mass, scene.alpha, scene.ball.velocity, 1e-8, window=window,
                         series_samples=200)          # coarse samples: long jumps between contacts
    assert len(run.contacts) == len(info["ends"]) >= 7
    for c, s, e in zip(run.contacts, info["starts"], info["ends"]):
        assert c.t_start == pytest.approx(s, abs=1e-9)
        assert c.t_end == pytest.approx(e, abs=1e-9)


def test_window_beyond_double_precision_is_refused_up_front():
    scene = impactval.load_scene("heavy_ball_slender_beam")
    with pytest.raises(ImpactvalError, match=r"window 1e\+09 s is too long.*at most .* s \(--window\)"):
        impactval.solve(scene, window=1e9)


def test_window_over_the_node_budget_is_refused_with_an_estimate(monkeypatch):
    from impactval.reference import solve as solve_mod

    scene = impactval.load_scene("heavy_ball_slender_beam")
    monkeypatch.setattr(solve_mod, "node_cap", lambda n_modes: 3000)
    with pytest.raises(ImpactvalError, match=r"window 1 s needs about .* steps \(~.* GB, ~.* s\).*at most"):
        solve_mod.solve_modes(structure_modes(scene, 8), scene.ball.mass, scene.alpha, scene.ball.velocity,
                              1e-6, window=1.0, series_samples=1e9)


def _scene(ball, target):
    from impactval.scenarios.scene import scene_from_dict

    return scene_from_dict({"name": "extreme", "ball": ball, "target": target})


_BEAM = {"kind": "beam", "material": "steel", "support": "simply-supported", "length": 0.5, "width": 0.01,
         "height": 0.01, "impact_at": 0.5}


@pytest.mark.parametrize("label,ball,target,ode_modes", [
    ("delta_m 1.5e-9 m, plate", {"radius": 1e-3, "velocity": 1e-4, "material": "steel"},
     {"kind": "rigid-plate", "material": "steel"}, None),
    ("delta_m 2e-10 m, beam", {"radius": 1e-3, "velocity": 1e-5, "material": "steel"}, dict(_BEAM, modes=12), 12),
    ("modal mass 1e-3 x ball", {"radius": 0.01, "velocity": 1.0, "material": "steel"},
     {"kind": "modal", "material": "steel", "omega": [3e4, 1.5e5], "modal_mass": [3.27e-5, 3.27e-5], "phi": [1, 1]},
     2),
    ("modal mass 1e3 x ball", {"radius": 0.01, "velocity": 1.0, "material": "steel"},
     {"kind": "modal", "material": "steel", "omega": [3e4, 1.5e5], "modal_mass": [32.7, 32.7], "phi": [1, 1]}, 2),
    ("ball 33 kg on a slender beam", {"radius": 0.1, "velocity": 0.5, "material": "steel"},
     dict(_BEAM, height=0.005, modes=10), 10),
    ("ball 0.5 mg on a beam", {"radius": 5e-4, "velocity": 0.5, "material": "steel"}, dict(_BEAM, modes=10), 10),
])
def test_reference_holds_at_the_extremes(label, ball, target, ode_modes):
    """Issue 14 point 3: finite, converged, uncertainty under tol, and within it of an independent answer."""
    scene = _scene(ball, target)
    r = impactval.solve(scene, tol=1e-6)
    m = r.metrics
    assert all(np.isfinite([m.t_m, m.f_m, m.delta_m])) and m.t_m > 0 and m.delta_m > 0
    for key in ("t_m", "f_m", "delta_m"):
        assert getattr(r.uncertainty, key) <= 1e-6 * getattr(m, key)
    if ode_modes is None:
        truth = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    else:
        truth, _ = solve_ode(structure_modes(scene, ode_modes), scene.ball.mass, scene.alpha, scene.ball.velocity,
                             rtol=1e-12, atol=1e-14)
    for key in ("t_m", "f_m", "delta_m"):
        assert abs(getattr(m, key) - getattr(truth, key)) <= getattr(r.uncertainty, key), f"{label}: {key}"


@pytest.mark.slow
def test_ten_thousand_modes_converge():
    """10,000 modes (w up to ~1e6): the tol = 1e-6 answer is within its uncertainty of the tol = 1e-9 one."""
    scene = impactval.load_scene("beam_ss_midspan")
    r = impactval.solve(scene, tol=1e-6, modes=10000)
    tight = impactval.solve(scene, tol=1e-9, modes=10000)
    assert r.modes == 10000
    for key in ("t_m", "f_m", "delta_m"):
        assert abs(getattr(r, key) - getattr(tight, key)) <= getattr(r.uncertainty, key) <= 1e-6 * getattr(r, key)


def test_solve_takes_a_name_and_refuses_what_is_not_a_scene():
    """Issue 18: solve("plate_steel") works like solve(load_scene("plate_steel")); None and 3 are refused."""
    assert impactval.solve("plate_steel").t_m == impactval.solve(impactval.load_scene("plate_steel")).t_m
    for bad in (None, 3):
        with pytest.raises(ImpactvalError, match="a scene is a Scene, a catalogue name"):
            impactval.solve(bad)


def test_a_nearly_free_mode_is_a_free_mass():
    """The slowest mode a scene may have (omega = 0.01 rad/s, a 10-minute period: a free mass over a
    70 us contact) is finite and the ODE form agrees; omega = 1e-300 (issue 18: NaN uncertainties were
    printed) is refused at load, naming the field."""
    with pytest.raises(ImpactvalError, match="omega"):
        _scene({"radius": 0.01, "velocity": 1.0, "material": "steel"},
               {"kind": "modal", "material": "steel", "omega": [1e-300, 1e5], "modal_mass": [0.1, 0.1],
                "phi": [1.0, 1.0]})
    scene = _scene({"radius": 0.01, "velocity": 1.0, "material": "steel"},
                   {"kind": "modal", "material": "steel", "omega": [0.01, 1e5], "modal_mass": [0.1, 0.1],
                    "phi": [1.0, 1.0]})
    r = impactval.solve(scene, tol=1e-6)
    truth, _ = solve_ode(structure_modes(scene), scene.ball.mass, scene.alpha, scene.ball.velocity, rtol=1e-12,
                         atol=1e-14)
    for key in ("t_m", "f_m", "delta_m"):
        assert abs(getattr(r, key) - getattr(truth, key)) <= getattr(r.uncertainty, key) <= 1e-6 * getattr(r, key)
