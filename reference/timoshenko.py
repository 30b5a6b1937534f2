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
work per mode (`_clamped_shapes`): the exact sinusoid amplitude between the ends' tails below the cut-off, a few
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


def _gauss(L: float, panels: int, order: int = 10) -> tuple[np.ndarray, np.ndarray]:
    t, wt = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, L, panels + 1)
    h = np.diff(edges)
    x = (edges[:-1, None] + 0.5 * h[:, None] * (t[None, :] + 1.0)).ravel()
    return x, (0.5 * h[:, None] * wt[None, :]).ravel()


def _null_vectors(sec: Section, support: str, om: np.ndarray) -> np.ndarray:
    """(n, 4) coefficients of the modes in the `_values` basis (null vectors of the boundary matrices)."""
    M, _ = _boundary_matrices(sec, support, om)
    return np.linalg.svd(M)[2][:, -1, :]            # row scaling does not change them


def _grid_mass_peak(sec: Section, om: np.ndarray, coeffs: np.ndarray, starts: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(int rho A W^2 + rho I Psi^2 dx [kg], max |W|) of the unnormalised modes, by a grid over the whole span.

    max |W|: a grid of 16 points per pi of wave phase, then Newton on W' = 0 (W'' = Psi' - q W) from the best
    grid point; the mass integral: Gauss-Legendre, 10 points per half pi of phase. O(n) work per mode."""
    rA, rI, L = sec.density * sec.area, sec.density * sec.second_moment, sec.length
    n = len(om)
    mass, peaks = np.empty(n), np.empty(n)
    ph = _phase(sec, om)
    _, _, qs = wave_numbers(sec, om)
    start = 0
    while start < n:
        end = start + 1                                # chunk: modes x grid points <= 2e5
        while end < n and (end + 1 - start) * (20 * ph[end] / math.pi + 100) <= 2e5:
            end += 1
        sl = slice(start, end)
        o, c, q = om[sl], coeffs[sl], qs[sl][:, None]
        top = float(ph[sl].max())
        xs = np.linspace(0.0, L, int(16 * top / math.pi) + 65)
        peaks[sl] = _refine_peak(sec, o, c, q, np.broadcast_to(xs, (len(o), len(xs))), xs[1] - xs[0], starts)
        xg, wg = _gauss(L, int(2 * top / math.pi) + 8)
        Wg, Pg = _combined(sec, o, xg, c)
        mass[sl] = (Wg * Wg * rA + Pg * Pg * rI) @ wg
        start = end
    return mass, peaks


def _refine_peak(sec: Section, o: np.ndarray, c: np.ndarray, q: np.ndarray, xs: np.ndarray, h,
                 starts: int = 1) -> np.ndarray:
    """max |W| per mode: from the `starts` best local maxima of |W| over the grid points xs (n, m) (spacing h,
    scalar or (n,)), 6 Newton steps on W' = 0 (W'' = Psi' - q W) each, kept within one spacing and the span.

    Several starts: a grid of 16 points per pi of phase reads a peak up to ~0.5 % low, so when W has peaks of
    nearly equal height (two waves above the cut-off) the best grid point can sit next to a lower one."""
    L = sec.length
    W = np.abs(_combined(sec, o, xs, c)[0])
    rows = np.arange(len(o))[:, None]
    if starts == 1:
        j = np.argmax(W, axis=1)[:, None]
    else:
        pad = np.pad(W, ((0, 0), (1, 1)), constant_values=-1.0)
        left, right = pad[:, :-2], pad[:, 2:]
        # rank the local maxima by the parabola through three points (error O(h^4), the point's own O(h^2))
        curv = np.maximum(2 * W - left - right, 1e-300)
        score = np.where((W >= left) & (W >= right), W + (right - left) ** 2 / (8 * curv), -1.0)
        starts = min(starts, W.shape[1])
        j = np.argpartition(-score, starts - 1, axis=1)[:, :starts]
    peak = np.max(W[rows, j], axis=1)
    h = np.reshape(np.broadcast_to(h, (len(o),)), (-1, 1))
    x0 = xs[rows, j]
    x = x0
    for _ in range(6):
        wv, _, dwv, dpv = _combined(sec, o, x, c, derivs=True)
        d2 = dpv - q * wv
        step = np.where(d2 != 0, dwv / np.where(d2 != 0, d2, 1.0), 0.0)
        x = np.clip(x - step, np.maximum(x0 - h, 0.0), np.minimum(x0 + h, L))
    return np.maximum(peak, np.max(np.abs(_combined(sec, o, x, c)[0]), axis=1))


def _clamped_shapes_grid(sec: Section, support: str, om: np.ndarray, impact_x: float) -> tuple[np.ndarray, np.ndarray]:
    """(modal_mass, phi) by grids over the whole span for every mode: O(n^2) for n modes. The reference that
    `_clamped_shapes` is tested against."""
    coeffs = _null_vectors(sec, support, om)
    mass, peak = _grid_mass_peak(sec, om, coeffs)
    phi = _combined(sec, om, np.array([impact_x]), coeffs)[0][:, 0]
    return mass / peak**2, phi / peak


# ----------------------------------------------------------------------------- shapes in O(1) per mode

def _atoms(sec: Section, om: np.ndarray, c: np.ndarray):
    """W and Psi of the modes as combinations of four atoms each: returns (kind, rates, w, p) with kind (n,)
    True where the atoms are (e^{a (x - L)}, e^{-a x}, cos k x, sin k x) (a^2 L^2 > 1) and False where they are
    (cos b x, sin b x, cos k x, sin k x), b = |a| (a^2 L^2 < -1: above the cut-off); rates (n, 2) = (a or b, k);
    w, p (n, 4) the atoms' coefficients in W and Psi."""
    a2, k2, q = wave_numbers(sec, om)
    a, k = np.sqrt(np.abs(a2)), np.sqrt(k2)
    expo = a2 * sec.length**2 > 1.0
    gk = (q - k2) / k
    safe_a = np.where(a > 0, a, 1.0)           # a = 0 only at the cut-off, a mode these atoms are not used for
    g = (a2 + q) / safe_a
    c0, c1, c2, c3 = c.T
    a = safe_a
    w = np.stack([c0, np.where(expo, c1, c1 * a2 / a), c2, c3], axis=1)
    p = np.stack([np.where(expo, g * c0, (a2 + q) * c1), np.where(expo, -g * c1, (a2 + q) * c0 / a),
                  -gk * c3, gk * c2], axis=1)
    return expo, np.stack([a, k], axis=1), w, p


