"""Hertz contact and the ball on a rigid plate in closed form (paper eq. 18-37).

All functions are pure; SI units (m, s, N, kg, Pa).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: c = integral_0^1 dx / sqrt(1 - x^(5/2)) = (2/5) B(2/5, 1/2)   (paper eq. 30)
C_HERTZ = 0.4 * math.gamma(0.4) * math.gamma(0.5) / math.gamma(0.9)
#: the paper's e0 = pi / (2 c): linear-spring duration over Hertz duration (eq. 85)
E0 = math.pi / (2.0 * C_HERTZ)


def e_star(young1: float, poisson1: float, young2: float, poisson2: float) -> float:
    """Contact modulus E* [Pa]: 1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2."""
    return 1.0 / ((1 - poisson1**2) / young1 + (1 - poisson2**2) / young2)


def hertz_alpha(radius: float, e_star_pa: float) -> float:
    """Hertz coefficient alpha in f = alpha * delta**1.5, ball on a flat (paper eq. 20).

    Parameters: radius R [m], e_star_pa E* [Pa]. Returns alpha [N/m**1.5].
    """
    return 4.0 / 3.0 * e_star_pa * math.sqrt(radius)


def hertz_alpha_spheres(radius1: float, radius2: float, e_star_pa: float) -> float:
    """Hertz alpha [N/m**1.5] for two spheres: (4/3) E* / sqrt(1/R1 + 1/R2) (ball on ball)."""
    return 4.0 / 3.0 * e_star_pa / math.sqrt(1.0 / radius1 + 1.0 / radius2)


@dataclass(frozen=True)
class ContactLaw:
    """A normal contact law f = coefficient * delta**exponent for delta > 0 (0 otherwise).

    `kind` "hertz" (exponent 1.5, coefficient alpha [N/m**1.5]) or "linear" (exponent 1,
    coefficient k [N/m]). Every adapter takes its force, potential and tangent stiffness from here,
    and carries the law in its result so the comparison knows which theory applies.
    """

    kind: str
    coefficient: float

    def __post_init__(self) -> None:
        if self.kind not in ("hertz", "linear"):
            raise ValueError(f"contact law kind must be 'hertz' or 'linear', got {self.kind!r}")
        if not (math.isfinite(self.coefficient) and self.coefficient > 0):
            raise ValueError(f"contact law coefficient must be a positive finite number, got {self.coefficient!r}")

    @classmethod
    def hertz(cls, alpha: float) -> "ContactLaw":
        return cls("hertz", float(alpha))

    @classmethod
    def linear(cls, stiffness: float) -> "ContactLaw":
        return cls("linear", float(stiffness))

    @property
    def exponent(self) -> float:
        return 1.5 if self.kind == "hertz" else 1.0

    def force(self, delta: float) -> float:
        """Contact force [N] at approach delta [m] (0 for delta <= 0)."""
        return self.coefficient * delta**self.exponent if delta > 0 else 0.0

    def potential(self, delta: float) -> float:
        """Stored energy [J] at approach delta [m]: coefficient delta^(p+1) / (p+1)."""
        p = self.exponent
        return self.coefficient * delta ** (p + 1) / (p + 1) if delta > 0 else 0.0

    def stiffness(self, delta: float) -> float:
        """Tangent stiffness df/ddelta [N/m] at approach delta [m] (0 for delta <= 0)."""
        p = self.exponent
        return p * self.coefficient * delta ** (p - 1) if delta > 0 else 0.0

    def as_dict(self) -> dict[str, float | str]:
        return {"kind": self.kind, "coefficient": self.coefficient, "exponent": self.exponent}


@dataclass(frozen=True)
class PlateImpact:
    """Ball on a rigid plate, closed form: `delta_m` [m], `f_m` [N], `t_m` [s], `k_m` [N/m],
    `omega_m` = pi/t_m [rad/s], and the linear-theory spring `k0` [N/m] (eq. 47-49)."""

    mass: float
    alpha: float
    v0: float
    delta_m: float
    f_m: float
    t_m: float
    k_m: float
    omega_m: float
    k0: float

    def delta(self, t: np.ndarray | float) -> np.ndarray:
        """Approach delta(t) [m] for t in [0, t_m] (0 outside), exact to ~1e-13 relative.

        Inverts t(delta) = (delta_m/v0) c I_u(2/5, 1/2), u = (delta/delta_m)^(5/2) (eq. 27, 29).
        """
        from scipy import special     # lazy: keeps the CLI's start-up fast

        t = np.asarray(t, dtype=float)
        half = 0.5 * self.t_m
        tau = np.where(t <= half, t, self.t_m - t)
        inside = (t > 0) & (t < self.t_m)
        x = np.clip(np.where(inside, tau, 0.0) / half, 0.0, 1.0)
        u = special.betaincinv(0.4, 0.5, x)
        return np.where(inside, self.delta_m * u**0.4, 0.0)

    def force(self, t: np.ndarray | float) -> np.ndarray:
        """Contact force f(t) = alpha * delta(t)^1.5 [N]."""
        return self.alpha * self.delta(t) ** 1.5

    def time_of(self, delta: np.ndarray | float) -> np.ndarray:
        """Time [s] at which the approach first reaches `delta` [m] (0 <= delta <= delta_m)."""
        from scipy import special

        x = np.clip(np.asarray(delta, dtype=float) / self.delta_m, 0.0, 1.0)
        return self.delta_m / self.v0 * C_HERTZ * special.betainc(0.4, 0.5, x**2.5)


def plate_impact(mass: float, alpha: float, v0: float) -> PlateImpact:
    """Closed-form impact of a ball (mass [kg]) at v0 [m/s] on a rigid plate with Hertz alpha."""
    delta_m = (5.0 * mass * v0**2 / (4.0 * alpha)) ** 0.4          # eq. 32
    f_m = alpha * delta_m**1.5                                      # eq. 33
    t_m = 2.0 * C_HERTZ * delta_m / v0                              # eq. 31, 36
    return PlateImpact(mass, alpha, v0, delta_m, f_m, t_m, f_m / delta_m, math.pi / t_m,
                       0.8 * alpha * math.sqrt(delta_m))
