"""Clamped-clamped / cantilever Timoshenko mode shapes in O(1) work per mode (reference/timoshenko_shapes.py,
`_clamped_shapes`) against the whole-span grid (`_clamped_shapes_grid`, the previous method), a dense search of
max |W| and adaptive quadrature of the modal mass."""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from impactval.reference import timoshenko as tim
from impactval.reference import timoshenko_shapes as shapes
from impactval.scenarios.scene import scene_from_dict


def _section(length, height, width, material):
    scene = scene_from_dict({"ball": {"radius": 0.01, "velocity": 1.0, "material": "steel"},
                             "target": {"kind": "beam", "material": material, "support": "cantilever",
                                        "length": length, "width": width, "height": height, "impact_at": 0.5 * length,
                                        "theory": "timoshenko"}})
    return tim.Section.of(scene.target)


#: (L, h, b, material, modes): stubby (L/h 4, cut-off after ~6 modes) and slender (L/h 67, ~60 modes below it)
BEAMS = {"stubby": (0.04, 0.01, 0.01, "steel", 300), "slender": (0.5, 0.0075, 0.02, "aluminium", 400)}


def _modes(name, support):
    L, h, b, mat, n = BEAMS[name]
    sec = _section(L, h, b, mat)
    om = tim.clamped_frequencies(sec, support, n)
    return sec, om, tim._null_vectors(sec, support, om)


def _dense_peak(sec, om, c):
    """max |W| of one mode by plain sampling (no Newton): 128 points per pi of wave phase (reads a peak at most
    ~1e-4 low), then every sampled local maximum within 1e-3 of the best and the ends are zoomed into, 5 rounds
    of 41 points each shrinking the bracket 20x."""
    L = sec.length
    xs = np.linspace(0.0, L, int(128 * tim._phase(sec, om)[0] / math.pi) + 200)
    W = np.abs(tim._combined(sec, om, xs, c)[0][0])
    inner = np.flatnonzero((W[1:-1] >= W[:-2]) & (W[1:-1] >= W[2:])) + 1
    cand = np.concatenate([[0, len(xs) - 1], inner[W[inner] >= (1 - 1e-3) * W.max()]])
    h = xs[1] - xs[0]
    lo, hi = np.maximum(xs[cand] - h, 0.0), np.minimum(xs[cand] + h, L)
    t = np.linspace(0.0, 1.0, 41)
    best = W.max()
    for _ in range(5):
        x = lo[:, None] + (hi - lo)[:, None] * t
        v = np.abs(tim._combined(sec, om, x.reshape(1, -1), c)[0]).reshape(x.shape)
        best = max(best, v.max())
        j = np.argmax(v, axis=1)
        rows = np.arange(len(x))
        lo, hi = x[rows, np.maximum(j - 1, 0)], x[rows, np.minimum(j + 1, len(t) - 1)]
    return best


@pytest.mark.parametrize("support", ["clamped-clamped", "cantilever"])
@pytest.mark.parametrize("name", list(BEAMS))
def test_fast_shapes_against_the_grid(name, support):
    """Same modal mass (integral) as Gauss-Legendre on the grid, never a lower max |W|, and the same phi^2/m (free
    of the normalisation: what the solver uses) to roundoff, on every mode below and above the cut-off."""
    sec, om, c = _modes(name, support)
    assert np.any(om < sec.cutoff) and np.any(om > sec.cutoff)
    mass_fast, peak_fast = shapes._fast_mass_peak(sec, om, c)
    mass_grid, peak_grid = shapes._grid_mass_peak(sec, om, c)
    assert np.max(np.abs(mass_fast / mass_grid - 1)) < 1e-12
    # the grid's max is a value of |W| at some point, so the true max is at least it
    assert np.all(peak_fast >= peak_grid * (1 - 1e-13))
    x = 0.37 * sec.length
    mm_fast, phi_fast = shapes._clamped_shapes(sec, support, om, x)
    mm_grid, phi_grid = shapes._clamped_shapes_grid(sec, support, om, x)
    g_fast, g_grid = phi_fast**2 / mm_fast, phi_grid**2 / mm_grid
    assert np.max(np.abs(g_fast - g_grid)) < 1e-11 * np.max(g_grid)
    below = om < sec.cutoff                    # one wave + end tails: the grid (one Newton start) is exact there
    assert np.max(np.abs(peak_fast[below] / peak_grid[below] - 1)) < 1e-12


