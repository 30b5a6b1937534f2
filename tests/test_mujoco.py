"""MuJoCo adapter: the bars of issue 4 on the worked case (physics.md), measured."""
import math

import numpy as np
import pytest

import impactval
from conftest import requires_mujoco, run_py
from impactval.engines.base import EngineSettings
from impactval.errors import EngineError

pytestmark = requires_mujoco


@pytest.fixture(scope="module")
def adapter():
    from impactval.engines.mujoco_ import MujocoAdapter

    return MujocoAdapter()


def rel(a, b):
    return abs(a / b - 1.0)


@pytest.mark.parametrize("integrator", ["Euler", "implicitfast", "RK4"])
def test_plate_injected_hertz_within_0_05_percent(adapter, plate_scene, plate, integrator):
    """Issue 4 bar: plate, injected Hertz, dt = 1e-6: t_m, f_m, delta_m within 0.05 % of the closed form."""
    r = adapter.run(plate_scene, EngineSettings(dt=1e-6, integrator=integrator))
    assert r.status == "ok", r.message
    for got, want in ((r.t_m, plate.t_m), (r.f_m, plate.f_m), (r.delta_m, plate.delta_m)):
        assert rel(got, want) <= 5e-4
    assert r.n_steps == pytest.approx(plate.t_m / 1e-6, abs=2)
    assert r.rebound_velocity == pytest.approx(plate_scene.ball.velocity, rel=1e-3)   # elastic
    assert r.wall_time_step_s > 0 and r.version.startswith(("3.", "4."))


def test_plate_native_linear_matches_closed_form_sine(adapter, plate_scene, plate):
    """Issue 4 bar: native linear contact on the plate vs the linear theory (closed form):
    delta = (v0/omega0) sin(omega0 t), t_m = pi/omega0, f_m = k0 delta_m: within 0.1 %."""
    r = adapter.run(plate_scene, EngineSettings(dt=1e-6, contact="native"))
    assert r.status == "ok", r.message
    k0 = r.diagnostics["contact_stiffness"]
    assert k0 == pytest.approx(plate.k0, rel=1e-12)
    omega0 = math.sqrt(k0 / plate_scene.ball.mass)
    delta_m = plate_scene.ball.velocity / omega0
    assert rel(r.t_m, math.pi / omega0) <= 1e-3
    assert rel(r.delta_m, delta_m) <= 1e-3
    assert rel(r.f_m, k0 * delta_m) <= 1e-3
    # the force really is the linear law, sample by sample
    on = r.delta > 0.05 * delta_m
    assert np.allclose(r.f[on], k0 * r.delta[on], rtol=1e-3)


def test_plate_native_hertz_fit_is_close(adapter, plate_scene, plate):
    """native-hertz: MuJoCo's solimp shape fitted to alpha*delta^1.5 (measured: ~0.2 % on the plate)."""
    r = adapter.run(plate_scene, EngineSettings(dt=1e-6, contact="native-hertz"))
    assert r.status == "ok", r.message
    assert r.diagnostics["native_hertz_fit_rms"] < 0.01
    for got, want in ((r.t_m, plate.t_m), (r.f_m, plate.f_m), (r.delta_m, plate.delta_m)):
        assert rel(got, want) <= 5e-3


@pytest.fixture(scope="module")
def beam_ref():
    return impactval.solve(impactval.load_scene("beam_ss_midspan"), tol=1e-5)


