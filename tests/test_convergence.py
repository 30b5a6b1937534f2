"""Order of accuracy, the error estimate, and modal truncation (issue 8)."""
import math

import numpy as np
import pytest

import impactval
from impactval.reference import kernel
from impactval.reference.hertz import plate_impact
from impactval.reference.solve import P_DEGREE, _select, integrate, structure_modes, solve_modes


def _max_rel(m, ref):
    e = m.relative_to(ref)
    return max(abs(e.t_m), abs(e.f_m), abs(e.delta_m))


def test_scheme_reaches_order_six_despite_the_t15_onset():
    """Errors against the closed form fall by ~2^6 per halving of the base step (order p + 1)."""
    scene = impactval.load_scene("plate_steel")
    p = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    md = structure_modes(scene)
    errs = [_max_rel(integrate(md, p.mass, p.alpha, p.v0, n, J=14).metrics, p) for n in (20, 40, 80)]
    orders = [math.log2(a / b) for a, b in zip(errs, errs[1:])]
    assert P_DEGREE + 1 == 6
    assert min(orders) >= 5.5, f"observed orders {orders}"


def test_energy_error_converges_at_the_scheme_order():
    scene = impactval.load_scene("modal_two_mode")
    md = structure_modes(scene)
    e = []
    for n in (20, 40, 80):
        run = integrate(md, scene.ball.mass, scene.alpha, scene.ball.velocity, n, J=14)
        e.append(np.max(np.abs(run.energy / run.energy[0] - 1)))
    orders = [math.log2(a / b) for a, b in zip(e, e[1:])]
    assert min(orders) >= 5.0, f"energy orders {orders}"


def test_moments_match_quadrature():
    from scipy import integrate as si
    omega = np.array([1.0, 3e3, 4e5, 2e7, 9e8])
    g = np.ones_like(omega)
    H = 2.5e-6
    Er, Ei, Kr, Ki, S = kernel.moments(omega, g, H, 2, 5)
    for j in range(3):
        eta = H / 2**j
        for i, w in enumerate(omega):
            assert Er[j, i] == pytest.approx(math.cos(w * eta), abs=1e-15)
            for l in range(6):
                f = lambda s, part: (np.cos if part == 0 else np.sin)(w * (eta - s)) * (s / eta) ** l
                lim = max(50, int(w * eta))
                re = si.quad(f, 0, eta, args=(0,), limit=lim, epsabs=0, epsrel=1e-13)[0]
                im = si.quad(f, 0, eta, args=(1,), limit=lim, epsabs=0, epsrel=1e-13)[0]
                scale = eta / (l + 1)
                assert Kr[j, l, i] == pytest.approx(re, abs=1e-12 * scale)
                assert Ki[j, l, i] == pytest.approx(im, abs=1e-12 * scale)


@pytest.mark.parametrize("name", ["plate_steel", "modal_two_mode", "heavy_ball_slender_beam"])
@pytest.mark.parametrize("tol", [1e-5, 1e-7, 1e-9])
def test_reported_uncertainty_bounds_the_real_error(name, tol):
    scene = impactval.load_scene(name)
    modes = 8 if scene.target.kind == "beam" else None
    truth = impactval.solve(scene, tol=1e-12, modes=modes)
    r = impactval.solve(scene, tol=tol, modes=modes)
    for key in ("t_m", "f_m", "delta_m"):
        err = abs(getattr(r, key) - getattr(truth, key))
        assert err <= getattr(r.uncertainty, key) <= tol * getattr(r, key)


def test_residual_flexibility_makes_few_modes_converge_fast():
    """Mode-acceleration correction: n modes + the static flexibility of the rest converge much faster."""
    scene = impactval.load_scene("beam_ss_midspan")
    m0, a, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    truth, _ = solve_modes(structure_modes(scene, 2000, residual=True), m0, a, v0, 1e-10)
    plain, corrected = [], []
    for n in (24, 48, 96):
        plain.append(_max_rel(solve_modes(structure_modes(scene, n), m0, a, v0, 1e-10)[0].metrics, truth.metrics))
        corrected.append(_max_rel(solve_modes(structure_modes(scene, n, residual=True), m0, a, v0, 1e-10)[0].metrics,
                                  truth.metrics))
    assert all(c < p / 20 for c, p in zip(corrected[1:], plain[1:]))
    assert corrected[1] / corrected[2] > 30          # ~n^-6 with the correction
    assert plain[1] / plain[2] < 10                  # ~n^-3 without


