"""A beam or plate scene with an explicit `modes = n`: its reference is the n-mode model (no residual; the paper's
modal model, reference/solve.py), which may be far from the structure's continuum that the engines model.

Nothing here runs inside `reference.solve.solve` (its cost is a timed benchmark): the runner (`References`) and the
`impactval reference` command call `continuum_scene` / `truncation_check` where they solve a scene's reference, and
the engines size their structures against `continuum_scene(scene)` (engines/chain.py `continuum_metrics`).

The rule (docs/reference.md "An explicit mode count"): the engines model the whole structure, so they are sized and
error-estimated against the continuum (the same scene without `modes`, its count chosen automatically); the row's
error is taken against the scene's reference (the n-mode model), and the runner adds the n-mode model's departure
from the continuum (`truncation_gap`) to the row's structure error, so structure + numerics = error still holds and
the row says so. The beam-theory gap is measured on the continuum as well.
"""
from __future__ import annotations

import dataclasses
import math

#: an explicit count's departure from the continuum is reported (reference validity warning, row note) when its
#: largest metric exceeds TRUNCATION_WARN_FACTOR x the reference's tol (the reference's uncertainty, <= tol, says
#: nothing about it), and TRUNCATION_WARN_FLOOR (a tenth of the finest accuracy bar the sweeps and reports use, 0.1 %:
#: the worked beam with 160 modes is 2.3e-5 off its continuum, 20x tol 1e-6 but invisible in every row), and is
#: resolved by the two solves' uncertainties (it exceeds 3x their sum). ss_eb with modes = 5: 8.4e-2.
TRUNCATION_WARN_FACTOR, TRUNCATION_WARN_FLOOR = 10.0, 1e-4
#: the continuum is solved at the reference's tol, but not tighter than this (a percent-level question)
CONTINUUM_TOL_FLOOR = 1e-8
METRICS = ("t_m", "f_m", "delta_m")


def explicit_count(scene) -> int | None:
    """The scene's own mode count (`[target] modes`) for a beam or plate, else None."""
    target = getattr(scene, "target", None)
    if getattr(target, "kind", "") not in ("beam", "plate"):
        return None
    n = getattr(target, "modes", None)
    return int(n) if n is not None else None


def continuum_scene(scene):
    """`scene` without its explicit mode count (the structure's continuum, count chosen automatically); the scene
    itself when it has none (or is not a beam or plate)."""
    if explicit_count(scene) is None:
        return scene
    return dataclasses.replace(scene, target=dataclasses.replace(scene.target, modes=None))


def continuum_tol(tol: float) -> float:
    return max(float(tol), CONTINUUM_TOL_FLOOR)


def truncation_gap(ref, continuum) -> dict[str, float]:
    """(n-mode reference - continuum) / continuum per metric, signed fractions."""
    return {m: getattr(ref, m) / getattr(continuum, m) - 1.0 for m in METRICS}


def _rel_unc(r) -> float:
    u = r.uncertainty
    return max(u.t_m / r.t_m, u.f_m / r.f_m, u.delta_m / r.delta_m)


def significant(ref, continuum, tol: float) -> bool:
    """Whether the n-mode reference's departure from the continuum is worth a warning (see TRUNCATION_WARN_FACTOR)."""
    gap = truncation_gap(ref, continuum)
    d = max(abs(v) for v in gap.values())
    return math.isfinite(d) and d > max(TRUNCATION_WARN_FACTOR * tol, TRUNCATION_WARN_FLOOR) and \
        d > 3.0 * (_rel_unc(ref) + _rel_unc(continuum))


def truncation_warning(scene, ref, continuum, tol: float) -> str:
    """The reference validity line for a scene with an explicit count whose n-mode model is far from the continuum
    (`significant`), else ""."""
    n = explicit_count(scene)
    if n is None or not significant(ref, continuum, tol):
        return ""
    gap = truncation_gap(ref, continuum)
    parts = ", ".join(f"{m} {100 * gap[m]:+.3g} %" for m in METRICS)
    what = "beam" if scene.target.kind == "beam" else "plate"
    return (f"modes = {n} (the scene's) define the reference model, exactly {n} modes without the rest's static "
            f"flexibility: it differs from the {what}'s continuum by {parts} (the continuum solved with an automatic "
            f"count, {continuum.modes} modes; more than {TRUNCATION_WARN_FACTOR:g} x tol {tol:g} and "
            f"{100 * TRUNCATION_WARN_FLOOR:g} %, which the uncertainty does not cover); engines model the whole {what}, so this is in their structure error: "
            f"remove `modes` to compare with the {what}")


def truncation_check(scene, ref, tol: float, solve=None):
    """(continuum reference or None, warning or ""): the continuum of a scene with an explicit count solved at
    `continuum_tol(tol)` (`solve(scene, tol)`, default impactval.solve) and `truncation_warning`. None, "" for a
    scene without an explicit count; a refused continuum solve gives None and a warning saying it was not checked."""
    if explicit_count(scene) is None or ref is None or not getattr(ref, "success", True):
        return None, ""
    from impactval.errors import ImpactvalError

    if solve is None:
        import impactval

        solve = impactval.solve
    try:
        cont = solve(continuum_scene(scene), tol=continuum_tol(tol))
    except ImpactvalError as exc:
        n = explicit_count(scene)
        return None, (f"modes = {n} (the scene's) define the reference model (exactly {n} modes); its distance to the "
                      f"structure's continuum was not measured (the continuum solve was refused: {str(exc)[:160]})")
    return cont, truncation_warning(scene, ref, cont, tol)


def with_warning(ref, warning: str):
    """`ref` with `warning` added to its validity (unchanged when empty or already there)."""
    if not warning or warning in tuple(ref.validity or ()):
        return ref
    return dataclasses.replace(ref, validity=tuple(ref.validity or ()) + (warning,))
