"""Timoshenko beam modes (shear deformation and rotary inertia) for every support.

Equations (rectangle, Cowper's shear coefficient kappa = 10(1 + nu)/(12 + 11 nu), G = E/(2(1 + nu))):

    kappa G A (w'' - psi') = rho A w_tt,    E I psi'' + kappa G A (w' - psi) = rho I psi_tt.

A free vibration w = W(x) cos(omega t) is a sum of e^{lambda x} with
lambda^4 + b lambda^2 + c = 0, b = omega^2 rho (1/E + 1/(kappa G)), c = omega^4 rho^2/(E kappa G) - omega^2 rho A/(E I):
one pair of wave numbers is always real (W = cos k x, sin k x); the other is hyperbolic (a^2 > 0) below the
cut-off frequency omega_c = sqrt(kappa G A / (rho I)) and oscillatory (a^2 < 0) above it, so both spectra
(bending and the "second", shear-dominated one) come out of one frequency equation.

- simply supported: W = sin(n pi x / L) and the two roots of a quadratic in omega^2 per n (closed form);
- clamped-clamped and cantilever (clamped at x = 0, free at x = L): the 4x4 boundary determinant, in a basis
  that is bounded at every frequency (exponentially scaled hyperbolic functions above a L = 1, the regular pair
  cosh(a x), a sinh(a x) below it and across the cut-off) with signs matched between the bases, so that every
  sign change of the scaled determinant is a root; a grid of 32 points per pi of wave phase brackets the roots
  (pairs closer than a grid cell, where the two spectra veer, by zooming into |det|'s minima: `_close_pairs`),
  a vectorised bisection refines them to machine precision.

Shapes are normalised to max |W| = 1 over the span; modal mass = int (rho A W^2 + rho I Psi^2) dx (closed form:
W and Psi are combinations of four exponentials/sinusoids); phi = W at the impact point. max |W| is found in O(1)
work per mode (`timoshenko_shapes._clamped_shapes`): the exact sinusoid amplitude between the ends' tails below the cut-off, a few
chosen passes of the two-wave beat above it. The static flexibility at the impact point (bending + shear, by
Castigliano/Menabrea on the statically indeterminate beam) is exact and feeds the residual (mode-acceleration)
correction.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: grid points per pi of wave phase when bracketing roots of the frequency equation
GRID_PER_PI = 32
#: the root search starts at this fraction of the first simply supported frequency (below any support's first)
GRID_START = 1e-3


@dataclass(frozen=True)
class Section:
    """Beam data for Timoshenko theory: `young`, `shear_modulus` [Pa], `kappa` [-], `density` [kg/m^3],
    `area` [m^2], `second_moment` [m^4], `length` [m]."""

    young: float
    shear_modulus: float
    kappa: float
    density: float
    area: float
    second_moment: float
    length: float

    @classmethod
    def of(cls, beam) -> "Section":
        m = beam.material
        return cls(m.young, beam.shear_modulus, beam.shear_coefficient, m.density, beam.area,
                   beam.second_moment, beam.length)

    @property
    def cutoff(self) -> float:
        """omega_c = sqrt(kappa G A / (rho I)) [rad/s]: above it the second spectrum exists."""
        return math.sqrt(self.kappa * self.shear_modulus * self.area / (self.density * self.second_moment))


def wave_numbers(sec: Section, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a^2, k^2, q) at `omega` [rad/s]: a^2 [1/m^2] (> 0 below the cut-off), k^2 > 0, q = rho omega^2/(kappa G)."""
    w2 = np.asarray(omega, float) ** 2
    rho, E, kG = sec.density, sec.young, sec.kappa * sec.shear_modulus
    b = w2 * rho * (1.0 / E + 1.0 / kG)
    c = w2 * w2 * rho**2 / (E * kG) - w2 * rho * sec.area / (E * sec.second_moment)
    root = np.sqrt(b * b - 4.0 * c)
    a2 = -2.0 * c / (b + root)          # (-b + root)/2 without cancellation
    k2 = 0.5 * (b + root)
    return a2, k2, w2 * rho / kG


