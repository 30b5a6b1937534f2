"""Adapters for the error-split plumbing tests (issue 17 item 2, issue 19), loaded as "split_fakes:Class"."""
import dataclasses
import math

import numpy as np

from impactval.engines.base import EngineAdapter, Plan, Simulation

#: what the fake MuJoCo Warp reports as (Warp - C)/C: a zero is a measured zero, not a missing value
VS_C = {"t_m": 1.5e-4, "f_m": -2.5e-4, "delta_m": 0.0, "c_t_m": 6.9e-5, "c_version": "fake"}
ORACLE_TOL = 1e-8


def _timoshenko(scene):
    return dataclasses.replace(scene, target=dataclasses.replace(scene.target, theory="timoshenko"))


def _own_model_solution(scene):
    """The reference solver on this engine's structure model: the Timoshenko beam, 24 modes + residual."""
    from impactval.reference.solve import solve_modes
    from impactval.reference.structure import structure_modes

    modes = structure_modes(_timoshenko(scene), 24, residual=True)
    run, _ = solve_modes(modes, scene.ball.mass, scene.alpha, scene.ball.velocity, ORACLE_TOL)
    return run


class TimoshenkoOracle(EngineAdapter):
    """A beam engine whose structure model is a Timoshenko beam (24 modes + residual flexibility) and
    whose numerics are exact: it returns the reference solver's own curve on that model. Its plan
    reports that model's error against the scene's reference the way real adapters do; its result
    carries a fixed `vs_mujoco_c` like the MuJoCo Warp adapter's."""

    name = "timoshenko-oracle"
    module = "math"

    def version(self) -> str:
        return "oracle"

    def plan(self, scene, settings) -> Plan:
        import impactval
        from impactval.errors import EngineError

        if scene.target.kind != "beam":
            raise EngineError(f"timoshenko-oracle: beams only, got a {scene.target.kind!r} target.")
        ref = impactval.solve(scene, tol=ORACLE_TOL)
        own = _own_model_solution(scene).metrics
        me = {m: getattr(own, m) / getattr(ref, m) - 1.0 for m in ("t_m", "f_m", "delta_m")}
        return Plan(math.inf, "exact", max(abs(v) for v in me.values()),
                    {f"model_error_{m}": v for m, v in me.items()})

    def simulate(self, scene, settings) -> Simulation:
        run = _own_model_solution(scene)
        t = np.asarray(run.t, float)
        return Simulation(t=t, delta=np.asarray(run.delta, float), f=np.asarray(run.f, float),
                          x_ball=np.asarray(run.x_ball, float),
                          x_structure=np.zeros_like(t), v_ball=np.zeros_like(t), energy=np.zeros(0),
                          build_s=0.0, step_s=0.0, n_steps=len(t), model="timoshenko-24-modes",
                          diagnostics={"vs_mujoco_c": dict(VS_C)})