def test_beam_ss_chain_81_within_1_5_percent(adapter, beam_ref):
    """Issue 4 bar: simply supported beam at mid-span, chain N = 81 with the section's rotary inertia,
    dt = 1e-6: all three errors <= 1.5 %, the chain's first three frequencies within 1 % of the
    continuum, and the chain's predicted model error (engines.chain.model_error) within 0.05 % of the
    measured error (time integration adds little at 1e-6)."""
    sc = impactval.load_scene("beam_ss_midspan")
    r = adapter.run(sc, EngineSettings(dt=1e-6, segments=81, options=(("rotary_inertia", "section"),)))
    assert r.status == "ok", r.message
    for got, want in ((r.t_m, beam_ref.t_m), (r.f_m, beam_ref.f_m), (r.delta_m, beam_ref.delta_m)):
        assert rel(got, want) <= 0.015
    chain = np.array(r.diagnostics["structure_frequencies"][:3])
    cont = np.array(r.diagnostics["continuum_frequencies"][:3])
    assert np.all(np.abs(chain / cont - 1) <= 0.01)
    assert r.diagnostics["segments"] == 81
    assert r.diagnostics["equality_violation_max"] < 1e-8        # the pin holds
    for key, got, want in (("t_m", r.t_m, beam_ref.t_m), ("f_m", r.f_m, beam_ref.f_m),
                           ("delta_m", r.delta_m, beam_ref.delta_m)):
        assert abs((got / want - 1) - r.diagnostics[f"model_error_{key}"]) <= 5e-4


def test_beam_defaults_sized_from_the_scene(adapter, beam_ref):
    """Issue 11: with every default (N sized from the scene, dt auto, Euler-Bernoulli chain) the worked
    beam is within the chain tolerance, and dt is below half the predicted limit."""
    sc = impactval.load_scene("beam_ss_midspan")
    r = adapter.run(sc, EngineSettings())
    assert r.status == "ok", r.message
    assert r.dt <= 0.5 * r.dt_limit and r.model_error <= 1e-2
    for got, want in ((r.t_m, beam_ref.t_m), (r.f_m, beam_ref.f_m), (r.delta_m, beam_ref.delta_m)):
        assert rel(got, want) <= r.model_error + 1e-3


def test_beam_native_linear_spring_on_flexible_target(adapter):
    """Native contact on a beam is still the linear spring k0 (small impedance; see NATIVE_IMPEDANCE)."""
    sc = impactval.load_scene("beam_ss_midspan")
    r = adapter.run(sc, EngineSettings(dt=1e-6, segments=41, contact="native"))
    assert r.status == "ok", r.message
    k0 = r.diagnostics["contact_stiffness"]
    on = r.delta > 0.05 * r.delta_m
    assert np.allclose(r.f[on], k0 * r.delta[on], rtol=2e-3)


@pytest.mark.parametrize("name", ["beam_cc_midspan", "beam_cantilever_tip", "beam_ss_quarter"])
def test_chain_frequencies_all_supports(adapter, name):
    """Each support's chain (N = 41) has its first three frequencies within 1 % of the continuum."""
    sc = impactval.load_scene(name)
    from impactval.engines.chain import continuum_frequencies, hencky_chain

    chain = adapter.structure_frequencies(sc, EngineSettings(segments=41))[:3]
    cont = continuum_frequencies(sc.target, 3)
    assert np.all(np.abs(chain / cont - 1) <= 0.01), (chain, cont)
    # MuJoCo's linearised chain is engines.chain's Hencky chain
    assert np.allclose(chain, hencky_chain(sc.target, 41).frequencies()[:3], rtol=1e-4)


def test_a_long_chain_takes_its_frequencies_from_the_chain_model_which_mujoco_matches(adapter):
    """Above FD_FREQUENCIES_MAX_DOF the adapter reports its chain model's frequencies (MuJoCo's own, from the
    finite-differenced transition matrix, cost ~DOF^4: a 373-segment Timoshenko chain of a user's beam spent 140 s of a
    199 s job there) and says so; the two agree on a 161-segment Timoshenko chain (325 DOF) to 1e-3, measured here
    both ways; a chain under the limit keeps MuJoCo's own."""
    from impactval.engines.mujoco_ import FD_FREQUENCIES_MAX_DOF, chain_frequencies

    sc = impactval.load_scene("beam_ss_stubby_timoshenko")
    settings = EngineSettings(segments=161, dt=1e-7)
    run = adapter.build(sc, settings)
    try:
        assert run.model.nv > FD_FREQUENCIES_MAX_DOF
        reported = adapter.frequencies(run)
        assert "chain model" in run.diagnostics["structure_frequencies_from"]
        own = chain_frequencies(run.mj, run.model)[:len(reported)]
    finally:
        adapter.close(run)
    assert np.array_equal(reported, adapter.chain(sc, settings).frequencies()[:len(reported)])
    assert np.allclose(reported, own, rtol=1e-3), (reported, own)
    small = adapter.build(sc, EngineSettings(segments=41, dt=1e-7))
    try:
        assert small.model.nv <= FD_FREQUENCIES_MAX_DOF
        assert np.array_equal(adapter.frequencies(small), chain_frequencies(small.mj, small.model)[:6])
        assert "structure_frequencies_from" not in small.diagnostics
    finally:
        adapter.close(small)