def _int_cos(z: np.ndarray, L: float) -> np.ndarray:
    """int_0^L cos(z x) dx = sin(z L)/z, stable at z = 0."""
    return L * np.sinc(z * L / math.pi)


def _int_sin(z: np.ndarray, L: float) -> np.ndarray:
    """int_0^L sin(z x) dx = (1 - cos z L)/z = 2 sin^2(z L/2)/z, stable at z = 0."""
    return L * np.sin(0.5 * z * L) * np.sinc(0.5 * z * L / math.pi)


def _trig_gram(al: np.ndarray, be: np.ndarray, L: float) -> np.ndarray:
    """(n, 2, 2): int_0^L of (cos al x, sin al x) x (cos be x, sin be x)."""
    cm, cp = _int_cos(al - be, L), _int_cos(al + be, L)
    sm, sp = _int_sin(al - be, L), _int_sin(al + be, L)
    return 0.5 * np.stack([np.stack([cm + cp, sp - sm], -1), np.stack([sp + sm, cm - cp], -1)], -2)


def _atom_gram(expo: np.ndarray, rates: np.ndarray, L: float) -> np.ndarray:
    """(n, 4, 4): int_0^L atom_i atom_j dx for the atoms of `_atoms`, in closed form with every factor bounded."""
    a, k = rates[:, 0], rates[:, 1]
    n = len(a)
    G = np.empty((n, 4, 4))
    G[:, 2:, 2:] = _trig_gram(k, k, L)
    t = ~expo
    if np.any(t):
        G[t, :2, :2] = _trig_gram(a[t], a[t], L)
        G[t, :2, 2:] = _trig_gram(a[t], k[t], L)
    if np.any(expo):
        ae, ke = a[expo], k[expo]
        same = -np.expm1(-2.0 * ae * L) / (2.0 * ae)        # int e^{2a(x-L)} = int e^{-2ax}
        cross = L * np.exp(-ae * L)                         # int e^{a(x-L)} e^{-ax}
        G[expo, 0, 0], G[expo, 1, 1], G[expo, 0, 1], G[expo, 1, 0] = same, same, cross, cross
        eikL = np.exp(1j * ke * L)
        right = (eikL - np.exp(-ae * L)) / (ae + 1j * ke)   # int e^{a(x-L)} e^{ikx}
        left = (1.0 - np.exp(-ae * L) * eikL) / (ae - 1j * ke)   # int e^{-ax} e^{ikx}
        G[expo, 0, 2], G[expo, 0, 3] = right.real, right.imag
        G[expo, 1, 2], G[expo, 1, 3] = left.real, left.imag
    G[:, 2:, :2] = np.swapaxes(G[:, :2, 2:], 1, 2)
    return G


