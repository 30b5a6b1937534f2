"""Arguments of the public API and the CLI checked at the edge (issue 18).

Scene fields have their ranges in `impactval.scenarios.limits`; this module holds the ranges of
the solver and run arguments (tolerance, window, time step, timeout, tail, counts), each refused
with the argument's name, the allowed range and a fix.
"""
from __future__ import annotations

import math
import numbers
from typing import Any

from impactval.errors import ImpactvalError
from impactval.scenarios.limits import MAX_MODES, check_answer, is_real  # noqa: F401 - check_answer re-exported

#: the largest beam chain (engine segments): a MuJoCo/Bullet body per segment
MAX_SEGMENTS = 10_000
#: the largest mode count of an engine's modal (FFRF) beam (a dense eigenproblem per build)
MAX_ENGINE_MODES = 1_000
#: the most engine steps one job may take (MuJoCo with the injected Hertz law: ~7e4 steps/s measured
#: on this 2-core machine under load, so ~70 s)
MAX_ENGINE_STEPS = 5e6

#: name -> (low, high, unit, what); low/high inclusive; used by check_run_number
RUN_LIMITS: dict[str, tuple[float, float, str, str]] = {
    "--dt": (1e-12, 1e-2, "s", "an engine time step"),
    "--timeout": (1e-3, 1e6, "s", "a time limit per engine job"),
    "--tail": (0.0, 1e3, "s", "simulated time after the first contact ends"),
}


def _as_float(value: Any) -> float:
    if not is_real(value):
        return math.nan
    if isinstance(value, numbers.Integral) and abs(int(value)) > 2**1023:
        return math.inf if value > 0 else -math.inf
    return float(value)


def check_tol(tol: Any, name: str = "tol") -> float:
    """A relative tolerance in [1e-12, 0.1] as a float."""
    x = _as_float(tol)
    if not (math.isfinite(x) and 1e-12 <= x <= 0.1):
        raise ImpactvalError(f"{name} must be a relative tolerance between 1e-12 and 0.1 (e.g. 1e-6), got {tol!r}.")
    return x


def check_window(window: Any, name: str = "window") -> float:
    """A non-negative finite time [s] as a float."""
    x = _as_float(window)
    if not (math.isfinite(x) and x >= 0):
        raise ImpactvalError(f"{name} must be a non-negative time in s (0 = the first contact only), got {window!r}.")
    return x


def check_modes(modes: Any, name: str = "modes") -> int | None:
    """None, or a whole mode count from 1 to MAX_MODES."""
    if modes is None:
        return None
    if isinstance(modes, bool) or not isinstance(modes, numbers.Integral) or not 1 <= modes <= MAX_MODES:
        raise ImpactvalError(f"{name} must be a whole number from 1 to {MAX_MODES} (or None for an automatic "
                             f"choice), got {modes!r}.")
    return int(modes)


def check_flag(value: Any, name: str) -> bool:
    """A bool (numpy bools too)."""
    if isinstance(value, bool) or (hasattr(value, "dtype") and getattr(value.dtype, "kind", "") == "b"):
        return bool(value)
    raise ImpactvalError(f"{name} must be True or False, got {value!r}.")


def check_run_number(option: str, value: Any) -> float:
    """An `impactval run` number in its range (RUN_LIMITS)."""
    low, high, unit, what = RUN_LIMITS[option]
    x = _as_float(value)
    if not (math.isfinite(x) and low <= x <= high):
        raise ImpactvalError(f"{option} must be {what}, from {low:g} to {high:g} {unit}, got {value!r}.")
    return x


def check_engine_steps(scenes, dts, tail: float) -> None:
    """Refuse a run whose engine jobs would take more than MAX_ENGINE_STEPS steps, with the estimate
    (for the numeric time steps in `dts`; "auto" is skipped).

    An engine simulates the contact (at least one rigid-plate contact time) plus `tail` [s] per job; the rigid-plate
    time is a lower bound of the real contact time, so the estimate is a lower bound too.
    """
    from impactval.reference.hertz import plate_impact

    dts = [dt for dt in dts if is_real(dt)]      # "auto": the engine picks its step; nothing to estimate here
    for sc in scenes:
        t_plate = plate_impact(sc.ball.mass, sc.alpha, sc.ball.velocity).t_m
        for dt in dts:
            steps = (t_plate + tail) / dt
            if steps > MAX_ENGINE_STEPS:
                raise ImpactvalError(
                    f"--dt {dt:g} s with --tail {tail:g} s needs at least {steps:.3g} engine steps per job on scene "
                    f"{sc.name!r} (contact ~{t_plate:.3g} s); the limit is {MAX_ENGINE_STEPS:.0e}: use a larger --dt "
                    f"(e.g. {t_plate / 1000:.1g} s) or a shorter --tail.")


def load_scenes(names) -> list:
    """Every scene of `names` (catalogue names or TOML paths) loaded, or one ImpactvalError that lists every refused
    scene at once, one `impactval: error:` line each (the CLI prints the first prefix), so that a batch with several
    bad files is fixed in one round instead of one rerun per file; nothing is run when any is refused."""
    import impactval

    scenes, refused = [], []
    for name in names:
        try:
            scenes.append(impactval.load_scene(name))
        except ImpactvalError as err:
            refused.append(str(err))
    if len(refused) == 1:
        raise ImpactvalError(refused[0])
    if refused:
        raise ImpactvalError("\nimpactval: error: ".join(refused + [
            f"{len(refused)} of {len(names)} scenes refused (above); nothing was run: fix or leave out those files"]))
    return scenes
