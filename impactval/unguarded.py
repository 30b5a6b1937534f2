"""Adapters that step past their predicted stability limit, for stability maps (issue 14).

The adapter base refuses a time step above the predicted explicit limit `dt_limit` before stepping
(status "unstable", no stepping). A stability map has to see what really happens there, so
`impactval extremes` runs an explicit time step through "impactval.unguarded:SPEC", a subclass of
SPEC's adapter (SPEC = "mujoco", "pybullet", "pkg.module:Class", ...) whose plan reports no limit
(the base then steps as asked); the predicted limit is kept in the row's diagnostics as
`predicted_dt_limit` [s] and `predicted_dt_limit_what`. Divergence is still detected by the base
(NaN, energy growth, the ball through the target). Everything else (build, step, metrics) is the
engine's own adapter, unchanged.
"""
from __future__ import annotations

import math
from functools import lru_cache

PREFIX = "impactval.unguarded:"


def unguarded_spec(spec: str) -> str:
    """The engine spec that steps past the predicted limit ("mujoco" -> "impactval.unguarded:mujoco")."""
    return spec if spec.startswith(PREFIX) else PREFIX + spec


def guarded_spec(spec: str) -> str:
    """The inverse of `unguarded_spec`."""
    return spec[len(PREFIX):] if spec.startswith(PREFIX) else spec


@lru_cache(maxsize=None)
def _unguarded_class(spec: str) -> type:
    from impactval.engines.base import Plan, adapter_class

    base = adapter_class(spec)

    class Unguarded(base):  # type: ignore[misc, valid-type]
        __doc__ = f"{base.__name__} stepping past its predicted stability limit (see impactval.unguarded)."

        def plan(self, scene, settings) -> Plan:
            p = super().plan(scene, settings)
            diag = {**p.diagnostics, "predicted_dt_limit": float(p.dt_limit), "predicted_dt_limit_what": p.what}
            return Plan(math.inf, p.what, p.model_error, diag)

    Unguarded.__name__ = Unguarded.__qualname__ = f"Unguarded{base.__name__}"
    Unguarded.__module__ = __name__
    return Unguarded


def __getattr__(name: str) -> type:
    """"impactval.unguarded:mujoco" or "impactval.unguarded:fake_engines:KillSelf" -> the class."""
    if name.startswith("__"):
        raise AttributeError(name)
    from impactval.errors import EngineError

    try:
        return _unguarded_class(name)
    except EngineError as err:
        raise AttributeError(f"{name}: {err}") from None
