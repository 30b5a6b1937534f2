"""An analytic stepping adapter: the ball on a rigid plate, advanced in closed form (no engine needed).

`HertzSpringAdapter` follows the contract of `engines.base.SteppingAdapter` exactly as a real engine
would, but each `step` moves the state along the exact solution: the Hertz half-period
(`reference.hertz.PlateImpact.delta`) for contact "hertz", the sine of the linear spring k0 for
contact "native"; after the contact the ball leaves at v0. A second ball (target kind "ball") is the
same closed form for the relative motion (reduced mass, approach speed; reference/spheres.py), each
ball's motion being the centre of mass's plus its share of delta. So the contract, the loop, the window,
the metric code and the conformance suite are tested with no engine installed
(`pytest -k fake`). Use it as "impactval.engines.fake_:HertzSpringAdapter".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from impactval.engines.base import EngineSettings, Plan, SteppingAdapter
from impactval.engines.options import option, positive
from impactval.errors import EngineError


@dataclass(frozen=True)
class FakeOptions:
    """Options of the analytic adapter (one, so option parsing is exercised too)."""

    stiffness_scale: float = option(1.0, "factor on the contact law's coefficient (default 1)", positive)


@dataclass
class _State:
    t: float
    dt: float
    law: object
    mass: float
    v0: float
    t_contact: float
    delta_of: object
    diagnostics: dict
    share: float = 1.0           # ball 1's share of the relative motion, m2/(m1 + m2) (1 on a plate)
    v_cm: float = 0.0            # centre-of-mass velocity toward the target [m/s] (two balls)
    m_total: float = math.inf


class HertzSpringAdapter(SteppingAdapter):
    """A mass on a Hertz (or linear) spring, integrated in closed form; rigid plates and second balls."""

    name = "fake"
    module = "math"
    contacts = ("hertz", "native")
    integrators = ("closed-form",)
    Options = FakeOptions
    expected_failures: dict[str, str] = {}

    def version(self) -> str:
        return "closed-form"

    def explicit(self, settings: EngineSettings) -> bool:
        return False                 # exact at any step: no stability limit

    def contact_law(self, scene, settings):
        law = super().contact_law(scene, settings)
        scale = settings.option("stiffness_scale", 1.0)
        return type(law)(law.kind, law.coefficient * scale)

    def plan(self, scene, settings) -> Plan:
        return Plan(math.inf, "closed form", 0.0)

    def build(self, scene, settings: EngineSettings) -> _State:
        from impactval.reference.hertz import plate_impact

        from impactval.engines.base import contact_scene

        if scene.target.kind not in ("rigid-plate", "ball"):
            raise EngineError(f"fake: only rigid-plate and ball scenes (the closed form), got a {scene.target.kind!r} "
                              f"target.")
        law = self.contact_law(scene, settings)
        rel = contact_scene(scene)          # a second ball: the relative motion
        m, v0 = rel.ball.mass, rel.ball.velocity
        if law.kind == "hertz":
            p = plate_impact(m, law.coefficient, v0)
            t_c = p.t_m

            def delta_of(t):
                return float(p.delta(t)) if t < t_c else -v0 * (t - t_c)
        else:
            om = math.sqrt(law.coefficient / m)
            t_c = math.pi / om

            def delta_of(t):
                return v0 / om * math.sin(om * t) if t < t_c else -v0 * (t - t_c)
        state = _State(0.0, float(settings.dt), law, m, v0, t_c, delta_of, {"closed_form_t_m": t_c})
        if scene.target.kind == "ball":
            m1, m2 = scene.ball.mass, scene.target.mass
            state.share, state.m_total = m2 / (m1 + m2), m1 + m2
            state.v_cm = (m1 * scene.ball.velocity - m2 * scene.target.velocity) / (m1 + m2)
        return state

    def step(self, model: _State) -> None:
        model.t += model.dt

    def contact(self, model: _State) -> tuple[float, float]:
        d = model.delta_of(model.t)
        return d, model.law.force(d)

    def _speed(self, model: _State) -> float:
        """Approach rate [m/s] from the energy balance (sign: approaching before half the contact)."""
        d = model.delta_of(model.t)
        if model.t >= model.t_contact:
            return -model.v0
        v2 = max(model.v0**2 - 2.0 * model.law.potential(d) / model.mass, 0.0)
        return math.copysign(math.sqrt(v2), 0.5 * model.t_contact - model.t)

    def energy(self, model: _State) -> float:
        d = model.delta_of(model.t)
        e_cm = 0.5 * model.m_total * model.v_cm**2 if math.isfinite(model.m_total) else 0.0
        return 0.5 * model.mass * self._speed(model) ** 2 + model.law.potential(d) + e_cm

    def kinematics(self, model: _State) -> tuple[float, float, float]:
        d, x_cm = model.delta_of(model.t), model.v_cm * model.t
        x1 = x_cm + model.share * d
        return x1, x1 - d, model.v_cm + model.share * self._speed(model)

    def describe(self, model: _State) -> str:
        return f"closed-form {model.law.kind} spring"

    def frequencies(self, model: _State) -> np.ndarray:
        return np.zeros(0)


class ExplicitHertzSpringAdapter(HertzSpringAdapter):
    """The same closed form, declared explicit: the base predicts the limit 2/omega of the ball on the
    contact spring's tangent stiffness at f_m and refuses a dt above it (tests that path with no engine)."""

    name = "fake-explicit"

    def explicit(self, settings: EngineSettings) -> bool:
        return True

    def plan(self, scene, settings) -> Plan:
        return SteppingAdapter.plan(self, scene, settings)
