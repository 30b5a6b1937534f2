"""Ball on ball in the engines (issue 17, point 1): two free spheres in MuJoCo, PyBullet and Exudyn.

Every number is checked against the closed form of the relative motion (reduced mass m* = m1 m2/(m1 + m2),
approach speed v1 + v2, alpha of both curvatures and both moduli; reference/spheres.py), which is independent
of the engines: Hertz t_m, f_m, delta_m (paper eq. 31-33), the linear spring's sine (t_m = pi/omega,
delta_m = v/omega, omega = sqrt(k/m*)), and momentum/energy exchange of an elastic collision.
"""
import math

import pytest

import impactval
from conftest import requires_exudyn, requires_mujoco, requires_pybullet
from impactval.engines.base import EngineSettings, load_adapter
from impactval.reference.hertz import plate_impact
from impactval.reference.spheres import (approach_speed, reduced_mass, two_sphere_impact,
                                         two_sphere_velocities_after)

ENGINES = [pytest.param("mujoco", marks=requires_mujoco), pytest.param("pybullet", marks=requires_pybullet),
           pytest.param("exudyn", marks=requires_exudyn)]
SCENES = ["ball_ball_glass_dem", "ball_ball_steel_on_aluminium"]
#: the plate bar of issues 4-6 (injected Hertz), here at every default (dt = auto)
BAR = 5e-4


def rel(a, b):
    return abs(a / b - 1.0)


@pytest.mark.parametrize("scene_name", SCENES)
@pytest.mark.parametrize("engine", ENGINES)
def test_injected_hertz_at_defaults_within_plate_bar(engine, scene_name):
    """Injected Hertz, every default: t_m, f_m, delta_m within 0.05 % of the closed form; both balls leave
    with the elastic-exchange velocities (ball 2's from the slope of its displacement) within 0.1 %."""
    sc = impactval.load_scene(scene_name)
    closed = two_sphere_impact(sc)
    r = load_adapter(engine).run(sc, EngineSettings())
    assert r.status == "ok", r.message
    for got, want in ((r.t_m, closed.t_m), (r.f_m, closed.f_m), (r.delta_m, closed.delta_m)):
        assert rel(got, want) <= BAR, (got, want)
    u1, u2 = two_sphere_velocities_after(sc)          # each toward the other ball
    assert rel(-r.rebound_velocity, u1) <= 1e-3, (r.rebound_velocity, u1)
    v2_away = (r.x_structure[-1] - r.x_structure[-2]) / (r.t[-1] - r.t[-2])
    assert abs(-v2_away - u2) <= 1e-3 * approach_speed(sc), (v2_away, u2)
    assert r.contact_law.kind == "hertz" and r.contact_law.coefficient == sc.alpha
    # the automatic step resolves the two-ball contact (>= 200 steps), not the first ball's on a plate
    assert r.dt <= closed.t_m / 200


@pytest.mark.parametrize("engine", ENGINES)
def test_native_linear_matches_the_sine_and_the_linear_reference(engine):
    """The engine's native linear contact (Exudyn: its native contact with exponent 1) at the two-ball k0:
    the sine of the reduced mass within 0.05 %, the row's law linear (the runner's linear-theory comparison),
    and `solve_linear` on the ball target gives the same sine (1e-9)."""
    from impactval.reference.linear import solve_linear

    sc = impactval.load_scene("ball_ball_steel_on_aluminium")
    opts = (("law", "linear"),) if engine == "exudyn" else ()
    r = load_adapter(engine).run(sc, EngineSettings(contact="native", options=opts))
    assert r.status == "ok", r.message
    k0 = plate_impact(reduced_mass(sc), sc.alpha, approach_speed(sc)).k0
    assert r.contact_law.kind == "linear" and rel(r.contact_law.coefficient, k0) <= 1e-12
    omega = math.sqrt(k0 / reduced_mass(sc))
    t_m, delta_m = math.pi / omega, approach_speed(sc) / omega
    assert rel(r.t_m, t_m) <= BAR and rel(r.delta_m, delta_m) <= BAR and rel(r.f_m, k0 * delta_m) <= BAR
    lin = solve_linear(sc)
    assert rel(lin.t_m, t_m) <= 1e-9 and rel(lin.delta_m, delta_m) <= 1e-9


@requires_exudyn
@pytest.mark.parametrize("scene_name", SCENES)
def test_exudyn_native_sphere_sphere_hertz(scene_name):
    """Exudyn's own ObjectContactSphereSphere between the two balls, exponent 1.5, alpha of both curvatures."""
    sc = impactval.load_scene(scene_name)
    closed = two_sphere_impact(sc)
    r = load_adapter("exudyn").run(sc, EngineSettings(contact="native"))
    assert r.status == "ok", r.message
    assert r.diagnostics["contact_object"] == "ObjectContactSphereSphere"
    assert r.diagnostics["contact_exponent"] == 1.5 and r.diagnostics["contact_alpha"] == sc.alpha
    for got, want in ((r.t_m, closed.t_m), (r.f_m, closed.f_m), (r.delta_m, closed.delta_m)):
        assert rel(got, want) <= BAR, (got, want)


