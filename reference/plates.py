"""Kirchhoff plate modes: a rectangular plate simply supported on all four edges.

omega_mn = pi^2 (m^2/a^2 + n^2/b^2) sqrt(D / (rho h)), D = E h^3 / (12 (1 - nu^2)); shapes
sin(m pi x/a) sin(n pi y/b) (max 1), modal mass rho h a b / 4. `plate_modes(plate, n)` returns the n lowest
modes exactly, sorted by frequency (ties by m, then n).

Static flexibility at the load point (the Navier double series of the Green's function,
w/F = 4/(D a b pi^4) sum_mn sin^2(m pi xi) sin^2(n pi eta) / (m^2/a^2 + n^2/b^2)^2) is summed in closed form
over the index along the longer side (sum cos(n theta)/(n^2 + c^2)^2 from the classical
sum cos(n theta)/(n^2 + c^2) = pi cosh(c (pi - theta)) / (2 c sinh(c pi)) - 1/(2 c^2)) and numerically over the
other index up to M = 4000 terms, plus the integral of the asymptotic tail: converged to ~1e-12 relative.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from impactval.reference.beams import Modes

#: terms of the outer (single) series of the static Green's function before its tail integral
STATIC_TERMS = 4000


def _lowest_indices(a: float, b: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(m, n) of the n smallest m^2/a^2 + n^2/b^2, sorted (stable: ties by m then n)."""
    r2 = max(4.0 * n / (math.pi * a * b), 1.0 / a**2 + 1.0 / b**2) * 1.5
    while True:
        mmax = int(math.floor(a * math.sqrt(r2))) + 1
        m = np.arange(1, mmax + 1)
        nmax = np.floor(b * np.sqrt(np.maximum(r2 - m**2 / a**2, 0.0))).astype(int)
        if int(np.sum(nmax)) >= n:
            break
        r2 *= 2.0
    mm = np.repeat(m, nmax)
    first = np.repeat(np.cumsum(nmax) - nmax, nmax)
    nn = np.arange(len(mm)) - first + 1
    lam = mm**2 / a**2 + nn**2 / b**2
    order = np.lexsort((nn, mm, lam))[:n]
    return mm[order], nn[order]


@lru_cache(maxsize=64)
def _plate_modes(young: float, poisson: float, density: float, a: float, b: float, h: float, xi: float,
                 eta: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    D = young * h**3 / (12.0 * (1.0 - poisson**2))
    m, k = _lowest_indices(a, b, n)
    omega = math.pi**2 * (m**2 / a**2 + k**2 / b**2) * math.sqrt(D / (density * h))
    phi = np.sin(m * math.pi * xi) * np.sin(k * math.pi * eta)
    return omega, np.full(n, 0.25 * density * h * a * b), phi


def plate_mode_indices(plate, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Half-wave numbers (m along the length x, n along the width y) of the n lowest modes."""
    return _lowest_indices(plate.length, plate.width, n)


def _cos_sum2(theta: float, c: np.ndarray) -> np.ndarray:
    """T(theta, c) = sum_{n >= 1} cos(n theta) / (n^2 + c^2)^2 for 0 <= theta <= 2 pi, c > 0 (overflow-free)."""
    u = math.pi - theta
    e = np.exp(-2.0 * c * math.pi)
    den = 1.0 - e
    ep, em = np.exp(c * (abs(u) - math.pi)), np.exp(-c * (abs(u) + math.pi))
    f = (ep + em) / den                                  # cosh(c u) / sinh(c pi)
    g = math.copysign(1.0, u) * (ep - em) / den if u != 0 else 0.0 * c   # sinh(c u) / sinh(c pi)
    coth = (1.0 + e) / den
    df = u * g - math.pi * f * coth                      # d f / d c
    dS = -math.pi / (2.0 * c**2) * f + math.pi / (2.0 * c) * df + 1.0 / c**3
    return -dS / (2.0 * c)


def static_flexibility(young: float, poisson: float, a: float, b: float, h: float, xi: float, eta: float) -> float:
    """w/F [m/N] at (xi a, eta b) under a point load F there, all modes together (Navier, summed as above)."""
    D = young * h**3 / (12.0 * (1.0 - poisson**2))
    if a > b:                          # sum in closed form along the longer side (no cancellation: c >= 1)
        a, b, xi, eta = b, a, eta, xi
    r = b / a
    m = np.arange(1, STATIC_TERMS + 1, dtype=float)
    c = m * r
    inner = 0.5 * (_cos_sum2(0.0, c) - _cos_sum2(2.0 * math.pi * eta, c))
    total = float(np.sum(np.sin(m * math.pi * xi) ** 2 * inner))
    # tail m > M: sin^2 -> 1/2 on average, inner -> (pi/(4 c^3) - 1/(2 c^4)) / 2
    M = STATIC_TERMS + 0.5
    total += 0.5 * 0.5 * (math.pi / (8.0 * r**3 * M**2) - 1.0 / (6.0 * r**4 * M**3))
    return 4.0 * b**4 / (D * a * b * math.pi**4) * total


def plate_modes(plate, n: int, residual: bool = False) -> Modes:
    """The n lowest modes of a `Plate` scene target seen from its impact point; with `residual`, the static
    flexibility of all the others (exact total minus the n retained modes' share)."""
    mat = plate.material
    xi, eta = plate.impact_at
    omega, mm, phi = _plate_modes(mat.young, mat.poisson, mat.density, plate.length, plate.width, plate.thickness,
                                  xi, eta, int(n))
    res = 0.0
    if residual:
        total = static_flexibility(mat.young, mat.poisson, plate.length, plate.width, plate.thickness, xi, eta)
        res = max(total - float(np.sum(phi**2 / (mm * omega**2))), 0.0)
    return Modes(omega, mm, phi, res)


# ----------------------------------------------------------------------------- Zener's infinite plate

def infinite_plate_damping(plate) -> float:
    """Point impedance of an infinite Kirchhoff plate, c = 8 sqrt(D rho h) [N s/m]: under a point force F
    the load point moves at w' = F / c (real, frequency independent)."""
    return 8.0 * math.sqrt(plate.bending_stiffness * plate.material.density * plate.thickness)


def zener_lambda(scene) -> float:
    """Zener's (1941) inelasticity parameter of a ball on an infinite plate of the scene's plate:
    lambda = m0 / (c T), T = (m0/alpha)^(2/5) v0^(-1/5), c = 8 sqrt(D rho h). With sigma = delta/(v0 T) and
    tau = t/T the impact obeys Zener's equation sigma'' + sigma^(3/2) + lambda d(sigma^(3/2))/dtau = 0."""
    m0, v0 = scene.ball.mass, scene.ball.velocity
    T = (m0 / scene.alpha) ** 0.4 * v0**-0.2
    return m0 / (infinite_plate_damping(scene.target) * T)


def zener_restitution(lam: float, rtol: float = 1e-12) -> tuple[float, float]:
    """(restitution e = rebound speed / v0, contact duration in units of T) from Zener's equation, integrated
    by scipy's DOP853: ball X'' = -sigma^(3/2), plate W' = lambda sigma^(3/2), sigma = X - W."""
    from scipy.integrate import solve_ivp

    def rhs(_t, y):
        s = y[0] - y[2]
        f = s * math.sqrt(s) if s > 0 else 0.0
        return [y[1], -f, lam * f]

    def end(_t, y):
        return y[0] - y[2]

    end.terminal, end.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 1000.0), [0.0, 1.0, 0.0], method="DOP853", rtol=rtol, atol=rtol * 1e-2,
                    events=end)
    return -float(sol.y_events[0][0][1]), float(sol.t_events[0][0])
