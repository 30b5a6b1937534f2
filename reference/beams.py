"""Euler-Bernoulli beam modes: frequencies, max-normalised shapes, modal masses, static flexibility.

Shapes are normalised to max |phi| = 1 over the span (physics.md sec. 3). Clamped shapes are
evaluated in an exponentially scaled form, so high mode numbers neither overflow nor cancel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass(frozen=True)
class Modes:
    """A modal structure seen from the impact point.

    `omega` [rad/s], `modal_mass` [kg] (for max-normalised shapes), `phi` [-] shape values at the
    impact point; `residual_flexibility` [m/N]: static flexibility of all modes *not* listed
    (0 when unknown or not wanted).
    """

    omega: np.ndarray
    modal_mass: np.ndarray
    phi: np.ndarray
    residual_flexibility: float = 0.0

    @property
    def n(self) -> int:
        return len(self.omega)


def truncate_modes(modes: Modes, n: int, residual: bool = False) -> Modes:
    """The n lowest-frequency modes of `modes`; with `residual`, the static flexibility of the
    dropped ones is added to the residual flexibility (mode-acceleration correction)."""
    order = np.argsort(modes.omega, kind="stable")
    keep, drop = order[:n], order[n:]
    extra = float(np.sum(modes.phi[drop] ** 2 / (modes.modal_mass[drop] * modes.omega[drop] ** 2))) if residual else 0.0
    return Modes(modes.omega[keep], modes.modal_mass[keep], modes.phi[keep], modes.residual_flexibility + extra)


@lru_cache(maxsize=64)
def _beta_l(support: str, n: int) -> np.ndarray:
    """First n roots beta_n L of the frequency equation of `support`."""
    from scipy import optimize      # lazy: keeps the CLI's start-up fast

    k = np.arange(1, n + 1, dtype=float)
    if support == "simply-supported":
        return k * math.pi
    if support == "clamped-clamped":       # cos x cosh x = 1  <=>  cos x - sech x = 0, x_n ~ (n + 1/2) pi
        centre, eq = (k + 0.5) * math.pi, (lambda x: math.cos(x) - 1.0 / math.cosh(x) if x < 700 else math.cos(x))
    elif support == "cantilever":          # cos x cosh x = -1, x_n ~ (n - 1/2) pi
        centre, eq = (k - 0.5) * math.pi, (lambda x: math.cos(x) + 1.0 / math.cosh(x) if x < 700 else math.cos(x))
    else:
        raise ValueError(f"unknown support {support!r}")
    out = np.empty(n)
    for i, c in enumerate(centre):
        if c > 40:   # sech(x) < 1e-17: the root is (n +- 1/2) pi to machine precision
            out[i] = c
        else:
            out[i] = optimize.brentq(eq, max(c - math.pi / 2, 1e-9), c + math.pi / 2, xtol=1e-15, rtol=1e-15)
    return out


def _shape(support: str, bl: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """Unnormalised classical shapes at xi = x/L (rows: modes, columns: points); overflow-free."""
    bl = np.asarray(bl)[:, None]
    xi = np.asarray(xi)[None, :]
    if support == "simply-supported":
        return np.sin(bl * xi)
    bx = bl * xi
    big_e = np.exp(-bl)                               # e^{-beta L}
    s, c = np.sin(bl), np.cos(bl)
    if support == "clamped-clamped":                  # sigma = (cosh - cos)/(sinh - sin)
        denom = 1.0 - big_e**2 - 2.0 * big_e * s      # (sinh bL - sin bL) * 2 e^{-bL}
        one_minus_sigma_scaled = 2.0 * (c - s - big_e) / denom        # (1 - sigma) e^{bL}
    else:                                             # cantilever: sigma = (cosh + cos)/(sinh + sin)
        denom = 1.0 - big_e**2 + 2.0 * big_e * s      # (sinh bL + sin bL) * 2 e^{-bL}
        one_minus_sigma_scaled = 2.0 * (s - c - big_e) / denom
    sigma = 1.0 - one_minus_sigma_scaled * big_e
    # cosh bx - sigma sinh bx = [(1 - sigma) e^{bx} + (1 + sigma) e^{-bx}] / 2
    hyper = 0.5 * (one_minus_sigma_scaled * np.exp(bx - bl) + (1.0 + sigma) * np.exp(-bx))
    return hyper - np.cos(bx) + sigma * np.sin(bx)


UNIVERSAL_BL = 60.0


def shape_max_one(support: str, b: float) -> float:
    """max over the span of |unnormalised shape| of the mode with beta L = b (sampled, then refined)."""
    from scipy import optimize
    # the hyperbolic terms die out 40/b from the ends; sample both end zones finely, plus the middle
    npts = int(min(64 * b / math.pi, 4000)) + 64
    zone = min(1.0, 40.0 / b)
    xi = np.unique(np.concatenate([np.linspace(0, zone, npts), np.linspace(1 - zone, 1, npts),
                                   np.linspace(0, 1, 2 * npts)]))
    vals = np.abs(_shape(support, np.array([b]), xi))[0]
    k = int(np.argmax(vals))
    lo, hi = xi[max(k - 1, 0)], xi[min(k + 1, len(xi) - 1)]
    res = optimize.minimize_scalar(lambda x: -abs(_shape(support, np.array([b]), np.array([x]))[0, 0]),
                                   bounds=(lo, hi), method="bounded", options={"xatol": 1e-13})
    return float(max(vals[k], -res.fun))


@lru_cache(maxsize=64)
def _shape_max(support: str, n: int) -> np.ndarray:
    """max over the span of |unnormalised shape| for the first n modes."""
    if support == "simply-supported":
        return np.ones(n)
    bl = _beta_l(support, n)
    out = np.empty(n)
    for i, b in enumerate(bl):
        if i > 0 and bl[i - 1] > UNIVERSAL_BL:
            # beyond beta L ~ 60, sigma = 1 to machine precision and each end zone is the same
            # function of beta x for every mode: the maximum no longer changes (tested)
            out[i] = out[i - 1]
        else:
            out[i] = shape_max_one(support, b)
    return out


def beam_frequencies(support: str, n: int, length: float, young: float, second_moment: float,
                     density: float, area: float) -> np.ndarray:
    """omega_n = (beta_n L)^2 / L^2 * sqrt(E I / (rho A)) [rad/s] for the first n modes."""
    return _beta_l(support, n) ** 2 / length**2 * math.sqrt(young * second_moment / (density * area))


def beam_shapes(support: str, n: int, xi: np.ndarray) -> np.ndarray:
    """Max-normalised shapes of the first n modes at xi = x/L (array n x len(xi))."""
    return _shape(support, _beta_l(support, n), np.atleast_1d(np.asarray(xi, float))) / _shape_max(support, n)[:, None]


def beam_modal_masses(support: str, n: int, density: float, area: float, length: float) -> np.ndarray:
    """Modal masses [kg] of max-normalised shapes: rho A int phi^2 dx = rho A L / max^2
    (the classical shapes have int_0^L phi^2 dx = L/2 (simply supported) or L (clamped, cantilever))."""
    mass = density * area * length
    if support == "simply-supported":
        return np.full(n, 0.5 * mass)
    return mass / _shape_max(support, n) ** 2


def beam_static_flexibility(support: str, length: float, young: float, second_moment: float, a: float) -> float:
    """Static flexibility w/F [m/N] at x = a under a point load at x = a (all modes together)."""
    ei = young * second_moment
    b = length - a
    if support == "simply-supported":
        return a**2 * b**2 / (3.0 * ei * length)
    if support == "clamped-clamped":
        return a**3 * b**3 / (3.0 * ei * length**3)
    if support == "cantilever":
        return a**3 / (3.0 * ei)
    raise ValueError(f"unknown support {support!r}")


def beam_modes(beam, n: int, residual: bool = False) -> Modes:
    """The first n modes of a `Beam` scene target seen from its impact point (Euler-Bernoulli or, with
    `beam.theory == "timoshenko"`, Timoshenko: reference/timoshenko.py).

    With `residual`, the static flexibility of all higher modes (the exact static flexibility
    minus the n retained modes' share) is attached for the mode-acceleration correction.
    """
    if getattr(beam, "theory", "euler-bernoulli") == "timoshenko":
        return _timoshenko_beam_modes(beam, n, residual)
    mat = beam.material
    omega = beam_frequencies(beam.support, n, beam.length, mat.young, beam.second_moment, mat.density, beam.area)
    phi = beam_shapes(beam.support, n, np.array([beam.impact_at]))[:, 0]
    mm = beam_modal_masses(beam.support, n, mat.density, beam.area, beam.length)
    res = 0.0
    if residual:
        total = beam_static_flexibility(beam.support, beam.length, mat.young, beam.second_moment, beam.impact_x)
        res = max(total - float(np.sum(phi**2 / (mm * omega**2))), 0.0)
    return Modes(omega, mm, phi, res)


def _timoshenko_beam_modes(beam, n: int, residual: bool) -> Modes:
    """Timoshenko modes (both spectra, frequency order); computed for the next power of two >= n and cut, so
    that the automatic mode-count doubling reuses them."""
    from impactval.reference import timoshenko as tim

    sec = tim.Section.of(beam)
    big = 1 << max(int(n) - 1, 31).bit_length()
    omega, mm, phi = (v[:n] for v in tim.timoshenko_modes(sec, beam.support, big, beam.impact_x))
    res = 0.0
    if residual:
        total = tim.static_flexibility(sec, beam.support, beam.impact_x)
        res = max(total - float(np.sum(phi**2 / (mm * omega**2))), 0.0)
    return Modes(omega.copy(), mm.copy(), phi.copy(), res)