@pytest.mark.parametrize("root", ["end", "middle"])
def test_a_thin_timoshenko_chain_builds_with_its_support_bodies_inertia_in_range(adapter, tmp_path, root):
    """A user's 158 x 2.5 x 1.2 mm PMMA Timoshenko beam under a steel ball crashed MuJoCo's compiler ("mass and
    inertia of moving bodies must be larger than mjMINVAL"): the end's shear-slide body had 1e-6 of a segment's
    rotary inertia, 3.4e-19 kg m^2. It now gets at least 2e-15 and its segment gives up as much: the model builds
    and the chain's total rotary inertia is the chain model's (1e-9), either tree root. A chain whose segments are
    too light for that is refused with the field to change."""
    from impactval.engines.mujoco_ import MIN_INERTIA

    path = tmp_path / "thin_pmma_timoshenko.toml"
    path.write_text('[ball]\nradius = 0.0064298\nvelocity = 0.07385\nmaterial = "steel"\n[target]\nkind = "beam"\n'
                    'material = "pmma"\nsupport = "simply-supported"\nlength = 0.15784\nwidth = 0.0024899\n'
                    'height = 0.0011588\nimpact_at = 0.6945\ntheory = "timoshenko"\n')
    sc = impactval.load_scene(str(path))
    settings = EngineSettings(segments=182, dt=1e-7, options={"chain_root": root})
    chain = adapter.chain(sc, adapter.check_settings(settings))
    assert 1e-6 * chain.rotary_inertia < 1e-15          # the case: a point's inertia below MuJoCo's floor
    run = adapter.build(sc, adapter.check_settings(settings))
    try:
        m = run.model
        iyy = m.body_inertia[1:, :].min(axis=1)
        assert iyy.min() >= MIN_INERTIA
        names = [m.body(i).name for i in range(1, m.nbody)]
        beam = [k for k, name in enumerate(names) if name.startswith("seg") or name in ("end", "roller0", "clamp0")]
        total = float(np.sum(m.body_inertia[1:, 1][beam]))
    finally:
        adapter.close(run)
    assert total == pytest.approx(chain.n * chain.rotary_inertia, rel=1e-9)
    with pytest.raises(EngineError, match="too light for MuJoCo.*--segments"):
        adapter.build(sc, adapter.check_settings(EngineSettings(segments=40000, dt=1e-7)))


def test_modal_target_injected_hertz(adapter):
    sc = impactval.load_scene("modal_two_mode")
    ref = impactval.solve(sc, tol=1e-7)
    r = adapter.run(sc, EngineSettings(dt=1e-7, integrator="RK4"))
    assert r.status == "ok", r.message
    for got, want in ((r.t_m, ref.t_m), (r.f_m, ref.f_m), (r.delta_m, ref.delta_m)):
        assert rel(got, want) <= 1e-4


def test_modal_target_native_is_refused(adapter):
    with pytest.raises(EngineError, match="modal target"):
        adapter.run(impactval.load_scene("modal_two_mode"), EngineSettings(contact="native"))


def test_pure_euler_bernoulli_chain_is_unstable_at_1us(adapter):
    """Without the section's rotary inertia the N = 81 chain exceeds Euler's limit at dt = 1e-6:
    refused before stepping with the predicted limit; the prediction is checked by stepping just below
    and just above it (the loop's own divergence detection)."""
    from dataclasses import replace

    from impactval.engines.base import Plan

    sc = impactval.load_scene("beam_ss_midspan")
    r = adapter.run(sc, EngineSettings(dt=1e-6, segments=81, options=(("rotary_inertia", "none"),)))
    assert r.status == "unstable" and r.n_steps == 0
    assert f"{r.dt_limit:.3g} s" in r.message and "dt = 1e-06 s" in r.message

    class NoRefusal(type(adapter)):        # the same adapter without the refusal: step at 0.95 and 1.05 x limit
        def plan(self, scene, settings):
            return replace(super().plan(scene, settings), dt_limit=float("inf"))

    s = EngineSettings(segments=81, tail=2e-4)
    below = NoRefusal().run(sc, replace(s, dt=0.95 * r.dt_limit))
    above = NoRefusal().run(sc, replace(s, dt=1.05 * r.dt_limit))
    assert below.status == "ok", below.message
    assert above.status == "unstable", above.message


