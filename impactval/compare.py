"""Errors of one impact result against a reference (style.md, pattern 1: ImpactResult -> numbers).

All errors are signed relative differences (engine - reference) / reference, except the
whole-curve error, which is a non-negative RMS.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import trapezoid

from impactval.reference.result import ImpactResult

#: the start of an ok row's message when its scene's reference was refused: no errors (NaN), and the run exits 1
NO_REFERENCE = "no reference to compare with"


def relative_errors(result: ImpactResult, ref: ImpactResult) -> dict[str, float]:
    """Signed relative errors in t_m, f_m, delta_m (NaN when either side has no number)."""
    out = {}
    for key in ("t_m", "f_m", "delta_m"):
        a, b = getattr(result, key), getattr(ref, key)
        out[key] = (a - b) / b if math.isfinite(a) and math.isfinite(b) and b != 0 else math.nan
    return out


def curve_error(result: ImpactResult, ref: ImpactResult) -> float:
    """Whole-curve error of the first contact: RMS of f_engine(t) - f_ref(t) over the reference's
    f_m, on the reference's time grid from the start to the end of its first contact.

    The engine series is interpolated linearly (0 outside its samples). The reference grid is
    graded (fine at touch and separation), so the RMS is time-weighted (trapezoid rule):
    sqrt( integral (df)^2 dt / t_m ) / f_m. NaN when either series is missing.
    """
    if not (ref.contacts and result.t.size and ref.t.size and math.isfinite(ref.f_m) and ref.f_m > 0):
        return math.nan
    first = ref.contacts[0]
    t_ref = np.asarray(ref.t, float)
    inside = (t_ref >= first.t_start) & (t_ref <= first.t_end)
    t = t_ref[inside]
    if t.size < 2:
        return math.nan
    f_ref = np.asarray(ref.f, float)[inside]
    f_eng = np.interp(t, np.asarray(result.t, float), np.asarray(result.f, float), left=0.0, right=0.0)
    diff2 = (f_eng - f_ref) ** 2
    span = t[-1] - t[0]
    return float(math.sqrt(trapezoid(diff2, t) / span) / ref.f_m)


#: a first contact whose force falls below this fraction of its f_m next to the other side's separation is cut
#: differently by a small difference in the force: near-grazing, t_m compares two different contacts
GRAZING_FRACTION = 0.02
#: how far from the other side's separation [fraction of the reference's t_m] the dip is looked for
GRAZING_WINDOW = 0.05


def contact_cut(result: ImpactResult, ref: ImpactResult, against: str = "the reference") -> str:
    """"" or one line when t_m compares differently cut first contacts (engine vs reference; `against` names the
    reference in the line: "the linear theory" for a linear contact law's row): the engine's contact
    goes on past the reference's separation though its force fell below GRAZING_FRACTION of its f_m next to it (it
    bridged a separation the reference makes, e.g. a ball that re-touches a ringing beam 15 us later), or it ends
    where the reference's force dips below GRAZING_FRACTION of f_m without separating (it split the contact). Near-
    grazing, a force difference of a few percent moves t_m by a whole re-contact; f_m, delta_m and the curve are not
    affected."""
    if not (result.contacts and ref.contacts and result.t.size and ref.t.size):
        return ""
    t_eng, t_ref = result.contacts[0].t_end, ref.contacts[0].t_end
    if not (math.isfinite(t_eng) and math.isfinite(t_ref) and ref.t_m > 0):
        return ""
    if abs(t_eng - t_ref) <= GRAZING_WINDOW * ref.t_m:
        return ""
    later = t_eng > t_ref
    side, at = (result, t_ref) if later else (ref, t_eng)     # whose force to look into, and next to which time
    t, f = np.asarray(side.t, float), np.asarray(side.f, float)
    first = side.contacts[0]
    inside = (t > first.t_start) & (t < first.t_end)
    near = inside & (t >= at - GRAZING_WINDOW * ref.t_m) & (t <= at + GRAZING_WINDOW * ref.t_m)
    f_m = first.f_max
    if not near.any() or not (math.isfinite(f_m) and f_m > 0):
        return ""
    k = int(np.flatnonzero(near)[np.argmin(f[near])])
    low = f[k] / f_m
    # a dip: the force came down to it from a tenth of f_m or more and rises past the grazing level after it (not the
    # rise at touch, nor the fall at separation)
    before, after = f[inside & (t < t[k])], f[inside & (t > t[k])]
    if low >= GRAZING_FRACTION or not (before.size and after.size) or before.max() < 0.1 * f_m \
            or after.max() < GRAZING_FRACTION * f_m:
        return ""
    if later:
        what = (f"its force fell to {100 * low:.2g} % of its f_m at {t[k]:.4g} s, next to {against}'s separation "
                f"at {t_ref:.4g} s, and rose again: it bridged a separation {against} makes")
    else:
        what = (f"it separated at {t_eng:.4g} s, where {against}'s force falls to {100 * low:.2g} % of f_m "
                f"({t[k]:.4g} s) and rises again: it split a contact {against} keeps")
    return (f"t_m compares differently cut contacts ({what}); near-grazing, a small force difference moves t_m by a "
            f"whole re-contact: read f_m, delta_m and the curve")


# ---------------------------------------------------------------------------- where the error comes from
METRICS = ("t_m", "f_m", "delta_m")


def _finite(x) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def structure_errors(diagnostics: dict | None) -> dict[str, float]:
    """The engine's structure model against the scene's continuum, per metric: the adapter's plan
    diagnostics `model_error_t_m/_f_m/_delta_m` (the reference solver run on the engine model's own
    modes, relative to the scene's reference: signed fractions). NaN where the adapter reports none."""
    diag = diagnostics or {}
    return {m: _finite(diag.get(f"model_error_{m}")) for m in METRICS}


def error_split(err: dict[str, float], structure: dict[str, float], hertz: bool) -> dict[str, float]:
    """What the integrator and contact numerics add, per metric: err - structure (both signed
    fractions of the scene's reference, so err = structure + numerics exactly). NaN when either part
    is missing, and for a non-Hertz contact law (the structure part is measured with Hertz, so the
    difference would also hold the contact law's model-form error)."""
    if not hertz:
        return dict.fromkeys(METRICS, math.nan)
    return {m: err[m] - structure[m] if math.isfinite(err[m]) and math.isfinite(structure[m]) else math.nan
            for m in METRICS}


def vs_mujoco_c(diagnostics: dict | None) -> dict[str, float]:
    """MuJoCo Warp against MuJoCo C on the identical model, per metric: the signed fractions
    (Warp - C)/C of `diagnostics["vs_mujoco_c"]` (engines/mujoco_warp_.py); NaN when absent or when
    either run failed (the dict then holds a status instead)."""
    d = (diagnostics or {}).get("vs_mujoco_c")
    if not isinstance(d, dict):
        return dict.fromkeys(METRICS, math.nan)
    return {m: _finite(d.get(m)) for m in METRICS}