#: a tail e^{-a x} counts where it exceeds this fraction of the sinusoid's amplitude (below roundoff elsewhere)
TAIL_NEGLIGIBLE = 1e-18
#: candidate passes per sign searched for max |W| above the cut-off (3 suffice; one spare for near ties)
PASSES = 4
#: grid points per pi of wave phase in the windows and passes searched for max |W| (then Newton from several
#: starts ranked by a parabola through three points)
WINDOW_PER_PI = 16


def _window_peaks(sec: Section, om, c, q, lo: np.ndarray, hi: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """max |W| over the union of intervals [lo, hi] (n, J) per mode: WINDOW_PER_PI grid points per pi of phase at `rate`
    [1/m] (n,) over the widest interval, then Newton; modes in chunks of <= 2e5 grid points."""
    n, J = lo.shape
    width = np.max(hi - lo, axis=1)
    m_need = np.ceil(WINDOW_PER_PI * rate * width / math.pi).astype(int) + 17
    out = np.empty(n)
    order = np.argsort(m_need, kind="stable")
    start = 0
    while start < n:
        m = int(m_need[order[min(start + 63, n - 1)]])
        end = start + max(1, min(64, int(2e5 // (J * m))))
        idx = order[start:end]
        m = int(m_need[idx].max())
        t = np.linspace(0.0, 1.0, m)
        xs = (lo[idx, :, None] + (hi - lo)[idx, :, None] * t).reshape(len(idx), J * m)
        h = np.max(hi[idx] - lo[idx], axis=1) / (m - 1)
        out[idx] = _refine_peak(sec, om[idx], c[idx], q[idx, None], xs, h, max(3 * J, 16))
        start = end
    return out


def _pass_windows(k1, k2, p1, p2, L: float, block: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (n, 2 PASSES): for W = R1 cos(k1 x - p1) + R2 cos(k2 x - p2) (k1 <= k2), the PASSES passes
    |k1 x - p1 - s - 2 pi j| <= pi (s = 0 for max W, pi for min W) whose centres x_j have the other wave's phase
    k2 x_j - p2 - s closest to 0 (mod 2 pi), cut to [0, L]. In turns that phase is alpha j + beta (alpha = k2/k1),
    and the passes with the smallest |alpha j + beta mod 1| are found in O(sqrt(passes)) per mode (`_nearest_turns`)."""
    n = len(k1)
    lo, hi = np.empty((n, 2 * PASSES)), np.empty((n, 2 * PASSES))
    alpha = k2 / k1
    for col, shift in ((0, 0.0), (PASSES, math.pi)):
        # passes whose centre is within half a pass of the span: j_first .. j_first + count - 1
        first = np.ceil((-math.pi - p1 - shift) / (2 * math.pi))
        count = (np.floor(((L * k1 + math.pi) - p1 - shift) / (2 * math.pi)) - first + 1).astype(int)
        beta = (alpha * (p1 + shift + 2 * math.pi * first) - p2 - shift) / (2 * math.pi)
        order = np.argsort(count, kind="stable")              # blocks of similar pass counts
        for b in range(0, n, block):
            sl = order[b:b + block]
            best = _nearest_turns(alpha[sl], beta[sl], count[sl], PASSES)
            xb = (p1[sl, None] + shift + 2 * math.pi * (first[sl, None] + best)) / k1[sl, None]
            half = math.pi / k1[sl, None]
            lo[sl, col:col + PASSES] = np.clip(xb - half, 0.0, L)
            hi[sl, col:col + PASSES] = np.clip(xb + half, 0.0, L)
    return lo, hi


def _turn_distance(alpha, beta, t):
    """|alpha t + beta| to the nearest whole number (alpha, beta (n, 1), t (n, m))."""
    v = alpha * t + beta
    return np.abs(v - np.round(v))


def _nearest_turns(alpha: np.ndarray, beta: np.ndarray, count: np.ndarray, k: int) -> np.ndarray:
    """(n, k): the k indices t in [0, count) with the smallest distance of alpha t + beta to a whole number,
    by baby steps s < B and giant steps t = s + B g (B ~ sqrt(count)): for each giant step the k nearest are among
    the k baby steps on either side of where frac(alpha s) meets -frac(alpha B g + beta) in sorted order; the last,
    partial giant step is read whole. O(sqrt(count)) per mode instead of O(count)."""
    a, b = alpha[:, None], beta[:, None]
    B = max(int(math.ceil(math.sqrt(int(count.max())))), 2 * k)
    s = np.arange(B)
    baby = a * s - np.floor(a * s)                            # frac(alpha s) in [0, 1)
    sort = np.argsort(baby, axis=1)
    baby_sorted = np.take_along_axis(baby, sort, axis=1)
    full = count // B                                         # whole giant steps per mode
    g = np.arange(int(full.max()) + 1)
    target = -(a * (B * g) + b)
    target -= np.floor(target)                                # frac(alpha s) closest to this is best
    shelf = 2.0 * np.arange(len(alpha))[:, None]               # one sorted array for all modes: row r in [2r, 2r + 1)
    pos = np.searchsorted((baby_sorted + shelf).ravel(), (target + shelf).ravel()).reshape(target.shape)
    pos -= B * np.arange(len(alpha))[:, None]
    off = np.arange(-k, k)
    cand_pos = (pos[:, :, None] + off) % B                    # (n, G, 2k), circular
    rows = np.arange(len(alpha))[:, None, None]
    cand = sort[rows, cand_pos] + B * g[None, :, None]        # indices t
    cand = cand.reshape(len(alpha), -1)
    valid = g[None, :, None].repeat(2 * k, axis=2).reshape(1, -1) < full[:, None]
    last = B * full[:, None] + s                              # the partial giant step, read whole
    cand = np.concatenate([np.where(valid, cand, 0), last], axis=1)
    ok = np.concatenate([valid, last < count[:, None]], axis=1)
    d = np.where(ok, _turn_distance(a, b, cand), np.inf)
    pick = np.argpartition(d, k - 1, axis=1)[:, :k]
    return np.take_along_axis(cand, pick, axis=1)


def _clamped_shapes(sec: Section, support: str, om: np.ndarray, impact_x: float) -> tuple[np.ndarray, np.ndarray]:
    """(modal_mass, phi) of the modes at frequencies `om`, O(1) work per mode for all but a bounded number.

    Modal mass: W and Psi are combinations of four atoms (`_atoms`), so int rho A W^2 + rho I Psi^2 dx =
    rho A w^T G w + rho I p^T G p with the atoms' Gram matrix G in closed form (`_atom_gram`); modes with
    |a| L <= 1 (next to the cut-off) use Gauss-Legendre (`_grid_mass_peak`).

    max |W|:
    - below the cut-off (a L > 1): W = c2 cos k x + c3 sin k x plus tails c1 e^{-a x}, c0 e^{a (x - L)}; where
      both tails are below TAIL_NEGLIGIBLE of R = hypot(c2, c3), |W| reaches R once per half wavelength, exactly;
      the end windows (tails not negligible, plus one wavelength) are searched by a grid + Newton;
    - above it (b L > 1): W = R1 cos(k1 x - p1) + R2 cos(k2 x - p2), k1 <= k2; the span is tiled by passes
      |k1 x - p1 - 2 pi j| <= pi (for max W; shifted by pi for min W); in each, the largest value is a function
      of the other wave's phase offset nu_j = k2 x_j - p2 (mod 2 pi) at the pass centre alone (the same line on
      the torus, shifted), decreasing in |nu_j| for k1 <= k2 (a pass cut by an end is lower still), so only the
      PASSES passes of smallest |nu_j| per sign, and the two ends, are searched (grid + Newton from several
      starts). Choosing them takes O(sqrt(passes)) multiply-and-rounds per mode (`_nearest_turns`);
    - low modes, tail windows covering the span, |a| L <= 1 or fewer than 8 passes: the whole-span grid with 16
      Newton starts (a bounded number of modes).
    The whole-span grid with one start (`_clamped_shapes_grid`, the previous method) reads max |W| up to 1e-3 low
    above the cut-off, where two waves give many peaks of nearly equal height.
    """
    coeffs = _null_vectors(sec, support, om)
    mass, peak = _fast_mass_peak(sec, om, coeffs)
    phi = _combined(sec, om, np.array([impact_x]), coeffs)[0][:, 0]
    return mass / peak**2, phi / peak


def _fast_mass_peak(sec: Section, om: np.ndarray, coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`_grid_mass_peak` in O(1) work per mode for all but a bounded number of modes (see `_clamped_shapes`)."""
    rA, rI, L = sec.density * sec.area, sec.density * sec.second_moment, sec.length
    n = len(om)
    a2, k2, qs = wave_numbers(sec, om)
    expo, rates, w, p = _atoms(sec, om, coeffs)
    closed = np.abs(a2) * L * L > 1.0
    mass, peak = np.full(n, np.nan), np.full(n, np.nan)
    if np.any(closed):
        G = _atom_gram(expo[closed], rates[closed], L)
        wc, pc = w[closed], p[closed]
        mass[closed] = (rA * np.einsum("ni,nij,nj->n", wc, G, wc) + rI * np.einsum("ni,nij,nj->n", pc, G, pc))
    full = ~closed
    # below the cut-off: tails and interior sinusoid
    a, k = rates[:, 0], rates[:, 1]
    R = np.hypot(coeffs[:, 2], coeffs[:, 3])
    with np.errstate(divide="ignore"):
        left = np.log(np.abs(coeffs[:, 1]) / (TAIL_NEGLIGIBLE * R)) / a
        right = np.log(np.abs(coeffs[:, 0]) / (TAIL_NEGLIGIBLE * R)) / a
    wave = 2 * math.pi / k
    xl = np.clip(left, 0.0, L) + wave
    xr = L - np.clip(right, 0.0, L) - wave
    tails = expo & (xr - xl > 0.5 * wave)
    full |= expo & ~tails
    if np.any(tails):
        i = np.flatnonzero(tails)
        lo = np.stack([np.zeros(len(i)), xr[i]], axis=1)
        hi = np.stack([np.minimum(xl[i], L), np.full(len(i), L)], axis=1)
        peak[i] = np.maximum(R[i], _window_peaks(sec, om[i], coeffs[i], qs[i], lo, hi, k[i]))
    # above the cut-off: two sinusoids
    osc = closed & ~expo
    if np.any(osc):
        z1 = coeffs[:, 0] + 1j * w[:, 1]             # W = Re(z1 e^{-i b x} + z2 e^{-i k x})
        z2 = coeffs[:, 2] + 1j * coeffs[:, 3]
        swap = a > k                                  # carrier 1: the smaller wave number
        k1, k2w = np.where(swap, k, a), np.where(swap, a, k)
        p1, p2 = np.angle(np.where(swap, z2, z1)), np.angle(np.where(swap, z1, z2))
        passes = k1 * L / (2 * math.pi)
        ok = osc & (passes >= 8)
        full |= osc & ~ok
        i = np.flatnonzero(ok)
        if len(i):
            lo, hi = _pass_windows(k1[i], k2w[i], p1[i], p2[i], L)
            peak[i] = _window_peaks(sec, om[i], coeffs[i], qs[i], lo, hi, k1[i] + k2w[i])
            ends = np.abs(_combined(sec, om[i], np.array([0.0, L]), coeffs[i])[0]).max(axis=1)
            peak[i] = np.maximum(peak[i], ends)
    if np.any(full):
        i = np.flatnonzero(full)
        m_grid, p_grid = _grid_mass_peak(sec, om[i], coeffs[i], starts=16)
        peak[i] = p_grid
        mass[i] = np.where(closed[i], mass[i], m_grid)
    return mass, peak


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
