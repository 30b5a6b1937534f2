"""Errors of one impact result against a reference (style.md, pattern 1: ImpactResult -> numbers).

All errors are signed relative differences (engine - reference) / reference, except the
whole-curve error, which is a non-negative RMS.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import trapezoid

from impactval.reference.result import ImpactResult


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