@pytest.mark.parametrize("name", ["beam_ss_midspan", "beam_cantilever_tip", "light_ball_heavy_beam"])
def test_automatic_mode_count_meets_tolerance(name):
    scene = impactval.load_scene(name)
    r = impactval.solve(scene, tol=1e-6)
    truth, _ = solve_modes(structure_modes(scene, 8 * r.modes, residual=True), scene.ball.mass, scene.alpha,
                           scene.ball.velocity, 1e-10)
    for key in ("t_m", "f_m", "delta_m"):
        err = abs(getattr(r, key) - getattr(truth.metrics, key))
        assert err <= getattr(r.uncertainty, key) <= 1e-6 * getattr(r, key)


def _table_excess(w: float, s: float) -> list[float]:
    """Assert that what the Richardson estimate misses of one mode's error (beyond the plate's own) stays below
    C(omega_c H) s w^-3.5 at every base step (the table row of the mode's coupling class), with the metrics solve_auto
    computes (kernel.solve_triple: delta_max from the dense peak); return excess / bound where omega_c H > 2."""
    from impactval.reference.beams import Modes
    from impactval.reference.solve import UNRESOLVED_C, UNRESOLVED_CLASSES, UNRESOLVED_THETA

    m0, alpha, v0 = 0.0327, 1.5384e10, 1.0
    p = plate_impact(m0, alpha, v0)
    empty = Modes(np.zeros(0), np.zeros(0), np.zeros(0))
    omega = w * v0 / p.delta_m
    one = Modes(np.array([omega]), np.array([m0 / s]), np.array([1.0]))
    omega_c = math.sqrt(omega**2 + 1.5 * alpha * math.sqrt(p.delta_m) * s / m0)
    row = UNRESOLVED_C[int(np.sum(s > UNRESOLVED_CLASSES))]

    def triple(md, n, tol):
        """(t_m, delta_m) of the fine run and the Richardson estimate (relative, as in solve_auto)."""
        omega, g, ew = _select(md)
        J = kernel.levels(n, tol, 1e-5)
        out = kernel.solve_triple(omega, g, ew, m0, alpha, v0, 0.0, p.t_m / n, J, P_DEGREE, 0.2 * p.t_m,
                                  int(6 * n + 60 * J + 50))
        x = np.array([[c[0, 1] - c[0, 0], c[0, 2]] for c in out[9:12]])
        rich = max(kernel.richardson(*x[:, 0], 4.0) / x[0, 0], 1.5 * kernel.richardson(*x[:, 1], 4.0) / x[0, 1])
        return x[0], rich

    def err(x, truth):            # relative, f_m = alpha delta_m^1.5 counted as 1.5x delta_m's
        return np.max(np.abs(x - truth) / truth * [1.0, 1.5])

    truth_plate, _ = triple(empty, 3000, 1e-12)
    truth, _ = triple(one, 3000, 1e-12)
    ratios = []
    for n in np.unique(np.round(np.logspace(np.log10(12), np.log10(500), 24)).astype(int)):
        for tol in (1e-5, 1e-8):
            theta = omega_c * p.t_m / n
            c = kernel.unresolved_factor(theta, math.sqrt(w), UNRESOLVED_THETA, row)
            x, rich = triple(one, n, tol)
            excess = err(x, truth) - rich - err(triple(empty, n, tol)[0], truth_plate)
            assert excess <= c * s * w**-3.5 + 1e-14, f"n={n}, theta={theta:.2f}: {excess:.3g} > {c * s * w**-3.5:.3g}"
            if theta > 2.0:
                ratios.append(excess / (c * s * w**-3.5))
    return ratios


@pytest.mark.parametrize("s", [0.3, 3.0])
@pytest.mark.parametrize("w", [4.0, 12.0, 40.0, 130.0, 400.0])
def test_unresolved_mode_error_table(w, s):
    """The table behind the unresolved-mode bound (measured by benchmarks/unresolved_table.py on a denser grid) holds
    for single modes of both coupling classes."""
    _table_excess(w, s)


def test_unresolved_mode_error_table_is_not_loose():
    """Where beams have most of their unresolved modes (s < 1, w ~ 100), the table is within 20x of the worst excess
    (measured 0.19 of the bound at w = 130, s = 0.3)."""
    assert max(_table_excess(130.0, 0.3)) > 0.05