def test_callback_is_cleared(adapter, plate_scene):
    import mujoco

    adapter.run(plate_scene, EngineSettings(dt=1e-6))
    assert mujoco.get_mjcb_passive() is None


def test_bad_settings_are_one_line_errors(adapter, plate_scene):
    with pytest.raises(EngineError, match="unknown integrator 'euler'"):
        adapter.run(plate_scene, EngineSettings(integrator="euler"))
    with pytest.raises(EngineError, match="unknown option 'timestep'"):
        adapter.run(plate_scene, EngineSettings(options=(("timestep", 1e-6),)))
    with pytest.raises(EngineError, match="rotary_inertia must be one of"):
        adapter.run(plate_scene, EngineSettings(options=(("rotary_inertia", "full"),)))


def test_core_never_imports_mujoco():
    out = run_py("import impactval, impactval.runner, impactval.compare, impactval.cli, impactval.engines.mujoco_; "
                 "import sys; print({'mujoco', 'pybullet', 'exudyn'} & set(sys.modules) or '')")
    assert out == ""


def test_euler_energy_error_is_second_order(adapter, plate_scene):
    """Energy from the velocities before and after a step (1/2 v_before' M v_after): error ~ dt^2, so dt = 2e-6 is not misread as
    "unstable" (the plain half-step kinetic energy swings by ~5 % there)."""
    e1, e2 = (adapter.run(plate_scene, EngineSettings(dt=dt)) for dt in (1e-6, 2e-6))
    assert e1.status == e2.status == "ok"
    assert e1.energy_error < 1e-3
    assert 3.0 < e2.energy_error / e1.energy_error < 5.0


def test_euler_energy_measure_has_no_ripple(adapter, plate_scene):
    """Semi-implicit Euler conserves 1/2 v_before' M v_after + V exactly on a linear system; the mean
    velocity used before added dt^2/8 f'M^-1 f, a bounded ripple the 5 % growth criterion read as instability
    (onset at 0.42 of dt_limit on this plate). At half the predicted limit (3 steps per contact) the
    measured growth is the real energy change the contact made: the rebound's (v_out/v0)^2 - 1
    (measured +3.92 % both; the mean-velocity measure said +11.8 %)."""
    lim = adapter.plan(plate_scene, adapter.check_settings(EngineSettings(dt=1e-6))).dt_limit
    sim = adapter.simulate(plate_scene, adapter.check_settings(EngineSettings(dt=float(f"{0.5 * lim:.4g}"))))
    e = np.asarray(sim.energy)
    assert sim.f[-1] == 0.0                     # the series ends after the contact: its last velocity is the rebound
    rebound = sim.v_ball[-1] / plate_scene.ball.velocity
    assert abs((e.max() / e[0] - 1.0) - (rebound**2 - 1.0)) < 1e-3


UNSEEN = __import__("pathlib").Path(__file__).parent / "unseen"


@pytest.mark.parametrize("scene_name, n", [("beam_ss_midspan", 41), (str(UNSEEN / "cantilever_titanium.toml"), 41),
                                           (str(UNSEEN / "cc_aluminium_0p3.toml"), 41)])