@pytest.mark.parametrize("engine, integrator, bound", [
    pytest.param("mujoco", "Euler", 2.0, marks=requires_mujoco),
    pytest.param("mujoco", "RK4", 2.0 * math.sqrt(2.0), marks=requires_mujoco),
    pytest.param("pybullet", None, 2.0, marks=requires_pybullet),
    pytest.param("exudyn", "rk44", 2.0 * math.sqrt(2.0), marks=requires_exudyn),
])
def test_dt_limit_is_the_reduced_mass_on_the_contact_spring(engine, integrator, bound):
    """dt_limit = bound/omega with omega = sqrt(k_t/m*), k_t = 1.5 alpha sqrt(delta_m) the Hertz tangent stiffness
    at the two-ball delta_m: two free masses on a spring oscillate with the reduced mass."""
    sc = impactval.load_scene("ball_ball_glass_dem")
    adapter = load_adapter(engine)
    settings = adapter.check_settings(EngineSettings(integrator=integrator))
    plan = adapter.plan(sc, settings)
    closed = two_sphere_impact(sc)
    omega = math.sqrt(1.5 * sc.alpha * math.sqrt(closed.delta_m) / reduced_mass(sc))
    assert plan.dt_limit == pytest.approx(bound / omega, rel=1e-12)


def test_base_sees_the_two_ball_contact():
    """No engine needed: the base's contact times, contact mass and through-depth describe the relative
    motion of two free balls (closed form of reference/spheres.py), so dt auto, the window and the default
    limit follow the two-ball contact; the through-target depth is the smaller radius."""
    from impactval.engines.base import contact_mass, plate_times, through_depth
    from impactval.scenarios.scene import scene_from_dict

    sc = impactval.load_scene("ball_ball_steel_on_aluminium")
    closed, p = two_sphere_impact(sc), plate_times(sc)
    assert (p.t_m, p.f_m, p.delta_m) == pytest.approx((closed.t_m, closed.f_m, closed.delta_m), rel=1e-14)
    assert contact_mass(sc) == pytest.approx(sc.ball.mass * sc.target.mass / (sc.ball.mass + sc.target.mass), rel=1e-14)
    small = scene_from_dict({"ball": {"radius": 0.02, "velocity": 1.0, "material": "steel"},
                             "target": {"kind": "ball", "radius": 0.005, "material": "steel"}})
    assert through_depth(small) == 0.005 and through_depth(sc) == sc.ball.radius
    plate = impactval.load_scene("plate_steel")
    assert contact_mass(plate) == plate.ball.mass and through_depth(plate) == plate.ball.radius


def test_fake_adapter_runs_two_balls_in_closed_form():
    """The analytic adapter (always installed) on the DEM glass case: the closed form to the metric code's
    sampling accuracy, both balls' velocities after the contact from momentum and energy."""
    sc = impactval.load_scene("ball_ball_glass_dem")
    closed = two_sphere_impact(sc)
    r = load_adapter("impactval.engines.fake_:HertzSpringAdapter").run(sc, EngineSettings())
    assert r.status == "ok", r.message
    for got, want in ((r.t_m, closed.t_m), (r.f_m, closed.f_m), (r.delta_m, closed.delta_m)):
        assert rel(got, want) <= 1e-4
    u1, _ = two_sphere_velocities_after(sc)
    assert rel(-r.rebound_velocity, u1) <= 1e-9


@requires_mujoco
def test_a_step_that_under_resolves_the_contact_says_so_and_what_step_to_take():
    """A user's glass ball (2.55 mm, 9.21 m/s) on a free 46.7 mm PMMA ball at dt = 1e-5 s, below MuJoCo's predicted
    limit: the 29.5 us contact (closed form of the relative motion) takes 3 steps, the energy grows 12.7 % and the row
    said "unstable ... (predicted limit 1.46e-05 s)" and nothing else, as if the step were safe. It now names the
    steps per contact and a step to take; that step (the automatic one) gives an ok row within the plate bar."""
    from impactval.scenarios.scene import scene_from_dict

    sc = scene_from_dict({"name": "glass_on_pmma_ball", "ball": {"radius": 0.0025512, "velocity": 9.212,
                                                                "material": "glass"},
                          "target": {"kind": "ball", "radius": 0.046747, "material": "pmma"}})
    closed = two_sphere_impact(sc)
    r = load_adapter("mujoco").run(sc, EngineSettings(dt=1e-5))
    assert r.status == "unstable" and r.dt <= r.dt_limit, r.message
    steps = closed.t_m / 1e-5
    assert f"the contact (~{closed.t_m:.3g} s) spans only {steps:.2g} steps" in r.message, r.message
    suggest = float(r.message.split("use dt <= ")[1].split(" s")[0])
    assert suggest <= closed.t_m / 100
    again = load_adapter("mujoco").run(sc, EngineSettings(dt=suggest))
    assert again.status == "ok", again.message
    for got, want in ((again.t_m, closed.t_m), (again.f_m, closed.f_m), (again.delta_m, closed.delta_m)):
        assert rel(got, want) <= BAR, (got, want)