def _cluster_misses(k: int, s: float, w: float, spread: float, tols) -> list[str]:
    """solve_modes on k modes sharing the coupling s = (m0/m) phi^2 evenly, at w (1 +- spread) (w = omega delta_plate/v0;
    k = 1: a single mode), on the worked ball, at each tol against the same modes at tol 1e-12: the comparisons whose
    real error (largest relative over t_m, f_m, delta_m) is above the reported uncertainty (only where the real error
    is >= 100x the truth's own uncertainty)."""
    from impactval.reference.beams import Modes

    m0, alpha, v0 = 0.0327, 1.5384e10, 1.0
    p = plate_impact(m0, alpha, v0)
    ws = w * (1 + spread * np.linspace(-1, 1, k))
    md = Modes(ws * v0 / p.delta_m, np.full(k, m0 * k / s), np.ones(k))
    truth, truth_unc = solve_modes(md, m0, alpha, v0, 1e-12)
    tr = truth.metrics
    misses = []
    for tol in tols:
        run, unc = solve_modes(md, m0, alpha, v0, tol)
        m = run.metrics
        real = max(abs(m.t_m / tr.t_m - 1), abs(m.f_m / tr.f_m - 1), abs(m.delta_m / tr.delta_m - 1))
        if real >= 100 * truth_unc.t_m / tr.t_m and real > unc.t_m / m.t_m:
            misses.append(f"k {k}, s {s:g}, w {w:g}, spread {spread:g}, tol {tol:.2g}: real {real:.3g} > "
                          f"reported {unc.t_m / m.t_m:.3g}")
    return misses


def _single_mode_misses(s: float, w: float, tols) -> list[str]:
    return _cluster_misses(1, s, w, 0.0, tols)


@pytest.mark.parametrize("s, w, tol", [(1.0, 15.0, 1e-6), (0.85, 50.0, 1e-8), (0.85, 50.0, 2.2e-8),
                                       (0.4, 50.0, 4.6e-9), (0.85, 150.0, 1e-10)])
def test_uncertainty_bounds_single_modes_off_the_table_grid(s, w, tol):
    """Single modes between the (s, w) points the unresolved-mode table was measured on, at the tolerances where the
    table before round 6 (a running maximum per bin on a sparser grid) reported less than the real error: 1.11x
    (s 1, w 15: w = 15 was not on its grid; its excess at theta_c 1.14 was 50x that bin's), 1.87x and 1.35x (s 0.85,
    w 50 at theta_c 1.800, just at a bin edge), 1.24x, 1.09x. Each must now be bounded."""
    assert not _single_mode_misses(s, w, [tol])


@pytest.mark.slow
def test_uncertainty_bounds_single_modes_off_the_table_grid_sweep():
    """14 couplings x 16 frequencies, none on the table's measurement grid, at 22 tolerances 1e-10 .. 1e-3 (4,046
    comparisons): the real error never exceeds the reported uncertainty (measured: worst 0.52 of it; the table before
    round 6 had 4 misses of 2,542 on 9 of these couplings, worst 1.87x)."""
    misses = []
    for s in (0.015, 0.03, 0.07, 0.15, 0.19, 0.21, 0.3, 0.4, 0.85, 1.15, 1.5, 4.0, 7.0, 15.0):
        for w in (3.5, 5.5, 7, 11, 14, 17, 22, 27, 35, 50, 70, 100, 150, 230, 350, 700):
            misses += _single_mode_misses(s, w, np.geomspace(1e-10, 1e-3, 22))
    assert not misses, misses


@pytest.mark.parametrize("k, s, w, spread", [(9, 1.0, 15.0, 0.0), (9, 1.0, 50.0, 0.02), (16, 3.0, 8.0, 0.3),
                                             (5, 0.5, 100.0, 0.1)])
def test_uncertainty_bounds_clusters_of_modes(k, s, w, spread):
    """The unresolved-mode bound adds the terms of modes in one theta bin and the bins in quadrature: k modes of about
    one frequency (equal ones act as one mode of coupling s) must still be bounded (measured: 0 of 3,106 comparisons
    on the sweep below, worst 0.88 of the bound, at k 16, s 3, w 8, spread 0.3)."""
    assert not _cluster_misses(k, s, w, spread, np.geomspace(1e-10, 1e-3, 8))


@pytest.mark.slow
def test_uncertainty_bounds_clusters_of_modes_sweep():
    """5 cluster sizes x 4 couplings x 6 frequencies x 4 spreads at 8 tolerances 1e-10 .. 1e-3 (3,106 comparisons):
    never above (worst 0.88 of the bound)."""
    misses = []
    for k in (2, 3, 5, 9, 16):
        for s in (0.1, 0.5, 1.0, 3.0):
            for w in (8, 15, 30, 50, 100, 300):
                for spread in (0.0, 0.02, 0.1, 0.3):
                    misses += _cluster_misses(k, s, w, spread, np.geomspace(1e-10, 1e-3, 8))
    assert not misses, misses
