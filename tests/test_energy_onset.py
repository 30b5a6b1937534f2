"""The energy check's message says when the growth started: after the first contact had ended (in the window a
--tail asks for), a shorter tail keeps the contact's row; during the contact, nothing is added."""
import math

import numpy as np

import impactval
from impactval.engines.base import EngineAdapter, EngineSettings, Plan, Simulation
from impactval.reference.result import Status


class _Series(EngineAdapter):
    """Returns a fixed series: a half-sine contact of 100 us (ball bounces off a rigid plate), then free flight,
    with energy growing from `onset` [s] on."""

    name = "series-fake"
    module = "math"

    def __init__(self, onset: float) -> None:
        self.onset = onset

    def version(self) -> str:
        return "fake"

    def plan(self, scene, settings) -> Plan:
        return Plan(math.inf, "exact", 0.0, {})

    def simulate(self, scene, settings) -> Simulation:
        dt, t_c = 1e-7, 1e-4
        t = np.arange(0.0, 4e-4, dt)
        delta = np.where(t < t_c, 1e-6 * np.sin(np.pi * t / t_c), -1e-3 * (t - t_c))
        f = np.where(delta > 0, 1e10 * np.maximum(delta, 0.0) ** 1.5, 0.0)
        energy = 1.0 + np.where(t > self.onset, np.expm1((t - self.onset) / 2e-5), 0.0)
        return Simulation(t=t, delta=delta, f=f, x_ball=delta, x_structure=np.zeros_like(t),
                          v_ball=np.zeros_like(t), energy=energy, build_s=0.0, step_s=0.0, n_steps=len(t))


def _row(onset: float):
    sc = impactval.load_scene("plate_steel")
    a = _Series(onset)
    s = a.check_settings(EngineSettings(dt=1e-7, tail=3e-4))
    return a.result_from(sc, s, a.simulate(sc, s), a.plan(sc, s))


def test_growth_in_the_tail_is_said_with_its_onset():
    r = _row(2.5e-4)
    assert r.status == Status.UNSTABLE
    assert r.message.startswith("energy grew")
    assert "after the first contact (0 .. 0.0001 s) had ended" in r.message, r.message
    t_past = float(r.message.split("first past the limit at t = ")[1].split(" s")[0])
    assert 2.5e-4 < t_past < 2.5e-4 + 2e-5       # 5 % over at 2e-5 ln(1.05) ~ 1e-6 s after the onset
    assert "--tail" in r.message


def test_growth_during_the_contact_adds_nothing():
    r = _row(5e-5)
    assert r.status == Status.UNSTABLE
    assert "first past the limit" not in r.message
