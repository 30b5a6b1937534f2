"""Euler-Bernoulli beam modes (physics.md sec. 3)."""
import math

import numpy as np
import pytest
from scipy import integrate

from impactval.reference import beams
from impactval.reference.beams import (beam_frequencies, beam_modal_masses, beam_shapes,
                                       beam_static_flexibility)

SUPPORTS = ["simply-supported", "clamped-clamped", "cantilever"]


def test_frequency_equation_roots_match_the_classical_values():
    assert beams._beta_l("clamped-clamped", 3) == pytest.approx([4.730040745, 7.853204624, 10.99560784], rel=1e-9)
    assert beams._beta_l("cantilever", 3) == pytest.approx([1.875104069, 4.694091133, 7.854757438], rel=1e-9)
    for n, root in enumerate(beams._beta_l("clamped-clamped", 50), start=1):
        assert abs(math.cos(root) - 1.0 / math.cosh(root)) < 2e-16 * root + 1e-15   # cos x cosh x = 1
        assert abs(root - (n + 0.5) * math.pi) < 0.02


def test_worked_beam_first_frequency():
    # 0.5 m x 10 mm x 10 mm steel, simply supported: (pi/L)^2 sqrt(EI/rho A)
    w = beam_frequencies("simply-supported", 3, 0.5, 210e9, 0.01**4 / 12, 7800, 1e-4)
    assert w[0] == pytest.approx((math.pi / 0.5) ** 2 * math.sqrt(210e9 * 0.01**4 / 12 / (7800 * 1e-4)))
    assert w[1] / w[0] == pytest.approx(4.0)


@pytest.mark.parametrize("support", SUPPORTS)
def test_shapes_are_max_normalised_and_modal_masses_integrate(support):
    xi = np.linspace(0.0, 1.0, 40001)
    n = 8
    phi = beam_shapes(support, n, xi)
    assert np.abs(phi).max(axis=1) == pytest.approx(np.ones(n), abs=1e-6)
    rho, area, length = 7800.0, 1e-4, 0.5
    mm = beam_modal_masses(support, n, rho, area, length)
    quad = rho * area * length * integrate.trapezoid(phi**2, xi, axis=1)
    assert mm == pytest.approx(quad, rel=1e-6)
    # orthogonality of the shapes (mass-weighted, uniform beam)
    gram = integrate.trapezoid(phi[:, None, :] * phi[None, :, :], xi, axis=2)
    assert np.abs(gram - np.diag(np.diag(gram))).max() < 1e-6


@pytest.mark.parametrize("support", ["clamped-clamped", "cantilever"])
def test_high_modes_neither_overflow_nor_lose_their_maximum(support):
    n = 2560
    bl = beams._beta_l(support, n)
    vals = beams.beam_shapes(support, n, np.linspace(0, 1, 7))
    assert np.isfinite(vals).all()
    # the shortcut for beta L > 60 (same maximum for every high mode) against a direct computation
    for k in (30, 400, 2559):
        assert beams._shape_max(support, n)[k] == pytest.approx(beams.shape_max_one(support, bl[k]), rel=1e-12)


@pytest.mark.parametrize("support,at", [("simply-supported", 0.5), ("simply-supported", 0.3),
                                        ("clamped-clamped", 0.5), ("cantilever", 0.95)])
def test_static_flexibility_is_the_sum_over_all_modes(support, at):
    L, E, I, rho, A = 0.5, 210e9, 0.01**4 / 12, 7800.0, 1e-4
    n = 4000
    w = beam_frequencies(support, n, L, E, I, rho, A)
    phi = beam_shapes(support, n, np.array([at]))[:, 0]
    mm = beam_modal_masses(support, n, rho, A, L)
    total = beam_static_flexibility(support, L, E, I, at * L)
    assert np.sum(phi**2 / (mm * w**2)) == pytest.approx(total, rel=1e-9)