@pytest.mark.parametrize("contact", ["hertz", "native"])
def test_chain_root_changes_the_tree_not_the_beam(adapter, scene_name, n, contact):
    """chain_root = "middle" (a floating middle segment, two branches, supports as constraints: roller body,
    pins, clamp tendons) is the same beam as MuJoCo's serial chain: the three supports, both contacts, equal
    within 1e-5 (measured to 1e-6 on the worked beam at N = 81), the first four frequencies within 2e-5 (6e-6:
    the soft supports, finite-differenced)."""
    scene = impactval.load_scene(scene_name)
    rows = [adapter.run(scene, EngineSettings(dt=2e-7, contact=contact, segments=n, options=(("chain_root", root),)))
            for root in ("end", "middle")]
    assert all(r.status == "ok" for r in rows), [r.message for r in rows]
    for k in ("t_m", "f_m", "delta_m"):
        assert rel(getattr(rows[1], k), getattr(rows[0], k)) < 1e-5, k
    freqs = [r.diagnostics["structure_frequencies"][:4] for r in rows]
    assert len(freqs[0]) == 4 and freqs[1] == pytest.approx(freqs[0], rel=2e-5)


def test_auto_root_takes_the_middle_above_256_dof_and_keeps_the_beam(adapter):
    """chain_root 'auto' (the default) roots a chain of more than AUTO_ROOT_DOF degrees of freedom at its middle (a
    serial chain's dense mass matrix: a user's 385-segment Timoshenko chain took 119 s serial, 40 s from the middle)
    and keeps the Timoshenko chain there; the metrics equal the serial chain's within 1e-4 (measured 1.8e-5), and a
    small chain stays serial (the catalogue's chains, all under 256 DOF, are built as before)."""
    from impactval.engines.mujoco_ import AUTO_ROOT_DOF

    scene = impactval.load_scene(str(UNSEEN / "heavy_wc_slender_timoshenko.toml"))
    auto = adapter.run(scene, EngineSettings(segments=130))
    end = adapter.run(scene, EngineSettings(segments=130, options=(("chain_root", "end"),)))
    assert auto.status == end.status == "ok", (auto.message, end.message)
    assert 2 * 130 > AUTO_ROOT_DOF and auto.diagnostics["chain_root"] == "middle" and end.diagnostics["chain_root"] == "end"
    assert not any("Euler-Bernoulli chain" in v for v in auto.validity), auto.validity
    for k in ("t_m", "f_m", "delta_m"):
        assert rel(getattr(auto, k), getattr(end, k)) < 1e-4, k
    assert adapter.plan(impactval.load_scene("beam_ss_midspan"), adapter.check_settings(EngineSettings())).diagnostics[
        "chain_root"] == "end"


@pytest.mark.parametrize("rotary, gain", [("section", 5.0), ("none", 5.0)])
def test_middle_root_is_what_float32_can_factorise(rotary, gain):
    """Why the MuJoCo Warp chain is rooted at its middle: the joint-space mass matrix of the worked beam's
    93-segment chain, factorised in float32 (numpy Cholesky, as mujoco_warp does in float32), solves M x = f
    with a relative error > 5x smaller than for the serial chain (measured 0.0096 vs 0.071 section, 0.026 vs
    0.23 none), in the joint units as built or rescaled to a unit diagonal."""
    import mujoco

    from impactval.engines.chain import hencky_chain
    from impactval.engines.mujoco_ import build_xml

    scene = impactval.load_scene("beam_ss_midspan")
    err = {}
    for root in ("end", "middle"):
        xml, _ = build_xml(scene, EngineSettings(dt=1e-6, options=(("chain_root", root),)),
                           hencky_chain(scene.target, 93, rotary))
        m = mujoco.MjModel.from_xml_string(xml)
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        mass = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, mass)
        f = np.random.default_rng(0).standard_normal(m.nv)
        for units in ("as built", "unit diagonal"):       # a change of joint units (diagonal scaling) does not help
            s = np.ones(m.nv) if units == "as built" else 1.0 / np.sqrt(np.diag(mass))
            scaled = mass * s[:, None] * s[None, :]
            exact = np.linalg.solve(scaled, f * s)
            low = np.linalg.cholesky(scaled.astype(np.float32))
            x32 = np.linalg.solve(low.T, np.linalg.solve(low, (f * s).astype(np.float32)))
            err[root, units] = np.linalg.norm(s * (x32 - exact)) / np.linalg.norm(s * exact)
    for units in ("as built", "unit diagonal"):
        assert err["end", units] > gain * err["middle", units], err