@pytest.mark.parametrize("support", ["clamped-clamped", "cantilever"])
@pytest.mark.parametrize("name", list(BEAMS))
def test_fast_peak_against_a_dense_search(name, support):
    """max |W| to 1e-12 against a dense grid + scipy bounded search, on every 7th mode and on each mode where the
    old grid read it low (above the cut-off, where two waves give many near-equal peaks)."""
    sec, om, c = _modes(name, support)
    _, peak_fast = shapes._fast_mass_peak(sec, om, c)
    _, peak_grid = shapes._grid_mass_peak(sec, om, c)
    low = np.flatnonzero(peak_grid < peak_fast * (1 - 1e-12))
    picks = sorted(set(range(0, len(om), 7)) | set(low[:: max(1, len(low) // 25)]))
    dense = np.array([_dense_peak(sec, om[i:i + 1], c[i:i + 1]) for i in picks])
    assert np.max(np.abs(peak_fast[picks] / dense - 1)) < 1e-12


@pytest.mark.parametrize("support", ["clamped-clamped", "cantilever"])
def test_modal_mass_against_quad(support):
    """int rho A W^2 + rho I Psi^2 dx in closed form against scipy quad (per half wavelength) on modes below,
    near and far above the cut-off of the stubby beam."""
    sec, om, c = _modes("stubby", support)
    mass, _ = shapes._fast_mass_peak(sec, om, c)
    rA, rI, L = sec.density * sec.area, sec.density * sec.second_moment, sec.length
    for i in (0, 3, 8, 40, 150, 299):
        o, ci = om[i:i + 1], c[i:i + 1]

        def integrand(x):
            W, P = tim._combined(sec, o, np.array([x]), ci)
            return rA * W[0, 0] ** 2 + rI * P[0, 0] ** 2

        edges = np.linspace(0.0, L, int(2 * tim._phase(sec, o)[0] / math.pi) + 4)
        total = sum(quad(integrand, a, b, epsabs=0.0, epsrel=1e-13, limit=200)[0] for a, b in zip(edges, edges[1:]))
        assert abs(mass[i] / total - 1) < 1e-11, i


def test_close_root_pairs_are_not_missed():
    """Where the bending and the second spectrum veer, two roots can fall into one cell of the bracketing grid
    (random beam seed 5017: a pair 1.8e-4 apart at 1.82e6 rad/s, another 3.4e-5 apart at 6.16e6): the grid's
    sign changes miss both and every higher mode shifts by two. The roots must not depend on how many are asked
    for, and must match a dense sign-change count."""
    scene = scene_from_dict({"ball": {"radius": 0.001, "velocity": 3.0, "material": "steel"},
                             "target": {"kind": "beam", "material": "tungsten-carbide", "support": "clamped-clamped",
                                        "length": 0.5887295527432278, "height": 0.021590940799941442,
                                        "width": 0.016976691471772498, "impact_at": 0.2, "theory": "timoshenko"}})
    sec = tim.Section.of(scene.target)
    many = tim.clamped_frequencies(sec, "clamped-clamped", 8192)
    for n in (1024, 4096):
        assert np.max(np.abs(tim.clamped_frequencies(sec, "clamped-clamped", n) / many[:n] - 1)) < 1e-12
    for lo, hi in ((1.81e6, 1.83e6), (6.15e6, 6.165e6)):
        grid = np.linspace(lo, hi, 200_001)
        f = tim.frequency_function(sec, "clamped-clamped", grid)
        dense = np.sum(np.sign(f[:-1]) * np.sign(f[1:]) < 0)
        assert dense >= 2 and np.sum((many > lo) & (many < hi)) == dense


def test_nearest_turns_against_brute_force():
    """The baby-step/giant-step choice of beat passes equals reading every pass."""
    rng = np.random.default_rng(7)
    count = rng.integers(8, 5000, 300)
    alpha, beta = rng.uniform(1.0, 8.0, 300), rng.uniform(-4.0, 4.0, 300)
    got = shapes._nearest_turns(alpha, beta, count, shapes.PASSES)
    for i in range(300):
        t = np.arange(count[i])
        want = np.sort(shapes._turn_distance(alpha[i], beta[i], t))[:shapes.PASSES]
        assert len(set(got[i])) == shapes.PASSES and np.all((got[i] >= 0) & (got[i] < count[i]))
        assert np.allclose(np.sort(shapes._turn_distance(alpha[i], beta[i], got[i])), want, rtol=0, atol=1e-15)