def ss_frequencies(sec: Section, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The n lowest simply supported frequencies [rad/s] (both spectra, sorted), their half-wave numbers m
    (W = sin(m pi x/L)) and branch (0: bending, 1: second spectrum). Closed form: for k = m pi/L,
    rho A rho I w^4 - w^2 [rho A (E I k^2 + kGA) + rho I kGA k^2] + kGA E I k^4 = 0."""
    m = np.arange(1, n + 1, dtype=float)
    k = m * math.pi / sec.length
    rA, rI = sec.density * sec.area, sec.density * sec.second_moment
    kGA, EI = sec.kappa * sec.shear_modulus * sec.area, sec.young * sec.second_moment
    bq = rA * (EI * k**2 + kGA) + rI * kGA * k**2
    disc = np.sqrt(bq * bq - 4.0 * rA * rI * kGA * EI * k**4)
    low = np.sqrt(2.0 * kGA * EI * k**4 / (bq + disc))
    high = np.sqrt((bq + disc) / (2.0 * rA * rI))
    om = np.concatenate([low, high[high <= low[-1]]])
    mm = np.concatenate([m, m[high <= low[-1]]])
    br = np.concatenate([np.zeros(n, int), np.ones(int(np.sum(high <= low[-1])), int)])
    order = np.argsort(om, kind="stable")[:n]
    return om[order], mm[order], br[order]


# ----------------------------------------------------------------------------- clamped supports: the determinant

def _values(sec: Section, omega: np.ndarray, x: np.ndarray):
    """The four basis solutions for many frequencies at points x [m]: omega (n,), x (n, m) or (m,).

    Returns (w, psi, w', psi') each (n, 4, m), and the sign per frequency that matches determinants in this
    basis to the regular basis (cosh a x, a sinh a x, cos k x, sin k x). Every value is bounded: the
    hyperbolic pair is exponentially scaled (e^{a (x - L)}, e^{-a x}) when a L > 1.
    """
    omega = np.asarray(omega, float)
    a2, k2, q = (v[:, None] for v in wave_numbers(sec, omega))
    x = np.broadcast_to(np.asarray(x, float), (len(omega), np.shape(x)[-1]))
    L = sec.length
    expo = a2 * L * L > 1.0
    a = np.sqrt(np.abs(a2))
    safe_a = np.where(a > 0, a, 1.0)
    ep, em = np.exp(np.where(expo, a * (x - L), 0.0)), np.exp(np.where(expo, -a * x, 0.0))
    g = (a2 + q) / safe_a
    hyper = a2 >= 0
    ax = np.where(expo, 0.0, a * x)
    axh = np.where(hyper, ax, 0.0)
    C = np.where(hyper, np.cosh(axh), np.cos(ax))
    S = np.where(a > 0, np.where(hyper, np.sinh(axh), np.sin(ax)) / safe_a, x)
    k = np.sqrt(k2)
    c, s = np.cos(k * x), np.sin(k * x)
    gk = (q - k2) / k
    w = np.stack([np.where(expo, ep, C), np.where(expo, em, a2 * S), c, s], axis=1)
    p = np.stack([np.where(expo, g * ep, (a2 + q) * S), np.where(expo, -g * em, (a2 + q) * C),
                  gk * s, -gk * c], axis=1)
    dw = np.stack([np.where(expo, a * ep, a2 * S), np.where(expo, -a * em, a2 * C), -k * s, k * c], axis=1)
    dp = np.stack([np.where(expo, (a2 + q) * ep, (a2 + q) * C), np.where(expo, (a2 + q) * em, (a2 + q) * a2 * S),
                   (q - k2) * c, (q - k2) * s], axis=1)
    return w, p, dw, dp, np.where(expo[:, 0], -1.0, 1.0)


def _combined(sec: Section, omega: np.ndarray, x: np.ndarray, c: np.ndarray, derivs: bool = False):
    """W, Psi (and with `derivs` also W', Psi') of the modes sum_i c[:, i] basis_i at points x (n, m) or (m,).

    Same basis as `_values`, combined directly (no (n, 4, m) arrays)."""
    omega = np.asarray(omega, float)
    a2, k2, q = (v[:, None] for v in wave_numbers(sec, omega))
    x = np.broadcast_to(np.asarray(x, float), (len(omega), np.shape(x)[-1]))
    L = sec.length
    c0, c1, c2, c3 = (c[:, i:i + 1] for i in range(4))
    k = np.sqrt(k2)
    cs, sn = np.cos(k * x), np.sin(k * x)
    gk = (q - k2) / k
    W = c2 * cs + c3 * sn
    P = gk * (c2 * sn - c3 * cs)
    if derivs:
        dW = k * (c3 * cs - c2 * sn)
        dP = (q - k2) * (c2 * cs + c3 * sn)
    expo = (a2 * L * L > 1.0)[:, 0]
    a = np.sqrt(np.abs(a2))
    if np.any(expo):
        r = expo
        ar, xr, qr = a[r], x[r], q[r]
        ep, em = np.exp(ar * (xr - L)), np.exp(-ar * xr)
        u, v = c0[r] * ep, c1[r] * em
        g = (ar * ar + qr) / ar
        W[r] += u + v
        P[r] += g * (u - v)
        if derivs:
            dW[r] += ar * (u - v)
            dP[r] += (ar * ar + qr) * (u + v)
    if not np.all(expo):
        r = ~expo
        ar, xr, qr, a2r = a[r], x[r], q[r], a2[r]
        hyper = a2r >= 0
        ax = ar * xr
        C = np.where(hyper, np.cosh(np.where(hyper, ax, 0.0)), np.cos(ax))
        safe = np.where(ar > 0, ar, 1.0)
        S = np.where(ar > 0, np.where(hyper, np.sinh(np.where(hyper, ax, 0.0)), np.sin(ax)) / safe, xr)
        W[r] += c0[r] * C + c1[r] * a2r * S
        P[r] += (a2r + qr) * (c0[r] * S + c1[r] * C)
        if derivs:
            dW[r] += a2r * (c0[r] * S + c1[r] * C)
            dP[r] += (a2r + qr) * (c0[r] * C + c1[r] * a2r * S)
    return (W, P, dW, dP) if derivs else (W, P)


def _boundary_matrices(sec: Section, support: str, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 4, 4): rows the four boundary conditions, columns the four basis solutions (rows scaled to max 1)."""
    w, p, dw, dp, sign = _values(sec, omega, np.array([0.0, sec.length]))
    w0, p0, dw0, dp0 = w[:, :, 0], p[:, :, 0], dw[:, :, 0], dp[:, :, 0]
    w1, p1, dw1, dp1 = w[:, :, 1], p[:, :, 1], dw[:, :, 1], dp[:, :, 1]
    if support == "clamped-clamped":         # w = psi = 0 at both ends
        rows = [w0, p0, w1, p1]
    elif support == "cantilever":            # clamped at 0; free at L: psi' = 0, w' - psi = 0
        rows = [w0, p0, dp1, dw1 - p1]
    elif support == "simply-supported":      # w = psi' = 0 at both ends (used to test the determinant route)
        rows = [w0, dp0, w1, dp1]
    else:
        raise ValueError(f"unknown support {support!r}")
    M = np.stack(rows, axis=1)
    M /= np.max(np.abs(M), axis=2, keepdims=True)
    return M, sign


def frequency_function(sec: Section, support: str, omega: np.ndarray) -> np.ndarray:
    """Scaled determinant of the boundary matrix; its sign changes are exactly the natural frequencies."""
    M, sign = _boundary_matrices(sec, support, np.atleast_1d(np.asarray(omega, float)))
    return sign * np.linalg.det(M)


def _phase(sec: Section, omega: np.ndarray) -> np.ndarray:
    """L (k + Im a): the total wave phase over the span (roots are about pi apart in it)."""
    a2, k2, _ = wave_numbers(sec, omega)
    return sec.length * (np.sqrt(k2) + np.sqrt(np.maximum(-a2, 0.0)))


def _grid(sec: Section, omega_hi: float) -> np.ndarray:
    """Frequencies from below the first natural frequency to omega_hi with <= pi/GRID_PER_PI of wave phase
    between neighbours.

    The grid starts at GRID_START x the first simply supported frequency: every support's first frequency lies
    above that (a cantilever's is ~0.36x it), whatever omega_hi is (a start tied to omega_hi, 1e-6 omega_hi,
    skipped the first root of a slender cantilever once n reached 4096 modes)."""
    lo = min(GRID_START * float(ss_frequencies(sec, 1)[0][0]), 0.5 * omega_hi)
    om = np.geomspace(lo, omega_hi, 400)
    for _ in range(20):
        ph = _phase(sec, om)
        steps = np.maximum(np.ceil(np.diff(ph) / (math.pi / GRID_PER_PI)).astype(int), 1)
        if np.all(steps == 1):
            return om
        i = np.repeat(np.arange(len(steps)), steps)
        first = np.repeat(np.cumsum(steps) - steps, steps)
        frac = (np.arange(len(i)) - first) / steps[i]
        om = np.concatenate([om[i] + frac * (om[i + 1] - om[i]), om[-1:]])
    raise RuntimeError("timoshenko frequency grid did not reach its phase resolution")   # pragma: no cover


def _bisect(sec: Section, support: str, lo: np.ndarray, hi: np.ndarray, f_lo: np.ndarray) -> np.ndarray:
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        done = (mid <= lo) | (mid >= hi)
        if np.all(done):
            break
        f_mid = frequency_function(sec, support, mid)
        left = np.sign(f_mid) == np.sign(f_lo)
        lo = np.where(left & ~done, mid, lo)
        f_lo = np.where(left & ~done, f_mid, f_lo)
        hi = np.where(~left & ~done, mid, hi)
    return 0.5 * (lo + hi)


@lru_cache(maxsize=64)
def clamped_frequencies(sec: Section, support: str, n: int) -> np.ndarray:
    """The n lowest natural frequencies [rad/s] of a clamped-clamped or cantilever (or, as a check,
    simply supported) Timoshenko beam, from the transcendental frequency equation."""
    # the k-th frequency of any support lies below the (k + 2)-th simply supported one (the supports differ
    # by at most two constraints); extend the search until n roots are found
    hi = float(ss_frequencies(sec, n + 2)[0][-1]) * 1.05
    while True:
        om = _grid(sec, hi)
        f = frequency_function(sec, support, om)
        idx = np.flatnonzero(np.sign(f[:-1]) * np.sign(f[1:]) < 0)
        lo, up, f_lo = om[idx], om[idx + 1], f[idx]
        extra = _close_pairs(sec, support, om, f)
        if len(extra[0]):
            lo, up, f_lo = (np.concatenate([u, v]) for u, v in zip((lo, up, f_lo), extra))
            order = np.argsort(lo, kind="stable")
            lo, up, f_lo = lo[order], up[order], f_lo[order]
        if len(lo) >= n:
            return _bisect(sec, support, lo[:n], up[:n], f_lo[:n])
        hi *= 1.5




def _close_pairs(sec: Section, support: str, om: np.ndarray, f: np.ndarray, points: int = 17, levels: int = 12):
    """Brackets (lo, hi, f(lo)) of pairs of roots closer than the grid spacing, which the grid's sign changes
    miss: two roots in one cell leave a local minimum of |f| with one sign on both sides (its depth is no guide:
    a pair 3.4e-5 apart left 0.58 of the smaller neighbour). Each such minimum's two cells are resampled
    (`points`) and, while no sign change shows, zoomed about the smallest |f| (8x per level, `levels` levels:
    pairs down to ~1e-13 of the cell apart). ~0.2 % of the grid points are such minima: ~+20 % grid cost.
    Seed 5017 of the random Timoshenko beams: a pair 1.8e-4 apart (relative) at 1.82e6 rad/s was missed at 4096
    modes (found at 8192), and every higher mode shifted by two."""
    a = np.abs(f)
    s = np.sign(f[:-1]) * np.sign(f[1:]) < 0
    i = np.arange(1, len(f) - 1)
    dip = (a[i] <= a[i - 1]) & (a[i] <= a[i + 1]) & ~s[i - 1] & ~s[i]
    i = i[dip]
    out_lo, out_hi, out_f = [], [], []
    lo, hi = om[i - 1], om[i + 1]
    t = np.linspace(0.0, 1.0, points)
    for _ in range(levels):
        if not len(lo):
            break
        x = lo[:, None] + (hi - lo)[:, None] * t
        fx = frequency_function(sec, support, x.ravel()).reshape(x.shape)
        ch = np.sign(fx[:, :-1]) * np.sign(fx[:, 1:]) < 0
        found = ch.any(axis=1)
        r, c = np.nonzero(ch & found[:, None])
        out_lo.append(x[r, c])
        out_hi.append(x[r, c + 1])
        out_f.append(fx[r, c])
        keep = ~found
        x, fx = x[keep], fx[keep]
        j = np.clip(np.argmin(np.abs(fx), axis=1), 1, points - 2)
        rows = np.arange(len(x))
        lo, hi = x[rows, j - 1], x[rows, j + 1]
    if not out_lo:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return np.concatenate(out_lo), np.concatenate(out_hi), np.concatenate(out_f)


def _null_vectors(sec: Section, support: str, om: np.ndarray) -> np.ndarray:
    """(n, 4) coefficients of the modes in the `_values` basis (null vectors of the boundary matrices)."""
    M, _ = _boundary_matrices(sec, support, om)
    return np.linalg.svd(M)[2][:, -1, :]            # row scaling does not change them


@lru_cache(maxsize=64)
def timoshenko_modes(sec: Section, support: str, n: int, impact_x: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(omega [rad/s], modal_mass [kg], phi [-]) of the n lowest modes, shapes max-normalised in W."""
    rA, rI, L = sec.density * sec.area, sec.density * sec.second_moment, sec.length
    if support == "simply-supported":
        om, m, _ = ss_frequencies(sec, n)
        k = m * math.pi / L
        _, k2, q = wave_numbers(sec, om)
        # W = sin(k x) is a solution at omega only with the wave number k itself: Psi = (k^2 - q)/k cos(k x)
        psi_amp = (k * k - q) / k
        return om, 0.5 * L * (rA + rI * psi_amp**2), np.sin(k * impact_x)
    from impactval.reference.timoshenko_shapes import _clamped_shapes     # the shapes' module imports this one

    om = clamped_frequencies(sec, support, n)
    mm, phi = _clamped_shapes(sec, support, om, impact_x)
    return om, mm, phi


# ----------------------------------------------------------------------------- static flexibility

def static_flexibility(sec: Section, support: str, a: float) -> float:
    """w/F [m/N] at x = a under a point load F at x = a, bending + shear (Timoshenko statics).

    Complementary energy U = int M^2/(2 E I) + V^2/(2 kappa G A) dx with M(x) = M0 + V0 x - F <x - a>,
    V = dM/dx; redundants (clamped-clamped: M0, V0) minimise U; the flexibility is 2 U / F^2.
    """
    L, EI, kGA = sec.length, sec.young * sec.second_moment, sec.kappa * sec.shear_modulus * sec.area
    b = L - a

    def energy_terms(M0: float, V0: float) -> float:
        # M linear on [0, a] and [a, L]: int M^2 = h (M_l^2 + M_l M_r + M_r^2)/3 exactly
        Ma, ML = M0 + V0 * a, M0 + V0 * L - b
        bend = (a * (M0 * M0 + M0 * Ma + Ma * Ma) + b * (Ma * Ma + Ma * ML + ML * ML)) / 3.0
        shear = a * V0 * V0 + b * (V0 - 1.0) ** 2
        return bend / EI + shear / kGA          # = 2 U at F = 1

    if support == "simply-supported":
        return energy_terms(0.0, b / L)
    if support == "cantilever":                 # clamped at 0, free at L: V = 1, M = -(a - x) on [0, a]
        return energy_terms(-a, 1.0)
    if support == "clamped-clamped":            # 2U is quadratic in (M0, V0): minimise exactly
        e0 = energy_terms(0.0, 0.0)
        g = np.array([energy_terms(1.0, 0.0) - energy_terms(-1.0, 0.0),
                      energy_terms(0.0, 1.0) - energy_terms(0.0, -1.0)]) / 2.0
        h11 = energy_terms(1.0, 0.0) + energy_terms(-1.0, 0.0) - 2 * e0
        h22 = energy_terms(0.0, 1.0) + energy_terms(0.0, -1.0) - 2 * e0
        h12 = (energy_terms(1.0, 1.0) - energy_terms(1.0, -1.0) - energy_terms(-1.0, 1.0)
               + energy_terms(-1.0, -1.0)) / 4.0
        H = np.array([[h11, h12], [h12, h22]])
        z = np.linalg.solve(H, -g)
        return energy_terms(float(z[0]), float(z[1]))
    raise ValueError(f"unknown support {support!r}")
